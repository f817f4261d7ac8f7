"""
Render the ground plane (z = 0 of the world frame) as a camera sees it.

The ground is a texture of known metric extent (a top view: texture columns run along world
+x, rows along world -y, so the texture looks like the panel seen from above with x right and
y up) plus optional analytic bright ellipses (light spots). Each image pixel's ray from
`geometry.PinholeCamera.pixel_rays` (distortion included) is intersected with the ground
(paper Eq 6 via `geometry.intersect_plane`'s formula) and the texture is sampled there, so a
world point lands exactly where `PinholeCamera.project` puts it. Pixels are averaged over
`supersample` x `supersample` sub-pixel rays (box filter, the sensor's pixel area), then the
image gets exposure gain, Gaussian optical blur, sensor noise and 8-bit clipping.

Used by perception's tests (synthetic frames with known truth) and by the simulated world's
RGB camera. `make_panel_texture` builds a wood panel with an ArUco marker centred on the
world origin (marker x/y axes = world x/y, as `cv2.aruco` defines the marker frame).
"""

from dataclasses import dataclass

import cv2
from helio_optics.geometry import PinholeCamera, transform_vectors
import numpy as np

WOOD_RGB = (196, 160, 112)  # light pine, 8-bit sRGB


@dataclass
class GroundTexture:
    """
    A top-view image of the ground with its metric extent.

    `image` is (H, W) or (H, W, C) (any dtype; rendered as float); `extent` is
    (x_min, x_max, y_min, y_max) in the world frame [m]: column 0's left edge is at x_min,
    row 0's top edge at y_max.
    """

    image: np.ndarray
    extent: tuple

    @property
    def metres_per_pixel(self):
        """Return the texture's pixel size (along x, along y) [m]."""
        x_min, x_max, y_min, y_max = self.extent
        return ((x_max - x_min) / self.image.shape[1], (y_max - y_min) / self.image.shape[0])

    def texture_coordinates(self, x, y):
        """Return (column, row) in texture pixels (centres at integers) of world (x, y)."""
        x_min, _, _, y_max = self.extent
        sx, sy = self.metres_per_pixel
        return (x - x_min) / sx - 0.5, (y_max - y) / sy - 0.5

    def world_of_texture(self, column, row):
        """Return world (x, y) [m] of texture pixel coordinates (inverse of the above)."""
        x_min, _, _, y_max = self.extent
        sx, sy = self.metres_per_pixel
        return x_min + (np.asarray(column) + 0.5) * sx, y_max - (np.asarray(row) + 0.5) * sy


@dataclass
class GroundEllipse:
    """
    A bright elliptical light spot on the ground, rendered analytically (exact area).

    `center` (x, y) [m] in the world frame; `semi_axes` (a, b) [m]; `angle` from world x to
    the first axis [rad]; `value` the radiance as an 8-bit level per channel (before gain).
    """

    center: tuple
    semi_axes: tuple
    angle: float = 0.0
    value: float = 255.0

    @property
    def area(self):
        """Return the ellipse area pi a b [m^2]."""
        return float(np.pi * self.semi_axes[0] * self.semi_axes[1])

    def contains(self, x, y):
        """Return a boolean mask of the world points (x, y) inside the ellipse."""
        dx, dy = x - self.center[0], y - self.center[1]
        c, s = np.cos(self.angle), np.sin(self.angle)
        u, v = (c * dx + s * dy) / self.semi_axes[0], (-s * dx + c * dy) / self.semi_axes[1]
        return u * u + v * v <= 1.0


def aruco_dictionary(name):
    """Return the predefined cv2.aruco dictionary called `name` (e.g. 'DICT_4X4_50')."""
    code = getattr(cv2.aruco, name, None)
    if not name.startswith('DICT_') or not isinstance(code, int):
        raise ValueError(f'unknown ArUco dictionary {name!r} (expected e.g. DICT_4X4_50)')
    return cv2.aruco.getPredefinedDictionary(code)


def make_panel_texture(extent=(-0.05, 0.15, -0.05, 0.15), metres_per_pixel=2e-4,
                       marker_side=0.04, marker_id=0, dictionary='DICT_4X4_50',
                       quiet_zone=0.006, wood_rgb=WOOD_RGB, grain=0.06, seed=0):
    """
    Make an RGB wood panel texture with an ArUco marker centred on the world origin.

    `marker_side` [m] is the side of the marker's black square (cv2.aruco's marker length);
    a white quiet zone `quiet_zone` [m] wide surrounds it. The marker image from
    `cv2.aruco.generateImageMarker` is placed so that its top-left corner is at
    (-side/2, +side/2): the marker frame's x/y axes are the world x/y axes. `grain` is the
    relative amplitude of a smooth random wood grain.
    """
    x_min, x_max, y_min, y_max = extent
    width = int(round((x_max - x_min) / metres_per_pixel))
    height = int(round((y_max - y_min) / metres_per_pixel))
    rng = np.random.default_rng(seed)
    rows = np.arange(height)[:, None]
    cols = np.arange(width)[None, :]
    streaks = np.sin(2 * np.pi * (rows / (0.004 / metres_per_pixel)
                                  + 0.3 * np.sin(2 * np.pi * cols / (0.05 / metres_per_pixel))))
    noise = cv2.GaussianBlur(rng.standard_normal((height, width)).astype(np.float32), (0, 0), 3)
    shade = 1.0 + grain * (0.6 * streaks + 0.4 * noise / max(float(noise.std()), 1e-9))
    image = np.clip(shade[:, :, None] * np.asarray(wood_rgb, dtype=np.float32)[None, None],
                    0, 255).astype(np.uint8)
    texture = GroundTexture(image=image, extent=tuple(extent))
    if marker_side > 0:
        draw_marker(texture, marker_side, marker_id, dictionary, quiet_zone)
    return texture


def draw_marker(texture, side, marker_id=0, dictionary='DICT_4X4_50', quiet_zone=0.006):
    """Draw an ArUco marker (black square `side` [m]) centred on the world origin in place."""
    sx, sy = texture.metres_per_pixel
    if abs(sx - sy) > 1e-12 * max(sx, sy):
        raise ValueError('draw_marker needs square texture pixels')
    half = side / 2 + quiet_zone
    c0, r0 = texture.texture_coordinates(-half, half)
    c1, r1 = texture.texture_coordinates(half, -half)
    edges = np.array([c0, r0, c1, r1, *texture.texture_coordinates(-side / 2, side / 2)]) + 0.5
    if np.max(np.abs(edges - np.rint(edges))) > 1e-3:
        raise ValueError('the marker edges must fall on texture pixel edges: choose the extent '
                         'and metres_per_pixel so that side/2 and the quiet zone are multiples '
                         'of the pixel size')
    c0, r0, c1, r1 = (int(round(v + 0.5)) for v in (c0, r0, c1, r1))
    if c0 < 0 or r0 < 0 or c1 > texture.image.shape[1] or r1 > texture.image.shape[0]:
        raise ValueError('the marker and its quiet zone do not fit in the texture extent')
    texture.image[r0:r1, c0:c1] = 255
    pixels = int(round(side / sx))
    marker = cv2.aruco.generateImageMarker(aruco_dictionary(dictionary), marker_id, pixels, 1)
    mc, mr = texture.texture_coordinates(-side / 2, side / 2)
    mc, mr = int(round(mc + 0.5)), int(round(mr + 0.5))
    patch = marker if texture.image.ndim == 2 else marker[:, :, None]
    texture.image[mr:mr + pixels, mc:mc + pixels] = patch
    return texture


class GroundRenderer:
    """
    Render ground textures through one camera; caches the camera's sub-pixel rays.

    `supersample` sub-pixel rays per pixel side (1 = pixel centres only).
    """

    def __init__(self, camera: PinholeCamera, supersample=2):
        if supersample < 1:
            raise ValueError('supersample must be >= 1')
        self.camera = camera
        self.supersample = int(supersample)
        s = self.supersample
        offsets = (np.arange(s) + 0.5) / s - 0.5
        us = (np.arange(camera.width)[:, None] + offsets[None, :]).reshape(-1)
        vs = (np.arange(camera.height)[:, None] + offsets[None, :]).reshape(-1)
        grid_u, grid_v = np.meshgrid(us, vs)
        rays = camera.pixel_rays(np.stack([grid_u.ravel(), grid_v.ravel()], axis=-1))
        self._rays = rays.astype(np.float64)
        self._shape = (camera.height * s, camera.width * s)
        self._cached_key = None     # pose and texture geometry of the cached maps
        self._cached_maps = None    # (x, y, column, row) for that key

    def ground_points(self, T_world_camera):
        """Return world (x, y) grids [m] where each sub-pixel ray meets z = 0 (NaN if never)."""
        directions = transform_vectors(T_world_camera, self._rays)
        origin = T_world_camera[:3, 3]
        with np.errstate(divide='ignore', invalid='ignore'):
            scale = -origin[2] / directions[:, 2]
        scale = np.where((scale > 0) & np.isfinite(scale), scale, np.nan)
        x = (origin[0] + scale * directions[:, 0]).reshape(self._shape)
        y = (origin[1] + scale * directions[:, 1]).reshape(self._shape)
        return x, y

    def _maps(self, T_world_camera, texture):
        """
        Return ground (x, y) and texture (column, row) remap grids for a pose and a texture.

        The camera rarely moves between frames (the arm holds the lens while the wood heats),
        so the last grids are kept and reused while the pose and the texture's geometry are
        unchanged.
        """
        pose = np.asarray(T_world_camera, dtype=np.float64)
        key = (pose.tobytes(), tuple(texture.extent), texture.image.shape[:2])
        if key != self._cached_key:
            x, y = self.ground_points(pose)
            column, row = texture.texture_coordinates(x, y)
            column = np.nan_to_num(column, nan=-1e6).astype(np.float32)
            row = np.nan_to_num(row, nan=-1e6).astype(np.float32)
            self._cached_maps = (x, y, column, row)
            self._cached_key = key
        return self._cached_maps

    def render(self, T_world_camera, texture, spots=(), background=40.0, gain=1.0,
               blur_sigma=0.0, noise_sigma=0.0, rng=None, dtype=np.uint8):
        """
        Return the camera image of the ground at pose `T_world_camera` (4x4, optical frame).

        `texture` a GroundTexture, `spots` GroundEllipses drawn over it (max of both),
        `background` the level where rays miss the texture, `gain` exposure (levels above
        255 clip: saturation), `blur_sigma` [px] Gaussian optical blur, `noise_sigma` [levels]
        Gaussian sensor noise from `rng` (a numpy Generator). Channels follow the texture.
        """
        x, y, column, row = self._maps(T_world_camera, texture)
        source = np.asarray(texture.image, dtype=np.float32)
        channels = 1 if source.ndim == 2 else source.shape[2]
        border = (float(background),) * max(channels, 1)
        image = cv2.remap(source, column, row, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=border)
        for spot in spots:
            inside = spot.contains(x, y)
            image[inside] = np.maximum(image[inside], np.float32(spot.value))
        s = self.supersample
        if s > 1:
            image = cv2.resize(image, (self.camera.width, self.camera.height),
                               interpolation=cv2.INTER_AREA)
        image *= np.float32(gain)
        if blur_sigma > 0:
            image = cv2.GaussianBlur(image, (0, 0), blur_sigma)
        if noise_sigma > 0:
            rng = np.random.default_rng() if rng is None else rng
            image += rng.normal(0.0, noise_sigma, image.shape).astype(np.float32)
        if np.dtype(dtype) == np.uint8:
            return np.clip(np.rint(image), 0, 255).astype(np.uint8)
        return image.astype(dtype)


def render_ground(camera, T_world_camera, texture, spots=(), supersample=2, **kwargs):
    """Render once (see GroundRenderer.render); build a GroundRenderer to render many frames."""
    return GroundRenderer(camera, supersample).render(T_world_camera, texture, spots, **kwargs)
