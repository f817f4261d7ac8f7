"""
The simulated RGB and thermal cameras (issue 6, items 5-6).

Both are rigid on the end effector (``helio_optics.rig_kinematics``: T_robot_rgb,
T_robot_thermal) and look at the panel (world z = 0). Every pixel's ray is cast onto the
panel by ``helio_optics.ground_render`` (one ray-plane implementation with
``geometry.PinholeCamera``, distortion included).

RGB: the panel texture (wood, ArUco marker, char darkening the wood; linear reflectance)
lit by the sun: the light of a point is its albedo times the irradiance on it (the sky's
diffuse light, which a cloud leaves, + the direct sun outside the lens shadow and the
concentrated light from the ray tracer, both scaled by the cloud's attenuation), times the
exposure; then a webcam's pipeline (`helio_optics.ground_render.Webcam`: blur and
vignetting in linear light, read and shot noise, clipping, ADC, the sRGB tone curve,
optionally a Bayer mosaic and JPEG). Sunlit white paper reads `exposure` of full scale; the
focused spot saturates.

The frame's light is kept between frames and redone only where something changed: the
panel's light at the present pose (redone when the camera moves, and in the image region of
each char change), scaled by the uniform daylight, plus the window of the lens shadow and
the spot (rendered alone, over its own image region); an unchanged scene costs only the
sensor stage.

Thermal (FLIR Lepton 3.5 class): 160 x 120 pixels, each the panel surface temperature at the
point its centre ray meets, plus Gaussian noise (NETD), read out capped at 180.9 degC
(parameter), encoded 16UC1 in centikelvin.
"""

from dataclasses import dataclass
import math

import cv2
from helio_optics.geometry import invert_transform, PinholeCamera, transform_points
from helio_optics.ground_render import (decode_srgb8, GroundRenderer, GroundTexture,
                                        jpeg_round_trip, linear_to_srgb,
                                        make_panel_texture, WebcamSettings)
import numpy as np

KELVIN = 273.15
CHAR_RGB = (38, 30, 26)     # 8-bit sRGB


@dataclass(frozen=True)
class RgbSettings:
    """RGB camera: size [px], horizontal field of view [rad], exposure and webcam values."""

    width: int = 640
    height: int = 480
    horizontal_fov: float = math.radians(70.0)
    supersample: int = 1
    exposure: float = 0.55          # sunlit white paper's share of full scale (linear) [-]
    diffuse_fraction: float = 0.12  # sky light as a fraction of the clear direct sun [-]
    blur_sigma: float = 0.7         # optical blur [px]
    vignetting: float = 0.15        # light lost at the image corners [-]
    read_noise: float = 0.002       # sensor read noise [fraction of full scale]
    full_well_electrons: float = 6000.0   # shot noise (0: none)
    adc_bits: int = 10              # linear read-out before the tone curve
    tone_curve: str = 'srgb'        # 'srgb' or 'linear'
    bayer: bool = False             # RGGB mosaic + demosaic
    jpeg_quality: int = 0           # 0: no JPEG
    exact_read_out: bool = False    # noise through the exact ADC and tone table (slower)

    def camera(self):
        """Return the PinholeCamera of these settings."""
        return PinholeCamera.from_fov(self.width, self.height, self.horizontal_fov)

    def webcam(self, seed=0):
        """Return the WebcamSettings of these settings (noise bank from `seed`)."""
        return WebcamSettings(tone_curve=self.tone_curve, blur_sigma=self.blur_sigma,
                              vignetting=self.vignetting, read_noise=self.read_noise,
                              full_well_electrons=self.full_well_electrons,
                              adc_bits=self.adc_bits, bayer=self.bayer,
                              jpeg_quality=self.jpeg_quality, seed=seed)


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

    def __init__(self, settings=None, seed=0):
        """Cache the pixel-centre rays of the camera; `seed` draws the noise bank."""
        self.settings = settings or ThermalSettings()
        self.camera = self.settings.camera()
        self._renderer = GroundRenderer(self.camera, supersample=1)
        self._view_key = None      # (pose, panel, placement) of the kept view
        self._view = None          # (pixels seeing the panel, their surface sampler)
        self._noise = NoiseBank((self.camera.height, self.camera.width), seed)

    def temperatures(self, panel, T_world_camera, rng=None):
        """Return the read-out [degC] per pixel: the field at pixel centres, noise, cap."""
        seen, sample = self._seen(panel, T_world_camera)
        field = np.full(seen.shape, panel.wood.ambient)
        field[seen] = sample()
        if self.settings.noise_sigma > 0.0:
            field += self.settings.noise_sigma * self._noise.draw(rng)
        return np.clip(field, self.settings.floor, self.settings.cap, out=field)

    def _seen(self, panel, T_world_camera):
        """
        Return (mask of the pixels that see the panel, sampler of their surface points).

        Kept while the camera and the heat patch stand still (they do while a dot heats):
        a frame then costs the gather of the surface field, not the ray casts.
        """
        key = (np.asarray(T_world_camera, dtype=np.float64).tobytes(), id(panel),
               panel.placement)
        if key != self._view_key:
            x, y = self._renderer.ground_points(T_world_camera)
            seen = np.isfinite(x)
            self._view = (seen, panel.surface_sampler(x[seen], y[seen]))
            self._view_key = key
        return self._view

    def image(self, panel, T_world_camera, rng=None):
        """Return the 16UC1 centikelvin read-out (H, W) as uint16."""
        return celsius_to_centikelvin(self.temperatures(panel, T_world_camera, rng))


class NoiseBank:
    """
    White Gaussian noise frames N(0, 1) for one image size, cut from a bank drawn once.

    The bank holds a few frames a little larger than the image; each draw is a random crop
    (frame and offset from the caller's generator): every frame's noise is white and
    Gaussian and costs a crop instead of a draw (as ``ground_render.Webcam`` does).
    """

    FRAMES = 4
    PAD = 32

    def __init__(self, shape, seed=0):
        """Draw the bank for images of `shape` (H, W) from `seed`."""
        self.shape = tuple(shape)
        padded = (self.FRAMES, self.shape[0] + self.PAD, self.shape[1] + self.PAD)
        self._bank = np.random.default_rng(seed + 101).standard_normal(padded)

    def draw(self, rng=None):
        """Return one frame of N(0, 1) noise (a view of the bank: do not write to it)."""
        rng = np.random.default_rng() if rng is None else rng
        k, dy, dx = (int(v) for v in rng.integers(0, (self.FRAMES, self.PAD + 1,
                                                      self.PAD + 1)))
        return self._bank[k, dy:dy + self.shape[0], dx:dx + self.shape[1]]


class NoisyReadOut:
    """
    A webcam's sensor read-out with noise, linearised about each pixel's noise-free level.

    ``ground_render.Webcam`` reads every frame out exactly: noise added to the ADC codes,
    clipping, the ADC, then the tone curve by a table look-up of 921 600 codes (2.5 ms a
    frame at 640 x 480, half of it the look-up). Here the noise-free level of each pixel in
    8-bit output units, T(c), and the output's noise per unit of the sensor's noise,
    T'(c) sigma(c), are worked out once per change of the light; a frame is then
    round(T(c) + T''(c) sigma^2 / 2 + T'(c) sigma(c) z), saturated to 0..255: two OpenCV
    passes (0.6 ms). That is the exact read-out's mean to second order and its standard
    deviation to first order in the noise (the test compares them level by level: within
    a third of a level, half a level under 1 % of full scale; the 10-bit ADC's step, a
    fraction of the noise, is not reproduced). Where the light is above full scale the
    pixel reads 255 whatever the noise (the exact read-out dips half a level below 255
    within 1 % above full scale).
    """

    SUBCODES = 8      # table steps per ADC code
    NOISE_SCALE = 25.0   # the int8 bank holds N(0, 1) x 25, clipped at 5 sigma
    PAD = 32
    FRAMES = 3

    def __init__(self, webcam, shape, seed=0):
        """Build the tone tables of a ``Webcam`` and an int8 noise bank for `shape`."""
        s = webcam.settings
        self._webcam = webcam
        self.top = float((1 << int(s.adc_bits)) - 1)
        samples = np.arange(int(self.top) * self.SUBCODES + 2) / (self.SUBCODES * self.top)
        curve = linear_to_srgb(samples) if s.tone_curve == 'srgb' else np.clip(samples, 0, 1)
        curve = 255.0 * curve
        per_code = np.gradient(curve) * self.SUBCODES
        # half the curvature per code^2: E[T(c + s z)] = T(c) + T''(c) s^2 / 2 + ...
        bend = 0.5 * np.gradient(per_code) * self.SUBCODES
        slope = per_code / self.NOISE_SCALE     # per unit of the int8 noise bank
        curve[-1], slope[-1], bend[-1] = 255.0, 0.0, 0.0    # above full scale: saturated
        # the noise is a function of the light, so are the level and the gain: one table
        # each, indexed by the light
        sigma = webcam.noise_sigma(samples.astype(np.float32)).astype(float) * self.top
        self._level = (curve + bend * sigma * sigma).astype(np.float32)
        self._gain = (slope * sigma).astype(np.float32)
        self._last = len(curve) - 1
        self.shape = tuple(shape)
        # flat frames a few rows longer than the image: a crop at any offset is contiguous
        self._size = int(np.prod(self.shape))
        self._slack = self.PAD * int(np.prod(self.shape[1:]))
        draw = np.random.default_rng(seed + 211).standard_normal(
            (self.FRAMES, self._size + self._slack), dtype=np.float32)
        self._bank = np.clip(np.rint(draw * np.float32(self.NOISE_SCALE)),
                             -127, 127).astype(np.int8)

    def prepare(self, light):
        """Return (level, gain) float32 for linear `light` on the sensor (after the optics)."""
        light = np.asarray(light, dtype=np.float32)
        index = light * np.float32(self.top * self.SUBCODES)
        np.clip(index, 0.0, float(self._last), out=index)
        index += np.float32(0.5)
        index = index.astype(np.intp)
        return np.take(self._level, index), np.take(self._gain, index)

    def expose(self, prepared, rng=None):
        """Return the 8-bit frame of (level, gain): noise from a random offset in the bank."""
        level, gain = prepared
        rng = np.random.default_rng() if rng is None else rng
        k, offset = (int(v) for v in rng.integers(0, (self.FRAMES, self._slack + 1)))
        noise = self._bank[k, offset:offset + self._size].reshape(level.shape)
        image = cv2.add(level, cv2.multiply(noise, gain, dtype=cv2.CV_32F), dtype=cv2.CV_8U)
        quality = self._webcam.settings.jpeg_quality
        return jpeg_round_trip(image, quality) if quality > 0 else image


class RgbCamera:
    """Renders the lit panel, the marker, the char and the light spot as a webcam does."""

    def __init__(self, panel_extent, pixel_size, settings=None, marker_side=0.04,
                 marker_id=0, dictionary='DICT_4X4_50', seed=0):
        """Build the panel's albedo texture (pixels aligned with the char raster)."""
        self.settings = settings or RgbSettings()
        self.camera = self.settings.camera()
        self._renderer = GroundRenderer(self.camera, supersample=self.settings.supersample)
        self._webcam = self._renderer.webcam(self.settings.webcam(seed + 7))
        s = self.settings
        noisy = s.read_noise > 0.0 or s.full_well_electrons > 0.0
        self._read_out = (NoisyReadOut(self._webcam, (s.height, s.width, 3), seed + 7)
                          if noisy and not s.bayer and not s.exact_read_out else None)
        texture = make_panel_texture(extent=panel_extent, metres_per_pixel=pixel_size,
                                     marker_side=marker_side, marker_id=marker_id,
                                     dictionary=dictionary, seed=seed)
        self.extent = tuple(panel_extent)
        self.pixel_size = float(pixel_size)
        self._wood = decode_srgb8(texture.image)          # linear; rows from y_max (top view)
        self._albedo = GroundTexture(image=self._wood.copy(), extent=self.extent, linear=True)
        self._char_rgb = decode_srgb8(np.array([CHAR_RGB], np.uint8))[0]
        self._panel = None          # optics(light of the albedo) at `_panel_pose`
        self._panel_pose = None
        self._dirty = []            # albedo raster boxes changed since `_panel` was made
        self._light_source = None   # the light window of the last frame
        self._attenuation = None    # and its direct sun's share
        self._window_rect = None    # image rectangle of the window's change to the light
        self._window_term = None    # and that change
        self._window_texture = None  # the window's change on the panel (albedo x change)
        self._frame = None          # the last frame's light on the sensor
        self._prepared = None       # and its noise-free sensor stage
        self.renders = {'frames': 0, 'panel': 0, 'panel_parts': 0, 'light': 0}

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
        self._dirty.append((r0, r1, c0, c1))

    def top_view(self, char):
        """
        Return the panel as a person sees it from above (H, W, 3) uint8 sRGB, row 0 at y_max.

        The renderer's own reflectance: the wood texture with the ArUco marker, darkened
        towards the char colour by the char fraction `char` (raster rows from y_min), under
        even white light, one pixel per raster pixel (square).
        """
        chi = np.flipud(np.asarray(char, dtype=np.float32))[:, :, None]
        albedo = self._wood * (1.0 - chi) + self._char_rgb * chi
        return np.rint(255.0 * linear_to_srgb(albedo)).astype(np.uint8)

    def render(self, T_world_camera, light=None, attenuation=1.0, rng=None):
        """
        Return the RGB image (H, W, 3) uint8 at a camera pose.

        The panel is lit by the sky (`diffuse_fraction` of the clear direct sun, whatever
        the clouds) and by the direct sun times `attenuation` (its share of the clear-sky
        value under clouds), except in `light` = (rows, cols, lit) from ``light_window``:
        the direct sun there, relative to the clear direct sun on the panel (0 in the lens
        shadow, far above 1 in the focus).
        """
        self.renders['frames'] += 1
        pose = np.asarray(T_world_camera, dtype=np.float64).tobytes()
        attenuation = float(attenuation)
        whole = (pose != self._panel_pose or self._panel is None or self._frame is None
                 or attenuation != self._attenuation)
        parts = self._panel_light(T_world_camera, pose)
        changed = [rect for _, rect in parts]
        if light is not self._light_source or whole:
            changed.append(self._window_rect)   # where the old window was
            self._window(T_world_camera, light, attenuation)
            changed.append(self._window_rect)
        else:
            self._window_update(T_world_camera, [box for box, _ in parts])
        self._light_source, self._attenuation = light, attenuation
        if whole:
            self._compose((0, 0, self.camera.width, self.camera.height), prepare_all=True)
        else:
            for rect in _merged([rect for rect in changed if rect is not None]):
                self._compose(rect)
        if self._read_out is not None:
            return self._read_out.expose(self._prepared, rng)
        return self._webcam.expose(self._prepared, rng)

    def panel_light(self, light, attenuation=1.0):
        """
        Return (rows, cols, light (h, w, 3)): what each raster pixel of `light`'s window sends.

        Linear, relative to the sensor's full scale before the lens (exposure x albedo x
        irradiance): the ground truth of what the camera images there (for tests).
        """
        s = self.settings
        rows, cols, lit = light
        height = self._albedo.image.shape[0]
        albedo = np.flipud(self._albedo.image[height - rows.stop:height - rows.start, cols])
        irradiance = (s.diffuse_fraction + attenuation * lit) / (1.0 + s.diffuse_fraction)
        return rows, cols, s.exposure * albedo * irradiance[:, :, None]

    def _panel_light(self, T_world_camera, pose):
        """
        Keep the panel's light through the optics at a pose (albedo x 1) up to date.

        Return the (raster box, image rectangle) of each part redone (none after a move:
        the caller redoes all).
        """
        changed = []
        if pose != self._panel_pose or self._panel is None:
            self.renders['panel'] += 1
            self._panel = self._webcam.optics(self._radiance(
                T_world_camera, self._albedo))
            self._panel_pose, self._dirty = pose, []
        for r0, r1, c0, c1 in self._dirty:
            rect = self._image_rect(T_world_camera, self._raster_box_world(r0, r1, c0, c1))
            if rect is None:
                continue
            self.renders['panel_parts'] += 1
            wide, inner = rect
            part = self._webcam.optics(self._radiance(
                T_world_camera, self._albedo, rect=wide), wide)
            x0, y0, x1, y1 = inner
            self._panel[y0:y1, x0:x1] = part[y0 - wide[1]:y1 - wide[1],
                                             x0 - wide[0]:x1 - wide[0]]
            changed.append(((r0, r1, c0, c1), inner))
        self._dirty = []
        return changed

    def _window(self, T_world_camera, light, attenuation):
        """Render the lens shadow and the focus's change to the light, over their region."""
        self._window_rect = self._window_term = self._window_texture = None
        if light is None or attenuation <= 0.0:
            return
        self.renders['light'] += 1
        rows, cols, lit = light
        box = self._raster_box_world(rows.start, rows.stop, cols.start, cols.stop)
        rect = self._image_rect(T_world_camera, box)
        if rect is None:
            return
        s = self.settings
        self._window_change = np.flipud(lit)[:, :, None] - np.float32(1.0)   # rows from y_max
        self._window_change *= np.float32(s.exposure * attenuation / (1.0 + s.diffuse_fraction))
        self._window_rows, self._window_cols = rows, cols
        height = self._albedo.image.shape[0]
        patch = self._albedo.image[height - rows.stop:height - rows.start, cols]
        self._window_texture = GroundTexture(image=patch * self._window_change, extent=box,
                                             linear=True)
        wide, inner = rect
        term = self._webcam.optics(self._radiance(
            T_world_camera, self._window_texture, rect=wide), wide)
        x0, y0, x1, y1 = inner
        self._window_rect = inner
        self._window_term = term[y0 - wide[1]:y1 - wide[1], x0 - wide[0]:x1 - wide[0]].copy()

    def _window_update(self, T_world_camera, boxes):
        """Redo the window's change where char changed the albedo (raster `boxes`)."""
        if self._window_texture is None:
            return
        rows, cols = self._window_rows, self._window_cols
        height = self._albedo.image.shape[0]
        for r0, r1, c0, c1 in boxes:
            r0, r1 = max(r0, rows.start), min(r1, rows.stop)
            c0, c1 = max(c0, cols.start), min(c1, cols.stop)
            if r1 <= r0 or c1 <= c0:
                continue
            # texture rows run from y_max: raster rows r0..r1 are these
            top, window_top = slice(height - r1, height - r0), slice(rows.stop - r1,
                                                                     rows.stop - r0)
            part = slice(c0 - cols.start, c1 - cols.start)
            self._window_texture.image[window_top, part] = \
                self._albedo.image[top, c0:c1] * self._window_change[window_top, part]
            rect = self._image_rect(T_world_camera, self._raster_box_world(r0, r1, c0, c1))
            inner = None if rect is None else _intersection(rect[1], self._window_rect)
            if inner is None:
                continue
            wide = rect[0]
            term = self._webcam.optics(self._radiance(
                T_world_camera, self._window_texture, rect=wide), wide)
            x0, y0, x1, y1 = inner
            wx, wy = self._window_rect[:2]
            self._window_term[y0 - wy:y1 - wy, x0 - wx:x1 - wx] = \
                term[y0 - wide[1]:y1 - wide[1], x0 - wide[0]:x1 - wide[0]]

    def _compose(self, rect, prepare_all=False):
        """Redo the frame's light and its prepared sensor stage inside `rect` (x0, y0, x1, y1)."""
        s = self.settings
        uniform = (s.diffuse_fraction + self._attenuation) / (1.0 + s.diffuse_fraction)
        if prepare_all:
            self._frame = self._panel * np.float32(s.exposure * uniform)
        else:
            x0, y0, x1, y1 = rect
            self._frame[y0:y1, x0:x1] = self._panel[y0:y1, x0:x1] * np.float32(
                s.exposure * uniform)
        if self._window_rect is not None:
            both = _intersection(rect, self._window_rect)
            if both is not None:
                wx, wy = self._window_rect[:2]
                x0, y0, x1, y1 = both
                self._frame[y0:y1, x0:x1] += self._window_term[y0 - wy:y1 - wy, x0 - wx:x1 - wx]
        prepare = (self._webcam.prepare if self._read_out is None
                   else self._read_out.prepare)
        if prepare_all:
            self._prepared = prepare(self._frame)
            return
        x0, y0, x1, y1 = rect
        first, second = prepare(self._frame[y0:y1, x0:x1])
        self._prepared[0][y0:y1, x0:x1] = first
        if second is not None:
            self._prepared[1][y0:y1, x0:x1] = second

    def _radiance(self, T_world_camera, texture, rect=None):
        """
        Return a linear texture's light per pixel (of `rect` (x0, y0, x1, y1), or all).

        A pinhole camera without distortion maps the ground plane to the image by a
        homography: one ``cv2.warpPerspective`` of the texture (no per-pixel rays, maps or
        NaN handling: a moving camera's frame costs a third). Cameras with distortion,
        supersampling, or pixels that look above the horizon go through
        ``GroundRenderer.radiance``'s per-pixel rays.
        """
        mapping = self._texture_homography(T_world_camera, texture)
        if mapping is None:
            return self._renderer.radiance(T_world_camera, texture, background=0.0,
                                           rect=rect)
        homography, downward = mapping
        x0, y0, x1, y1 = rect or (0, 0, self.camera.width, self.camera.height)
        if x0 or y0:
            homography = homography @ np.array([[1.0, 0.0, x0], [0.0, 1.0, y0],
                                                [0.0, 0.0, 1.0]])
        source = texture.linear_image()
        channels = 1 if source.ndim == 2 else source.shape[2]
        light = cv2.warpPerspective(source, homography, (x1 - x0, y1 - y0),
                                    flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                    borderMode=cv2.BORDER_CONSTANT,
                                    borderValue=(0.0,) * max(channels, 1))
        if downward is not None:    # the pixels at and above the horizon see no panel
            _blank_above_horizon(light, downward, x0, y0)
        return light

    def _texture_homography(self, T_world_camera, texture):
        """
        Return the 3 x 3 map from image pixels (centres at integers) to texture pixels.

        Returns (homography, None), or (homography, (a, b, c)) when part of the image
        looks at or above the horizon: a u + b v + c >= 0 there (no panel). None when the
        camera distorts, supersamples or sees no ground at all. A pixel's ray is
        d = R K^-1 (u, v, 1); it meets z = 0 at o - (o_z / d_z) d, so the ground point is
        the homogeneous (o_x d_z - o_z d_x, o_y d_z - o_z d_y, d_z): linear in (u, v, 1);
        the texture's pixel grid is affine in the ground point.
        """
        if self._renderer.supersample != 1 or np.any(self.camera.distortion):
            return None
        pose = np.asarray(T_world_camera, dtype=float)
        rays = pose[:3, :3] @ np.linalg.inv(np.asarray(self.camera.matrix, dtype=float))
        width, height = self.camera.width, self.camera.height
        corners = np.array([[-0.5, -0.5, 1.0], [width - 0.5, -0.5, 1.0],
                            [-0.5, height - 0.5, 1.0], [width - 0.5, height - 0.5, 1.0]])
        downward = corners @ rays[2]              # d_z, affine in (u, v): its corners
        if not np.any(downward < 0.0) or pose[2, 3] <= 0.0:
            return None
        ox, oy, oz = pose[:3, 3]
        ground = np.stack([ox * rays[2] - oz * rays[0], oy * rays[2] - oz * rays[1], rays[2]])
        x_min, _, _, y_max = texture.extent
        sx, sy = texture.metres_per_pixel
        to_texture = np.array([[1.0 / sx, 0.0, -x_min / sx - 0.5],
                               [0.0, -1.0 / sy, y_max / sy - 0.5],
                               [0.0, 0.0, 1.0]])
        horizon = None if np.all(downward < 0.0) else tuple(float(v) for v in rays[2])
        return to_texture @ ground, horizon

    def _raster_box_world(self, r0, r1, c0, c1):
        """Return the world extent (x_min, x_max, y_min, y_max) of raster rows/cols [m]."""
        x_min, _, y_min, _ = self.extent
        cell = self.pixel_size
        return (x_min + c0 * cell, x_min + c1 * cell, y_min + r0 * cell, y_min + r1 * cell)

    def _image_rect(self, T_world_camera, box):
        """
        Return (wide, inner) image rectangles (x0, y0, x1, y1) [px] of a ground box, or None.

        `inner` holds every pixel that sees the box or its blur; `wide` adds the context the
        blur needs. The whole image when a corner of the box is behind the camera.
        """
        x0, x1, y0, y1 = box
        corners = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
        in_camera = transform_points(invert_transform(T_world_camera), corners)
        width, height = self.camera.width, self.camera.height
        if np.any(in_camera[:, 2] <= 0.0) or np.any(self.camera.distortion):
            pixels = None
        else:
            pixels = self.camera.project(in_camera)
        margin = self._webcam.blur_margin() + 2
        if pixels is None:
            inner = (0, 0, width, height)
        else:
            low = np.floor(pixels.min(axis=0)).astype(int) - margin
            high = np.ceil(pixels.max(axis=0)).astype(int) + margin + 1
            inner = (max(int(low[0]), 0), max(int(low[1]), 0), min(int(high[0]), width),
                     min(int(high[1]), height))
            if inner[2] <= inner[0] or inner[3] <= inner[1]:
                return None
        wide = (max(inner[0] - margin, 0), max(inner[1] - margin, 0),
                min(inner[2] + margin, width), min(inner[3] + margin, height))
        return wide, inner


def _blank_above_horizon(light, downward, x0, y0):
    """
    Zero the pixels of `light` (its corner at image pixel (x0, y0)) at or above the horizon.

    There a u + b v + c >= 0, (a, b, c) = `downward`. Rows wholly above it are zeroed as
    slices, rows it crosses (few: the camera's roll is small) from the crossing column on.
    """
    a, b, c = downward
    height, width = light.shape[:2]
    rows = np.arange(y0, y0 + height)
    left = a * x0 + b * rows + c
    right = a * (x0 + width - 1) + b * rows + c
    light[(left >= 0.0) & (right >= 0.0)] = 0.0
    for row in np.flatnonzero((left >= 0.0) != (right >= 0.0)):
        columns = np.arange(x0, x0 + width)
        light[row][a * columns + b * rows[row] + c >= 0.0] = 0.0


def _intersection(a, b):
    """Return the intersection of two rectangles (x0, y0, x1, y1), or None."""
    if a is None or b is None:
        return None
    x0, y0, x1, y1 = max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3])
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None


def _overlap(a, b):
    """Tell whether two rectangles overlap."""
    return _intersection(a, b) is not None


def _merged(rects):
    """Return one even-aligned rectangle covering all of `rects` (the Bayer phase), or none."""
    if not rects:
        return []
    x0, y0 = min(r[0] for r in rects) // 2 * 2, min(r[1] for r in rects) // 2 * 2
    return [(x0, y0, max(r[2] for r in rects), max(r[3] for r in rects))]


def light_window(field, shape, origin, pixel_size, window):
    """
    Return (rows, cols, lit): the direct light in a window of the panel raster (rows from y_min).

    `lit` is the direct sun's irradiance relative to the direct sun on the panel, per unit
    DNI: 0 in the lens shadow, 1 outside it, plus the concentrated rays binned per pixel
    (far above 1 in the focus). None if the window misses the panel. The sky's diffuse
    light is the camera's to add (`RgbCamera.render`): a cloud dims the direct sun, not it.
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
    # the rays' power binned per raster pixel (bincount: np.histogram2d's searches cost
    # ~10 ms for 120 000 rays, this ~1 ms)
    column = np.floor((field.points[:, 0] - origin[0]) / pixel_size).astype(np.int64) - c0
    row = np.floor((field.points[:, 1] - origin[1]) / pixel_size).astype(np.int64) - r0
    inside = (column >= 0) & (column < c1 - c0) & (row >= 0) & (row < r1 - r0)
    binned = np.bincount(row[inside] * (c1 - c0) + column[inside],
                         weights=field.power[inside],
                         minlength=(r1 - r0) * (c1 - c0)).reshape(r1 - r0, c1 - c0)
    concentrated = binned / (pixel_size * pixel_size) / max(field.direct, 1e-6)
    concentrated = cv2.GaussianBlur(concentrated.astype(np.float32), (0, 0), 0.7)
    lit = np.where(shadow, 0.0, 1.0) + concentrated
    return slice(r0, r1), slice(c0, c1), lit.astype(np.float32)
