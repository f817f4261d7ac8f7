"""
The simulated RGB and thermal cameras (issue 6, items 5-6).

Both are rigid on the end effector (``helio_optics.rig_kinematics``: T_robot_rgb,
T_robot_thermal) and look at the panel (world z = 0). Every pixel's ray is cast onto the
panel by ``helio_perception.ground_render`` (one ray-plane implementation with
``geometry.PinholeCamera``, distortion included).

RGB: the panel texture (wood, ArUco marker, char darkening the wood) lit by the sun: the
radiance of a point is its albedo times the irradiance on it (diffuse sky light + the direct
sun outside the lens shadow + the concentrated light from the ray tracer), scaled by the
exposure so that sunlit wood is mid-grey and the focused spot saturates. Blur and sensor noise
come from the renderer.

Thermal (FLIR Lepton 3.5 class): 160 x 120 pixels, each the panel surface temperature at the
point its centre ray meets, plus Gaussian noise (NETD), read out capped at 180.9 degC
(parameter), encoded 16UC1 in centikelvin.
"""

from dataclasses import dataclass
import math

import cv2
from helio_optics.geometry import PinholeCamera
from helio_perception.ground_render import GroundRenderer, GroundTexture, make_panel_texture
import numpy as np

KELVIN = 273.15
CHAR_RGB = (38.0, 30.0, 26.0)


@dataclass(frozen=True)
class RgbSettings:
    """RGB camera: size [px], horizontal field of view [rad], exposure and sensor values."""

    width: int = 640
    height: int = 480
    horizontal_fov: float = math.radians(70.0)
    supersample: int = 1
    sunlit_level: float = 0.55      # image level of sunlit bare wood (1 = the wood albedo)
    diffuse_fraction: float = 0.12  # sky light as a fraction of the direct sun on the panel
    blur_sigma: float = 0.7         # optical blur [px]
    noise_sigma: float = 2.0        # sensor noise [8-bit levels]

    def camera(self):
        """Return the PinholeCamera of these settings."""
        return PinholeCamera.from_fov(self.width, self.height, self.horizontal_fov)


@dataclass(frozen=True)
class ThermalSettings:
    """Thermal camera: Lepton-like size, field of view, read-out cap and noise."""

    width: int = 160
    height: int = 120
    horizontal_fov: float = math.radians(45.0)   # tuned footprint (Lepton 3.5: 57 deg)
    cap: float = 180.9              # read-out upper limit [degC] (paper Sec. IV-B)
    floor: float = -10.0            # read-out lower limit [degC]
    noise_sigma: float = 0.05       # NETD [K]

    def camera(self):
        """Return the PinholeCamera of these settings."""
        return PinholeCamera.from_fov(self.width, self.height, self.horizontal_fov)


def celsius_to_centikelvin(temperature):
    """Encode temperatures [degC] as uint16 centikelvin (the Lepton's radiometric format)."""
    return np.clip(np.rint((np.asarray(temperature, float) + KELVIN) * 100.0),
                   0, 65535).astype(np.uint16)


def centikelvin_to_celsius(counts):
    """Decode uint16 centikelvin to degC."""
    return np.asarray(counts, float) / 100.0 - KELVIN


class ThermalCamera:
    """Renders the panel surface temperature as the thermal camera reads it."""

    def __init__(self, settings=None):
        """Cache the pixel-centre rays of the camera."""
        self.settings = settings or ThermalSettings()
        self.camera = self.settings.camera()
        self._renderer = GroundRenderer(self.camera, supersample=1)

    def temperatures(self, panel, T_world_camera, rng=None):
        """Return the read-out [degC] per pixel: the field at pixel centres, noise, cap."""
        x, y = self._renderer.ground_points(T_world_camera)
        seen = np.isfinite(x)
        field = np.full(x.shape, panel.wood.ambient)
        field[seen] = panel.surface_temperature_at(x[seen], y[seen])
        if self.settings.noise_sigma > 0.0:
            rng = np.random.default_rng() if rng is None else rng
            field = field + rng.normal(0.0, self.settings.noise_sigma, field.shape)
        return np.clip(field, self.settings.floor, self.settings.cap)

    def image(self, panel, T_world_camera, rng=None):
        """Return the 16UC1 centikelvin read-out (H, W) as uint16."""
        return celsius_to_centikelvin(self.temperatures(panel, T_world_camera, rng))


class RgbCamera:
    """Renders the lit panel, the marker, the char and the light spot."""

    def __init__(self, panel_extent, pixel_size, settings=None, marker_side=0.04,
                 marker_id=0, dictionary='DICT_4X4_50', seed=0):
        """Build the panel's albedo texture (pixels aligned with the char raster)."""
        self.settings = settings or RgbSettings()
        self.camera = self.settings.camera()
        self._renderer = GroundRenderer(self.camera, supersample=self.settings.supersample)
        texture = make_panel_texture(extent=panel_extent, metres_per_pixel=pixel_size,
                                     marker_side=marker_side, marker_id=marker_id,
                                     dictionary=dictionary, seed=seed)
        self.extent = tuple(panel_extent)
        self.pixel_size = float(pixel_size)
        self._wood = texture.image.astype(np.float32)     # rows from y_max down (top view)
        self._albedo = GroundTexture(image=self._wood.copy(), extent=self.extent)
        self._char_rgb = np.asarray(CHAR_RGB, np.float32)
        # Sensor noise: a bank of Gaussian frames drawn once (seeded); each image adds one of
        # them, circularly shifted by a random offset (cheap, and never the same twice).
        bank_rng = np.random.default_rng(seed + 7)
        shape = (self.camera.height, self.camera.width, 3)
        self._noise = [np.rint(bank_rng.standard_normal(shape, dtype=np.float32)
                               * self.settings.noise_sigma).astype(np.int16)
                       for _ in range(4)] if self.settings.noise_sigma > 0 else []

    def update_char(self, char, box=None):
        """
        Darken the albedo where the char raster (rows from y_min) changed.

        `box` (r0, r1, c0, c1) limits the look to where the panel reported changes (None:
        nothing changed).
        """
        if box is None:
            return
        r0, r1, c0, c1 = box
        height = self._wood.shape[0]
        chi = np.flipud(char[r0:r1, c0:c1]).astype(np.float32)[:, :, None]
        top = slice(height - r1, height - r0)
        self._albedo.image[top, c0:c1] = (self._wood[top, c0:c1] * (1.0 - chi)
                                          + self._char_rgb * chi)

    def render(self, T_world_camera, light=None, level=1.0, rng=None):
        """
        Return the RGB image (H, W, 3) uint8 at a camera pose.

        The panel is lit uniformly at `level` (direct + sky light relative to a clear day)
        except in `light` = (rows, cols, relative) from ``light_window``: the lens shadow and
        the focused spot, relative to the uniform light.
        """
        s = self.settings
        image_array = self._albedo.image
        saved = None
        if light is not None:
            rows, cols, relative = light
            height = image_array.shape[0]
            top = slice(height - rows.stop, height - rows.start)
            saved = image_array[top, cols].copy()
            image_array[top, cols] *= np.flipud(relative)[:, :, None]
        try:
            image = self._renderer.render(T_world_camera, self._albedo, background=20.0,
                                          gain=s.sunlit_level * level,
                                          blur_sigma=s.blur_sigma, noise_sigma=0.0)
        finally:
            if saved is not None:
                image_array[top, cols] = saved
        if self._noise:
            rng = np.random.default_rng() if rng is None else rng
            noise = self._noise[int(rng.integers(len(self._noise)))]
            shift = (int(rng.integers(noise.shape[0])), int(rng.integers(noise.shape[1])))
            noisy = image.astype(np.int16) + np.roll(noise, shift, axis=(0, 1))
            image = np.clip(noisy, 0, 255).astype(np.uint8)
        return image


def light_window(field, shape, origin, pixel_size, diffuse_fraction, window):
    """
    Return (rows, cols, relative): the light in a window of the panel raster (rows from y_min).

    `relative` is the irradiance relative to the uniform daylight (direct sun + sky):
    (sky + direct outside the lens shadow + concentrated) / (1 + sky), the concentrated
    rays binned per pixel and normalised by the direct sun on the panel. None if the window
    misses the panel.
    """
    c0 = max(0, int(math.floor((window[0] - origin[0]) / pixel_size)))
    c1 = min(shape[1], int(math.ceil((window[1] - origin[0]) / pixel_size)))
    r0 = max(0, int(math.floor((window[2] - origin[1]) / pixel_size)))
    r1 = min(shape[0], int(math.ceil((window[3] - origin[1]) / pixel_size)))
    if c1 <= c0 or r1 <= r0:
        return None
    xs = origin[0] + (np.arange(c0, c1) + 0.5) * pixel_size
    ys = origin[1] + (np.arange(r0, r1) + 0.5) * pixel_size
    shadow = field.in_shadow(xs[None, :], ys[:, None])
    x_edges = origin[0] + np.arange(c0, c1 + 1) * pixel_size
    y_edges = origin[1] + np.arange(r0, r1 + 1) * pixel_size
    binned, _, _ = np.histogram2d(field.points[:, 1], field.points[:, 0],
                                  bins=(y_edges, x_edges), weights=field.power)
    concentrated = binned / (pixel_size * pixel_size) / max(field.direct, 1e-6)
    concentrated = cv2.GaussianBlur(concentrated.astype(np.float32), (0, 0), 0.7)
    relative = (diffuse_fraction + np.where(shadow, 0.0, 1.0) + concentrated) \
        / (1.0 + diffuse_fraction)
    return slice(r0, r1), slice(c0, c1), relative.astype(np.float32)
