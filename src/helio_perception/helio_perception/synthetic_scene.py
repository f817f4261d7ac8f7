"""
Synthetic RGB frames with known truth: a wood panel, an ArUco marker and light spots.

Used by the tests and the benchmark: random camera poses looking at the paper's canvas
(offsets d_x = d_y = 5 cm from the marker centre, Sec. IV-C), a spot of known ellipse, and
the renderer's blur and noise. The truth (camera pose, spot centre and area) comes from the
scene description, never from the detector.
"""

from dataclasses import dataclass

from helio_optics.geometry import invert_transform, look_at, PinholeCamera, transform_points
from helio_perception.ground_render import GroundEllipse, GroundRenderer, make_panel_texture
import numpy as np


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
                 camera=None):
        self.camera = camera or PinholeCamera.from_fov(width, height, horizontal_fov)
        self.marker_side = marker_side
        self.texture = make_panel_texture(marker_side=marker_side, marker_id=marker_id,
                                          dictionary=dictionary)
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
    def random_spot(rng, value=255.0):
        """Return a light spot on the canvas: centre 3-7 cm from the marker, 3.5-7 mm axes."""
        semi_major = rng.uniform(0.0035, 0.007)
        return GroundEllipse(center=(rng.uniform(0.03, 0.07), rng.uniform(0.03, 0.07)),
                             semi_axes=(semi_major, semi_major * rng.uniform(0.7, 1.0)),
                             angle=rng.uniform(-np.pi, np.pi), value=value)

    def sees(self, T_world_camera, points, margin=12.0):
        """Tell whether all world points (N, 3) project inside the image, `margin` px in."""
        in_camera = transform_points(invert_transform(T_world_camera), points)
        if np.any(in_camera[:, 2] <= 0):
            return False
        pixels = self.camera.project(in_camera)
        size = np.array([self.camera.width, self.camera.height])
        return bool(np.all((pixels >= margin) & (pixels <= size - 1 - margin)))

    def random_view(self, rng, spot_count=1, **pose_options):
        """Return (T_world_camera, spots) with the marker and every spot fully in view."""
        h = self.marker_side / 2 + 0.006
        marker = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
        while True:
            pose = self.random_pose(rng, **pose_options)
            spots = [self.random_spot(rng) for _ in range(spot_count)]
            outlines = [marker] + [_ellipse_outline(spot) for spot in spots]
            if self.sees(pose, np.concatenate(outlines)):
                return pose, spots

    def render(self, T_world_camera, spots=(), rng=None, blur_sigma=0.8, noise_sigma=2.0,
               gain=1.0, with_marker=True):
        """Render a frame (RGB uint8) of the scene; `with_marker=False` hides the marker."""
        texture = self.texture if with_marker else self._plain_texture()
        image = self.renderer.render(T_world_camera, texture, spots, blur_sigma=blur_sigma,
                                     noise_sigma=noise_sigma, gain=gain, rng=rng)
        return SceneFrame(image=image, T_world_camera=T_world_camera, spots=list(spots))

    def _plain_texture(self):
        if not hasattr(self, '_plain'):
            self._plain = make_panel_texture(marker_side=0.0)
        return self._plain


def _ellipse_outline(spot, count=16):
    """Return points (count, 3) on an ellipse's outline, on the ground."""
    t = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    a, b = spot.semi_axes
    c, s = np.cos(spot.angle), np.sin(spot.angle)
    x, y = a * np.cos(t), b * np.sin(t)
    return np.stack([spot.center[0] + c * x - s * y, spot.center[1] + s * x + c * y,
                     np.zeros(count)], axis=-1)
