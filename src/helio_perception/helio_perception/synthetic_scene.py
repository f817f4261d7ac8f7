"""
Synthetic RGB frames with known truth: a wood panel, an ArUco marker and light spots.

Used by the tests and the benchmark: camera poses looking at the paper's canvas (offsets
d_x = d_y = 5 cm from the marker centre, Sec. IV-C), spots of known ellipse, and frames as a
webcam delivers them (`helio_optics.ground_render`: light blurred in linear units, sensor
noise, the sRGB tone curve; optionally vignetting, a Bayer mosaic and JPEG). The truth
(camera pose, spot centre and area) comes from the scene description, never from the
detector.
"""

from dataclasses import dataclass, replace

import cv2
from helio_optics.geometry import invert_transform, look_at, PinholeCamera, transform_points
from helio_optics.ground_render import (
    GroundEllipse, GroundRenderer, make_panel_texture, WebcamSettings)
import numpy as np

# A webcam of the usual kind: sRGB, a little optical blur, read and shot noise (about 2 grey
# levels on the wood), 10-bit read-out.
WEBCAM = WebcamSettings(blur_sigma=0.8, read_noise=0.002, full_well_electrons=6000.0)
EXPOSURE = 0.8   # white paper at 80 % of full scale (sRGB level 231); the spot saturates


@dataclass
class SceneFrame:
    """One rendered frame and its truth."""

    image: np.ndarray
    T_world_camera: np.ndarray
    spots: list


class SyntheticScene:
    """A camera of fixed intrinsics over a textured panel with a marker at the world origin."""

    def __init__(self, width=640, height=480, horizontal_fov=np.radians(60.0),
                 marker_side=0.04, marker_id=0, dictionary='DICT_4X4_50', supersample=2,
                 camera=None, sheet_margins=None):
        self.camera = camera or PinholeCamera.from_fov(width, height, horizontal_fov)
        self.marker_side = marker_side
        self.sheet_margins = sheet_margins
        self.texture = make_panel_texture(marker_side=marker_side, marker_id=marker_id,
                                          dictionary=dictionary,
                                          sheet_margins=sheet_margins).linearised()
        self.plain_texture = make_panel_texture(marker_side=0.0).linearised()
        self.renderer = GroundRenderer(self.camera, supersample=supersample)

    def random_pose(self, rng, height=(0.14, 0.22), lateral=0.08):
        """
        Return a camera pose T_world_camera that sees the marker and the canvas.

        The camera sits `height` [m] above the panel, up to `lateral` [m] off the canvas
        centre, and looks at a point between the marker and the canvas (a random roll).
        """
        target = np.array([rng.uniform(0.015, 0.035), rng.uniform(0.015, 0.035), 0.0])
        eye = target + np.array([rng.uniform(-lateral, lateral),
                                 rng.uniform(-lateral, lateral), rng.uniform(*height)])
        angle = rng.uniform(-np.pi, np.pi)
        return look_at(eye, target, up=(np.cos(angle), np.sin(angle), 0.0))

    @staticmethod
    def tilted_pose(rng, height, tilt, target=None):
        """
        Return a camera pose `height` [m] up whose axis is `tilt` [rad] off the vertical.

        It looks at `target` (default: a random point between marker and canvas); the tilt's
        direction (azimuth) and the roll about the axis are random.
        """
        if target is None:
            target = np.array([rng.uniform(0.01, 0.04), rng.uniform(0.01, 0.04), 0.0])
        azimuth = rng.uniform(-np.pi, np.pi)
        reach = height * np.tan(tilt)
        eye = np.asarray(target, float) + np.array([reach * np.cos(azimuth),
                                                    reach * np.sin(azimuth), height])
        roll = rng.uniform(-np.pi, np.pi)
        up = (np.cos(roll), np.sin(roll), 0.0)
        if abs(np.cos(roll - azimuth)) > 0.98 and tilt < 0.05:
            up = (-np.sin(roll), np.cos(roll), 0.0)
        return look_at(eye, target, up=up)

    @staticmethod
    def random_spot(rng, value=20.0, semi_major=(0.0035, 0.007), centre=(0.03, 0.07)):
        """Return a light spot on the canvas: centre 3-7 cm from the marker, 3.5-7 mm axes."""
        a = rng.uniform(*semi_major)
        return GroundEllipse(center=(rng.uniform(*centre), rng.uniform(*centre)),
                             semi_axes=(a, a * rng.uniform(0.7, 1.0)),
                             angle=rng.uniform(-np.pi, np.pi), value=value)

    def sees(self, T_world_camera, points, margin=12.0):
        """Tell whether all world points (N, 3) project inside the image, `margin` px in."""
        in_camera = transform_points(invert_transform(T_world_camera), points)
        if np.any(in_camera[:, 2] <= 0):
            return False
        pixels = self.camera.project(in_camera)
        size = np.array([self.camera.width, self.camera.height])
        return bool(np.all((pixels >= margin) & (pixels <= size - 1 - margin)))

    def marker_outline(self):
        """Return the corners (4, 3) of the marker's paper (quiet zone or sheet) [m]."""
        h = self.marker_side / 2
        left, right, bottom, top = self.sheet_margins or (0.006,) * 4
        return np.array([[-h - left, h + top, 0.0], [h + right, h + top, 0.0],
                         [h + right, -h - bottom, 0.0], [-h - left, -h - bottom, 0.0]])

    def random_view(self, rng, spot_count=1, spot_options=None, pose=None, **pose_options):
        """
        Return (T_world_camera, spots) with the marker and every spot fully in view.

        `pose(rng)` draws a candidate pose (default `random_pose(rng, **pose_options)`);
        `spot_options` go to `random_spot`.
        """
        draw = pose or (lambda generator: self.random_pose(generator, **pose_options))
        while True:
            candidate = draw(rng)
            spots = [self.random_spot(rng, **(spot_options or {})) for _ in range(spot_count)]
            outlines = [self.marker_outline()] + [ellipse_outline(spot) for spot in spots]
            if self.sees(candidate, np.concatenate(outlines)):
                return candidate, spots

    def render(self, T_world_camera, spots=(), rng=None, webcam=WEBCAM, exposure=EXPOSURE,
               with_marker=True, texture=None, occluder=None, motion_blur=None,
               **webcam_changes):
        """
        Render a webcam frame (RGB uint8) of the scene.

        `webcam_changes` replace fields of the WebcamSettings (e.g. blur_sigma=2.0);
        `with_marker=False` hides the marker; `texture` replaces the panel. Two things that
        happen in front of the panel, applied to the light before the camera's pipeline:
        `occluder` = (polygon (N, 2) [px], light [linear]): an object in front of the panel
        covering that convex polygon of the image; `motion_blur` = (length [px], angle
        [rad]): the camera moving during the exposure (a line kernel).
        """
        if webcam_changes:
            webcam = replace(webcam, **webcam_changes)
        ground = texture or (self.texture if with_marker else self.plain_texture)
        light = self.renderer.radiance(T_world_camera, ground, spots, background=0.05)
        if occluder is not None:
            polygon, level = occluder
            covered = np.zeros(light.shape[:2], np.uint8)
            cv2.fillConvexPoly(covered, np.rint(np.asarray(polygon) * 16).astype(np.int32), 1,
                               cv2.LINE_AA, 4)
            light[covered > 0] = np.float32(level)
        if motion_blur is not None:
            light = cv2.filter2D(light, -1, line_kernel(*motion_blur),
                                 borderType=cv2.BORDER_REPLICATE)
        image = self.renderer.webcam(webcam).develop(light * np.float32(exposure), rng)
        return SceneFrame(image=image, T_world_camera=T_world_camera, spots=list(spots))


def line_kernel(length, angle):
    """Return a normalised line kernel (motion blur of `length` px along `angle` [rad])."""
    size = int(np.ceil(length)) | 1
    kernel = np.zeros((4 * size + 1, 4 * size + 1), np.float32)
    centre = 2 * size
    for t in np.linspace(-length / 2, length / 2, 8 * size + 1):
        x, y = centre + t * np.cos(angle), centre + t * np.sin(angle)
        x0, y0 = int(np.floor(x)), int(np.floor(y))
        fx, fy = x - x0, y - y0
        kernel[y0, x0] += (1 - fx) * (1 - fy)
        kernel[y0, x0 + 1] += fx * (1 - fy)
        kernel[y0 + 1, x0] += (1 - fx) * fy
        kernel[y0 + 1, x0 + 1] += fx * fy
    return kernel / kernel.sum()


def ellipse_outline(spot, count=16):
    """Return points (count, 3) on an ellipse's outline, on the ground."""
    t = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    a, b = spot.semi_axes
    c, s = np.cos(spot.angle), np.sin(spot.angle)
    x, y = a * np.cos(t), b * np.sin(t)
    return np.stack([spot.center[0] + c * x - s * y, spot.center[1] + s * x + c * y,
                     np.zeros(count)], axis=-1)
