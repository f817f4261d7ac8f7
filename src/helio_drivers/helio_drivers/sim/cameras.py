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
point its centre ray meets, plus Gaussian noise (NETD), through the camera's radiometric error
(reading = T (1 + gain_error) + offset_error), read out between its floor and its cap (the
paper's camera: 180.9 degC), encoded in centikelvin (16UC1, or mono16 as ``usb_cam``
publishes a Lepton's Y16 stream). ``ThermalSettings.from_spec`` builds a datasheet's camera
(``helio_optics.thermal_cameras``: the paper's, a Lepton 3.5 in high or low gain) with a
radiometric error drawn within half its stated accuracy, and `FlatFieldCorrection` freezes its
output as a Lepton's shutter does (issue 29).
"""

from dataclasses import dataclass
import math
import threading

import cv2
from helio_drivers.sim.kernels import (bin_on_raster, noisy_read_out, relit_texture,
                                       thermal_counts, thermal_counts_at, tone_table_read_out)
from helio_optics.calibration_board import draw_board
from helio_optics.geometry import PinholeCamera
from helio_optics.ground_render import (decode_srgb8, GroundRenderer, GroundTexture,
                                        jpeg_round_trip, linear_to_srgb,
                                        make_panel_texture, WebcamSettings)
import numpy as np

KELVIN = 273.15
CONCENTRATED_BLUR_SIGMA = 0.7   # the binned rays' smoothing in the light window [raster px]
# raster pixels around the rays the smoothing reaches (its kernel's radius, 3), twice over
CONCENTRATED_BLUR_REACH = 8
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
    encoding: str = '16UC1'         # '16UC1' or 'mono16' (usb_cam's Y16), both centikelvin
    offset_error: float = 0.0       # the camera's true radiometric offset [K]
    gain_error: float = 0.0         # ... and gain error: T (1 + gain_error) + offset [-]
    ffc_period: float = 0.0         # a flat-field correction every this [s sim] (0: none)
    ffc_freeze_min: float = 0.3     # each freezes the output this long at least [s sim]
    ffc_freeze_max: float = 1.0     # ... and at most [s sim]

    def camera(self):
        """Return the PinholeCamera of these settings."""
        return PinholeCamera.from_fov(self.width, self.height, self.horizontal_fov)

    @classmethod
    def from_spec(cls, spec, seed=0):
        """
        Return the settings of a camera of datasheet `spec` (a ThermalCameraSpec).

        Its radiometric error is drawn from `seed`: an offset within half the stated
        absolute accuracy and a gain error within half the relative one (a "typical"
        accuracy holds for most units, not only at its bounds).
        """
        draw = np.random.default_rng(seed + 303).uniform(-0.5, 0.5, 2)
        return cls(width=spec.width, height=spec.height, horizontal_fov=spec.horizontal_fov,
                   cap=spec.cap, floor=spec.floor, noise_sigma=spec.netd,
                   encoding=spec.encoding, offset_error=float(draw[0] * spec.accuracy_abs),
                   gain_error=float(draw[1] * spec.accuracy_rel), ffc_period=spec.ffc_period,
                   ffc_freeze_min=spec.ffc_freeze[0], ffc_freeze_max=spec.ffc_freeze[1])


class FlatFieldCorrection:
    """
    When a thermal camera's output is frozen by its flat-field correction (simulated time).

    The first correction comes after one `period` and the next one `period` after each
    (a Lepton's automatic FFC: 3 minutes by default); each freezes the output for a time
    drawn from `seed` between `shortest` and `longest`. A period of 0: never.
    """

    def __init__(self, period, shortest, longest, seed=0):
        """Draw the freezes' lengths from `seed`; ValueError for a bad range."""
        if period < 0.0 or not 0.0 <= shortest <= longest:
            raise ValueError(f'flat-field correction: period {period} must be >= 0 and '
                             f'0 <= shortest {shortest} <= longest {longest}')
        if period > 0.0 and longest >= period:
            raise ValueError(f'flat-field correction: a freeze of up to {longest} s every '
                             f'{period} s leaves no frame')
        self.period, self.shortest, self.longest = float(period), shortest, longest
        self._rng = np.random.default_rng(seed + 707)
        self._lengths = {}

    def freeze_length(self, index):
        """Return the length of the `index`-th freeze (1, 2, ...) [s]."""
        while index not in self._lengths:
            self._lengths[len(self._lengths) + 1] = float(
                self._rng.uniform(self.shortest, self.longest))
        return self._lengths[index]

    def frozen(self, time):
        """Return whether the output is frozen at `time` [s since the start]."""
        if self.period <= 0.0 or time < self.period:
            return False
        index = int(time // self.period)
        return time - index * self.period < self.freeze_length(index)


def celsius_to_centikelvin(temperature):
    """Encode temperatures [degC] as uint16 centikelvin (the Lepton's radiometric format)."""
    return np.clip(np.rint((np.asarray(temperature, float) + KELVIN) * 100.0),
                   0, 65535).astype(np.uint16)


def centikelvin_to_celsius(counts):
    """Decode uint16 centikelvin to degC."""
    return np.asarray(counts, float) / 100.0 - KELVIN


class ThermalCamera:
    """Renders the panel surface temperature as the thermal camera reads it."""

    def __init__(self, settings=None, seed=0, camera=None):
        """
        Cache the pixel-centre rays of the camera; `seed` draws the noise bank.

        `camera`: the true PinholeCamera (a build's, ``sim.build``); default the settings'.
        """
        self.settings = settings or ThermalSettings()
        self.camera = camera or self.settings.camera()
        self._renderer = GroundRenderer(self.camera, supersample=1)
        self._view_key = None      # (pose, panel, placement) of the kept view
        self._view = None          # (pixels seeing the panel, their surface sampler)
        self._ground = None        # the pixels' ground points (x, y) of the kept view
        self._noise = NoiseBank((self.camera.height, self.camera.width), seed)
        self._no_noise = np.zeros((self.camera.height, self.camera.width))

    def temperatures(self, panel, T_world_camera, rng=None):
        """Return the read-out [degC] per pixel: the field at pixel centres, error, noise, cap."""
        seen, sample, _ = self._seen(panel, T_world_camera)
        field = np.full(seen.shape, panel.wood.ambient)
        field[seen] = sample()
        field = field * (1.0 + self.settings.gain_error) + self.settings.offset_error
        if self.settings.noise_sigma > 0.0:
            field += self.settings.noise_sigma * self._noise.draw(rng)
        return np.clip(field, self.settings.floor, self.settings.cap, out=field)

    def _seen(self, panel, T_world_camera):
        """
        Return (pixels that see the panel, their surface sampler, each pixel's point or -1).

        Kept while the camera and the heat patch stand still (they do while a dot heats):
        a frame then costs the gather of the surface field, not the ray casts.
        """
        self._ground_points(panel, T_world_camera)
        if self._view is None:
            x, y = self._ground
            seen = np.isfinite(x)
            position = np.full(seen.shape, -1, np.intp)
            position[seen] = np.arange(np.count_nonzero(seen))
            self._view = (seen, panel.surface_sampler(x[seen], y[seen]), position)
        return self._view

    def _ground_points(self, panel, T_world_camera):
        """Return True when the view is new: the pixels' ground points (x, y) were cast."""
        key = (np.asarray(T_world_camera, dtype=np.float64).tobytes(), id(panel),
               panel.placement)
        if key == self._view_key:
            return False
        self._ground = self._renderer.ground_points(T_world_camera)
        self._view_key = key
        self._view = None
        return True

    def image(self, panel, T_world_camera, rng=None):
        """
        Return the 16UC1 centikelvin read-out (H, W) as uint16.

        What ``celsius_to_centikelvin(temperatures(...))`` gives, in one compiled pass: at a
        new view from the pixels' ground points (``kernels.thermal_counts_at``), at a view
        seen before through its kept sampler (``kernels.thermal_counts``).
        """
        s = self.settings
        noisy = s.noise_sigma > 0.0
        ambient = float(panel.wood.ambient)
        sigma = float(s.noise_sigma) if noisy else 0.0
        out = np.empty((self.camera.height, self.camera.width), np.uint16)
        if self._ground_points(panel, T_world_camera):
            surface, far = panel.surface_rise()
            noise = self._noise.draw(rng) if noisy else self._no_noise
            x, y = self._ground
            bounds = np.array([panel.x_edges[0], panel.x_edges[-1], panel.y_edges[0],
                               panel.y_edges[-1]])
            thermal_counts_at(x, y, panel.x_centres, panel.y_centres, bounds, surface, far,
                              ambient, noise, sigma, float(s.floor), float(s.cap),
                              float(s.gain_error), float(s.offset_error), out)
            return out
        _, sampler, position = self._seen(panel, T_world_camera)
        surface, far = sampler.surface()
        noise = self._noise.draw(rng) if noisy else self._no_noise
        thermal_counts(position, sampler.corner, sampler.columns, sampler.wx, sampler.wy,
                       sampler.inside, surface, far, ambient, noise, sigma, float(s.floor),
                       float(s.cap), float(s.gain_error), float(s.offset_error), out)
        return out


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
    round(T(c) + T''(c) sigma^2 / 2 + T'(c) sigma(c) z), saturated to 0..255: the tables
    are read once per change of the light (``kernels.tone_table_read_out``), a frame is one
    vectorised pass over the level, the gain and the noise (``kernels.noisy_read_out``,
    0.13 ms; a table look-up per element in the frame's pass cost 0.9 ms). That is the
    exact read-out's mean to second order and its standard deviation to first order in the
    noise (the test compares them level by level: within
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
        self._no_scale = np.zeros((0, 0), np.float32)
        self._index = None
        self.shape = tuple(shape)
        # flat frames a few rows longer than the image: a crop at any offset is contiguous
        self._size = int(np.prod(self.shape))
        self._slack = self.PAD * int(np.prod(self.shape[1:]))
        draw = np.random.default_rng(seed + 211).standard_normal(
            (self.FRAMES, self._size + self._slack), dtype=np.float32)
        self._bank = np.clip(np.rint(draw * np.float32(self.NOISE_SCALE)),
                             -127, 127).astype(np.int8)

    def index_scale(self):
        """Return the table steps per unit of linear light (for `prepare`'s `scale`)."""
        return self.top * self.SUBCODES

    def prepare(self, light, scale=None, out=None):
        """
        Return (level, gain) (h, w, 3) float32 for linear `light` on the sensor (after optics).

        `light` (h, w, channels >= 3): the first three channels are read (a warp's padding
        channel is left where it is). `scale` (h, w): table steps per unit of light per
        pixel (`index_scale` x a gain the light still needs, such as the vignetting: one
        pass for both), or None. `out`: (level, gain) arrays (h, w, 3) float32 to fill,
        views of a kept frame's stage of any strides (written in place), or None.
        """
        light = np.asarray(light, dtype=np.float32)
        if light.ndim != 3 or light.shape[2] < 3:
            raise ValueError(f'light must be (h, w, >= 3), got shape {light.shape}')
        shape = light.shape[:2] + (3,)
        scale = self._no_scale if scale is None else np.asarray(
            np.broadcast_to(scale, shape[:2]), dtype=np.float32)
        if out is None:
            out = (np.empty(shape, np.float32), np.empty(shape, np.float32))
        elif any(part.shape != shape or part.dtype != np.float32 for part in out):
            raise ValueError(f'out must be two float32 arrays of shape {shape}')
        if self._index is None or self._index.size < 3 * shape[1]:
            self._index = np.empty(3 * shape[1], np.int32)     # one row's, reused
        tone_table_read_out(light, scale, np.float32(self.index_scale()), self._last,
                            self._level, self._gain, out[0], out[1], self._index)
        return out

    def draw(self, rng=None):
        """Return the noise of one frame: (bank frame, offset) drawn from `rng`."""
        rng = np.random.default_rng() if rng is None else rng
        return tuple(int(v) for v in rng.integers(0, (self.FRAMES, self._slack + 1)))

    def expose(self, prepared, rng=None, drawn=None):
        """
        Return the 8-bit frame of (level, gain): noise from a random offset in the bank.

        `drawn`: the frame's noise from ``draw`` (drawn earlier, on the thread that owns
        `rng`); None draws it from `rng` now.
        """
        level, gain = (np.ascontiguousarray(part) for part in prepared)
        k, offset = self.draw(rng) if drawn is None else drawn
        noise = self._bank[k, offset:offset + level.size]
        image = np.empty(level.shape, np.uint8)
        noisy_read_out(level.reshape(-1), gain.reshape(-1), noise, image.reshape(-1))
        quality = self._webcam.settings.jpeg_quality
        return jpeg_round_trip(image, quality) if quality > 0 else image


class DevelopingFrame:
    """
    A staged RGB frame (``RgbCamera.stage``): call it, once or more, on any thread, for its image.

    Frames develop in the order they were staged: a frame first develops (or waits for)
    the one staged before it, which it holds until then. The first caller of a frame
    develops it; a caller meanwhile waits for that one. An error while developing is
    raised to every caller of that frame.
    """

    def __init__(self, develop, after=None):
        """Hold `develop` (no arguments -> the image), to run after frame `after`."""
        self._develop = develop
        self._after = after
        self._claim = threading.Lock()
        self._done = threading.Event()
        self._image = None
        self._error = None

    @classmethod
    def developed(cls, image):
        """Return a frame developed already, holding `image`."""
        frame = cls(None)
        frame._claim.acquire()
        frame._image = image
        frame._done.set()
        return frame

    def __call__(self):
        """Return the image (H, W, 3) uint8, developing it if no thread has begun to."""
        self.wait_or_develop()
        if self._error is not None:
            raise self._error
        return self._image

    def done(self):
        """Tell whether the frame is developed (or failed to be)."""
        return self._done.is_set()

    def wait_or_develop(self):
        """Develop the frames staged before this one and it, or wait for who began them."""
        chain, frame = [], self
        while frame is not None and not frame._done.is_set():
            chain.append(frame)
            frame = frame._after
        for frame in reversed(chain):
            frame._develop_or_wait()

    def _develop_or_wait(self):
        if self._claim.acquire(blocking=False):
            try:
                self._image = self._develop()
            except Exception as error:     # raised to each caller of the frame
                self._error = error
            finally:
                self._develop = self._after = None
                self._done.set()
        else:
            self._done.wait()


class RgbCamera:
    """Renders the lit panel, the marker, the char and the light spot as a webcam does."""

    def __init__(self, panel_extent, pixel_size, settings=None, marker_side=0.04,
                 marker_id=0, dictionary='DICT_4X4_50', seed=0, print_reflectance=(0.0, 1.0),
                 camera=None, marker_scale=1.0, board=None):
        """
        Build the panel's albedo texture (pixels aligned with the char raster).

        `print_reflectance` (ink, paper): the marker print's linear reflectance
        (``ground_render.draw_marker``). `camera`: the true PinholeCamera (a build's,
        ``sim.build``: distortion included); default the settings' ideal one.
        `marker_scale`: the marker as printed over `marker_side` (a build's). `board`:
        (BoardSpec, centre (x, y), yaw) of a ChArUco board printed as the marker is
        (``helio_optics.calibration_board.draw_board``), or None.
        """
        self.settings = settings or RgbSettings()
        self.camera = camera or self.settings.camera()
        self._renderer = GroundRenderer(self.camera, supersample=self.settings.supersample)
        self._webcam = self._renderer.webcam(self.settings.webcam(seed + 7))
        s = self.settings
        noisy = s.read_noise > 0.0 or s.full_well_electrons > 0.0
        self._read_out = (NoisyReadOut(self._webcam, (s.height, s.width, 3), seed + 7)
                          if noisy and not s.bayer and not s.exact_read_out else None)
        texture = make_panel_texture(extent=panel_extent, metres_per_pixel=pixel_size,
                                     marker_side=marker_side, marker_id=marker_id,
                                     dictionary=dictionary, seed=seed,
                                     print_reflectance=print_reflectance,
                                     marker_scale=marker_scale)
        if board is not None:
            spec, centre, yaw = board
            draw_board(texture, spec, centre, yaw, print_reflectance)
        self.extent = tuple(panel_extent)
        self.pixel_size = float(pixel_size)
        # linear, rows from y_max (top view); RGB and a fourth, empty channel: OpenCV warps
        # four float channels in half the time of three (``_radiance``)
        self._wood = _with_padding_channel(decode_srgb8(texture.image))
        self._albedo = GroundTexture(image=self._wood.copy(), extent=self.extent, linear=True)
        self._char_rgb = _with_padding_channel(decode_srgb8(np.array([CHAR_RGB], np.uint8)))[0]
        # the panel's light on the sensor before the optics: albedo x irradiance x exposure
        # (rows from y_max), kept up to date with the char, the window and the clouds
        self._lit = GroundTexture(image=np.empty_like(self._wood), extent=self.extent,
                                  linear=True)
        self._uniform = None        # exposure x daylight outside the window, in `_lit`
        self._attenuation = None    # the direct sun's share it was made for
        self._light_source = None   # the light window of the last frame
        self._window_box = None     # its raster box (r0, r1, c0, c1) and its light per unit
        self._window_light = None   # its (direct sun per unit of DNI share, the sun's light)
        self._no_window = np.zeros((0, 0), np.float32)
        self._dirty = []            # raster boxes of `_lit` changed since `_prepared` was made
        self._prepared = None       # the noise-free sensor stage of the frame at `_pose`
        self._dark = None           # the sensor stage of a frame without light
        self._lit_rect = (0, 0, 0, 0)   # the image rectangle `_prepared` may be lit in
        self._pose = None
        self._view = None           # per-pose geometry (`_pose_view`)
        self._view_key = None
        # the linearised read-out takes the vignetting with its table index (one pass)
        vignette = self._webcam._vignette
        self._index_scale = None
        if self._read_out is not None and vignette is not None:
            self._index_scale = vignette[:, :, 0] * np.float32(self._read_out.index_scale())
        self.renders = {'frames': 0, 'whole': 0, 'parts': 0, 'light': 0}
        self._developing = None     # the DevelopingFrame staged last
        self._char_changes = []     # (box, char fraction) copied since the last frame

    def update_char(self, char, box=None):
        """
        Darken the albedo where the char raster (rows from y_min) changed.

        `box` (r0, r1, c0, c1) limits the look to where the panel reported changes (None:
        nothing changed). The changed part is copied now; the albedo takes it when the next
        staged frame develops (``stage``), or when the camera is asked for its light.
        """
        if box is None:
            return
        r0, r1, c0, c1 = box
        self._char_changes.append(
            (tuple(box), np.flipud(char[r0:r1, c0:c1]).astype(np.float32)[:, :, None]))

    def _apply_char_changes(self, changes):
        """Darken the albedo (and relight the lit texture) by copied char `changes`."""
        height = self._wood.shape[0]
        for box, chi in changes:
            r0, r1, c0, c1 = box
            top = slice(height - r1, height - r0)
            self._albedo.image[top, c0:c1] = (self._wood[top, c0:c1] * (1.0 - chi)
                                              + self._char_rgb * chi)
            if self._uniform is not None:
                self._relight(box)

    def _settle(self):
        """Develop (or wait for) every staged frame and take the char changes since."""
        if self._developing is not None:
            self._developing.wait_or_develop()
            self._developing = None
        changes, self._char_changes = self._char_changes, []
        self._apply_char_changes(changes)

    def top_view(self, char):
        """
        Return the panel as a person sees it from above (H, W, 3) uint8 sRGB, row 0 at y_max.

        The renderer's own reflectance: the wood texture with the ArUco marker, darkened
        towards the char colour by the char fraction `char` (raster rows from y_min), under
        even white light, one pixel per raster pixel (square).
        """
        chi = np.flipud(np.asarray(char, dtype=np.float32))[:, :, None]
        albedo = self._wood[:, :, :3] * (1.0 - chi) + self._char_rgb[:3] * chi
        return np.rint(255.0 * linear_to_srgb(albedo)).astype(np.uint8)

    def render(self, T_world_camera, light=None, attenuation=1.0, rng=None):
        """
        Return the RGB image (H, W, 3) uint8 at a camera pose.

        The panel is lit by the sky (`diffuse_fraction` of the clear direct sun, whatever
        the clouds) and by the direct sun times `attenuation` (its share of the clear-sky
        value under clouds), except in `light` = (rows, cols, lit) from ``light_window``:
        the direct sun there, relative to the clear direct sun on the panel (0 in the lens
        shadow, far above 1 in the focus).

        Kept between frames: the panel's lit texture (albedo x irradiance x exposure),
        changed only where the char, the window or the clouds changed it, and the frame's
        light through the optics with its noise-free sensor stage at the present pose,
        redone over the image region of the texture's changes (all of it after a move or
        a cloud): an unchanged scene costs the noise and the read-out.

        The same as ``stage(...)()``: staging and developing on one thread.
        """
        return self.stage(T_world_camera, light, attenuation, rng)()

    def stage(self, T_world_camera, light=None, attenuation=1.0, rng=None):
        """
        Take a frame's scene now; return its ``DevelopingFrame`` (call it for the image).

        Staging is the cheap part, on the thread that owns the world: it keeps the pose,
        the light window, the clouds' share and the char changes since the last frame
        (``update_char``, copied there) and draws the frame's noise from `rng`.
        Developing is the rest: the lit texture takes the changes, then the optics, the
        sensor stage and the read-out (all of a moving camera's cost). It reads nothing the
        world changes, so it may run on another thread while the world steps on; frames
        develop in the order they were staged (``DevelopingFrame``), and the images are
        the ones ``render`` gives for the same calls. Without the linearised read-out (a
        Bayer mosaic or the exact read-out draw their noise as they go) the frame is
        developed here, before ``stage`` returns.
        """
        T_world_camera = np.array(T_world_camera, dtype=np.float64)
        scene = (T_world_camera, light, float(attenuation), self._char_changes)
        self._char_changes = []
        if self._read_out is None:
            self._settle()
            return DevelopingFrame.developed(self._develop(scene, rng=rng))
        drawn = self._read_out.draw(rng)
        self._developing = DevelopingFrame(lambda: self._develop(scene, drawn=drawn),
                                           after=self._developing)
        return self._developing

    def _develop(self, scene, rng=None, drawn=None):
        """Make a staged frame: the lit texture's changes, its light where needed, read-out."""
        T_world_camera, light, attenuation, char_changes = scene
        self._apply_char_changes(char_changes)
        self.renders['frames'] += 1
        pose = T_world_camera.tobytes()
        whole = pose != self._pose or self._prepared is None
        if attenuation != self._attenuation:
            self._set_daylight(attenuation)
            whole = True
        if light is not self._light_source:
            self._set_window(light)
        if whole:
            self.renders['whole'] += 1
            self._whole_frame(T_world_camera)
            self._pose = pose
        else:
            for box in _merged_boxes(self._dirty):
                rect = self._image_rect(T_world_camera, self._raster_box_world(*box))
                if rect is not None:
                    self.renders['parts'] += 1
                    self._redo(T_world_camera, *rect)
        self._dirty = []
        if self._read_out is not None:
            return self._read_out.expose(self._prepared, rng, drawn)
        return self._webcam.expose(self._prepared, rng)

    def panel_light(self, light, attenuation=1.0):
        """
        Return (rows, cols, light (h, w, 3)): what each raster pixel of `light`'s window sends.

        Linear, relative to the sensor's full scale before the lens (exposure x albedo x
        irradiance): the ground truth of what the camera images there (for tests).
        """
        self._settle()
        s = self.settings
        rows, cols, lit = light
        height = self._albedo.image.shape[0]
        albedo = np.flipud(self._albedo.image[height - rows.stop:height - rows.start, cols, :3])
        irradiance = (s.diffuse_fraction + attenuation * lit) / (1.0 + s.diffuse_fraction)
        return rows, cols, s.exposure * albedo * irradiance[:, :, None]

    # ------------------------------------------------------------------ the lit texture
    def _set_daylight(self, attenuation):
        """Light the whole texture for a new direct-sun share (sky + attenuation x sun)."""
        s = self.settings
        self._attenuation = attenuation
        self._uniform = np.float32(s.exposure * (s.diffuse_fraction + attenuation)
                                   / (1.0 + s.diffuse_fraction))
        np.multiply(self._albedo.image, self._uniform, out=self._lit.image)
        if self._light_source is not None:
            self._set_window(self._light_source, force=True)

    def _set_window(self, light, force=False):
        """Put the lens shadow and the focus of `light` into the texture (the old one out)."""
        s = self.settings
        old, old_light = self._window_box, self._window_light
        self._light_source = light
        self._window_box = self._window_light = None
        if light is not None and self._attenuation > 0.0:
            rows, cols, lit = light
            # exposure x (sky + attenuation x lit) / (1 + sky) = lit x direct + the rest
            self._window_light = (np.ascontiguousarray(lit, dtype=np.float32), np.float32(
                s.exposure * self._attenuation / (1.0 + s.diffuse_fraction)))
            self._window_box = (rows.start, rows.stop, cols.start, cols.stop)
        if not force:
            self.renders['light'] += 1
        boxes = [box for box in (None if force else old, self._window_box) if box is not None]
        for box in _merged_boxes(boxes):
            # the texture holds the old window (or, forced, nothing to compare with)
            self._relight(box, None if force else (old_light, old))

    def _relight(self, box, previous=None):
        """
        Redo the lit texture in raster `box` (r0, r1, c0, c1) and mark it changed.

        `previous`: (window light, window box) the texture holds there now, under the same
        daylight and albedo: only the pixels whose light changed are written. None: all.
        """
        no_window = (self._no_window, np.float32(0.0))
        window, direct = self._window_light or no_window
        old_window, old_direct = (previous[0] or no_window) if previous else no_window
        old_box = previous[1] if previous and previous[1] else (0, 0, 0, 0)
        relit_texture(self._albedo.image, self._lit.image, tuple(int(v) for v in box),
                      self._uniform, window, self._window_box or (0, 0, 0, 0), direct,
                      old_window, old_box, old_direct, previous is not None)
        self._dirty.append(tuple(box))

    # ------------------------------------------------------------------ the frame
    def _blur(self, light):
        """Blur `light` (linear, on the sensor) in place by the optics; return it."""
        sigma = self._webcam.settings.blur_sigma
        if sigma > 0.0:
            cv2.GaussianBlur(light, (0, 0), sigma, dst=light)
        return light

    def _sensor_stage(self, light, rect, out=None):
        """
        Return the prepared sensor stage of blurred `light`, the image's part `rect`.

        `light` (h, w, 3 or 4): the colours, then perhaps the warp's padding channel.

        The vignetting (the optics' last step) goes with the linearised read-out's table
        index; the exact read-out gets the light vignetted (as ``Webcam.optics`` does).
        `out`: the (level, gain) parts of the kept stage the linearised read-out writes
        into (and returns); the exact read-out returns new arrays.
        """
        x0, y0, x1, y1 = rect
        if self._read_out is not None:
            scale = None if self._index_scale is None else self._index_scale[y0:y1, x0:x1]
            return self._read_out.prepare(light, scale, out)
        light = light[:, :, :3]
        vignette = self._webcam._vignette
        if vignette is not None:
            light = light * vignette[y0:y1, x0:x1]
        return self._webcam.prepare(light)

    def _whole_frame(self, T_world_camera):
        """
        Make the frame's sensor stage (`_prepared`) anew at a pose.

        Only the pixels that see the panel or its blur are rendered (``_image_rect`` of the
        panel, over the kept stage's arrays); the rest see no light and take the dark
        frame's stage. From the arm's poses the panel's near edge crosses the image, and a
        third of the frame sees nothing.
        """
        width, height = self.camera.width, self.camera.height
        dark = self._dark_stage()
        if self._prepared is None:
            self._prepared = tuple(None if part is None else part.copy() for part in dark)
        x_min, x_max, y_min, y_max = self.extent
        seen = self._image_rect(T_world_camera, (x_min, x_max, y_min, y_max))
        rect = (0, 0, 0, 0) if seen is None else seen[1]
        # dark again: what the last frame lit (`_lit_rect`) outside this frame's `rect`
        for strip in _rect_minus((0, 0, width, height), rect):
            box = _rect_intersection(strip, self._lit_rect)
            if box is not None:
                for part, value in zip(self._prepared, dark):
                    if part is not None:
                        part[box[1]:box[3], box[0]:box[2]] = value[box[1]:box[3], box[0]:box[2]]
        if seen is not None:
            self._redo(T_world_camera, *seen)
        self._lit_rect = rect

    def _dark_stage(self):
        """Return the sensor stage of a frame that sees no light (worked out once)."""
        if self._dark is None:
            light = np.zeros((self.camera.height, self.camera.width, 3), np.float32)
            self._dark = self._sensor_stage(
                light, (0, 0, self.camera.width, self.camera.height))
        return self._dark

    def _redo(self, T_world_camera, wide, inner):
        """Redo the frame's sensor stage in `inner` (its light rendered over `wide`)."""
        part = self._blur(self._radiance(T_world_camera, self._lit, rect=wide, padded=True))
        x0, y0, x1, y1 = inner
        kept = tuple(None if stage is None else stage[y0:y1, x0:x1] for stage in self._prepared)
        first, second = self._sensor_stage(
            part[y0 - wide[1]:y1 - wide[1], x0 - wide[0]:x1 - wide[0]], inner,
            None if any(stage is None for stage in kept) else kept)
        if first is not kept[0]:
            kept[0][...] = first
            if second is not None:
                kept[1][...] = second

    def _radiance(self, T_world_camera, texture, rect=None, padded=False):
        """
        Return a linear texture's light per pixel (of `rect` (x0, y0, x1, y1), or all).

        A pinhole camera without distortion maps the ground plane to the image by a
        homography: one ``cv2.warpPerspective`` of the texture (no per-pixel rays, maps or
        NaN handling: a moving camera's frame costs a third). Cameras with distortion,
        supersampling, or pixels that look above the horizon go through
        ``GroundRenderer.radiance``'s per-pixel rays. Of a four-channel texture (RGB and
        padding) the light of the three colours; with `padded`, the four channels as they
        come (the blur and the read-out skip the fourth: a copy less, 0.2 ms a frame).
        """
        keep = (lambda light: light) if padded else _colours
        mapping = self._texture_homography(T_world_camera, texture)
        if mapping is None:
            return keep(np.ascontiguousarray(self._renderer.radiance(
                T_world_camera, texture, background=0.0, rect=rect), dtype=np.float32))
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
        light = keep(light)
        if downward is not None:    # the pixels at and above the horizon see no panel
            _blank_above_horizon(light, downward, x0, y0)
        return light

    def _pose_view(self, T_world_camera):
        """
        Return the geometry of a camera pose, worked out once per pose (a dict).

        'ground': the 3 x 3 map from image pixels to homogeneous ground points (None when
        the camera distorts, supersamples or sees no ground), 'horizon': (a, b, c) with
        a u + b v + c >= 0 on the pixels at or above the horizon (None: there are none),
        'project': the 3 x 4 map from world points to homogeneous pixels whose third
        component is the depth (None when the camera distorts).
        """
        key = np.asarray(T_world_camera, dtype=np.float64).tobytes()
        if key == self._view_key:
            return self._view
        pose = np.asarray(T_world_camera, dtype=float)
        matrix = np.asarray(self.camera.matrix, dtype=float)
        distorted = bool(np.any(self.camera.distortion))
        view = {'ground': None, 'horizon': None, 'project': None}
        if not distorted:
            rotation = pose[:3, :3].T
            view['project'] = matrix @ np.hstack([rotation, -(rotation @ pose[:3, 3:4])])
        rays = pose[:3, :3] @ np.linalg.inv(matrix)
        width, height = self.camera.width, self.camera.height
        corners = np.array([[-0.5, -0.5, 1.0], [width - 0.5, -0.5, 1.0],
                            [-0.5, height - 0.5, 1.0], [width - 0.5, height - 0.5, 1.0]])
        downward = corners @ rays[2]              # d_z, affine in (u, v): its corners
        if (self._renderer.supersample == 1 and not distorted and np.any(downward < 0.0)
                and pose[2, 3] > 0.0):
            ox, oy, oz = pose[:3, 3]
            view['ground'] = np.stack([ox * rays[2] - oz * rays[0],
                                       oy * rays[2] - oz * rays[1], rays[2]])
            if not np.all(downward < 0.0):
                view['horizon'] = tuple(float(v) for v in rays[2])
        self._view, self._view_key = view, key
        return view

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
        view = self._pose_view(T_world_camera)
        if view['ground'] is None:
            return None
        x_min, _, _, y_max = texture.extent
        sx, sy = texture.metres_per_pixel
        to_texture = np.array([[1.0 / sx, 0.0, -x_min / sx - 0.5],
                               [0.0, -1.0 / sy, y_max / sy - 0.5],
                               [0.0, 0.0, 1.0]])
        return to_texture @ view['ground'], view['horizon']

    def _raster_box_world(self, r0, r1, c0, c1):
        """Return the world extent (x_min, x_max, y_min, y_max) of raster rows/cols [m]."""
        x_min, _, y_min, _ = self.extent
        cell = self.pixel_size
        return (x_min + c0 * cell, x_min + c1 * cell, y_min + r0 * cell, y_min + r1 * cell)

    def _image_rect(self, T_world_camera, box):
        """
        Return (wide, inner) image rectangles (x0, y0, x1, y1) [px] of a ground box, or None.

        `inner` holds every pixel that sees the box or its blur (its corner on even pixels:
        the Bayer mosaic's phase); `wide` adds the context the blur needs. The whole image
        when a corner of the box is behind the camera or the camera distorts.
        """
        x0, x1, y0, y1 = box
        width, height = self.camera.width, self.camera.height
        project = self._pose_view(T_world_camera)['project']
        pixels = None
        if project is not None:
            corners = np.array([[x0, y0, 0.0, 1.0], [x1, y0, 0.0, 1.0],
                                [x1, y1, 0.0, 1.0], [x0, y1, 0.0, 1.0]])
            homogeneous = corners @ project.T
            if np.all(homogeneous[:, 2] > 0.0):
                pixels = homogeneous[:, :2] / homogeneous[:, 2:]
        margin = self._webcam.blur_margin() + 2
        if pixels is None:
            inner = (0, 0, width, height)
        else:
            low = np.floor(pixels.min(axis=0)).astype(int) - margin
            high = np.ceil(pixels.max(axis=0)).astype(int) + margin + 1
            inner = (max(int(low[0]) // 2 * 2, 0), max(int(low[1]) // 2 * 2, 0),
                     min(int(high[0]), width), min(int(high[1]), height))
            if inner[2] <= inner[0] or inner[3] <= inner[1]:
                return None
        wide = (max(inner[0] - margin, 0), max(inner[1] - margin, 0),
                min(inner[2] + margin, width), min(inner[3] + margin, height))
        return wide, inner


def _with_padding_channel(rgb):
    """Return (..., 3) `rgb` as a contiguous (..., 4) array whose fourth channel is 0."""
    padded = np.zeros(rgb.shape[:-1] + (4,), rgb.dtype)
    padded[..., :3] = rgb
    return padded


def _colours(light):
    """Return the three colour channels of (H, W, 4) `light` (contiguous); others as given."""
    if light.ndim == 3 and light.shape[2] == 4:
        return cv2.cvtColor(light, cv2.COLOR_RGBA2RGB)
    return light


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


def _rect_intersection(a, b):
    """Return the intersection of image rectangles (x0, y0, x1, y1), or None."""
    box = _box_intersection((a[1], a[3], a[0], a[2]), (b[1], b[3], b[0], b[2]))
    return None if box is None else (box[2], box[0], box[3], box[1])


def _rect_minus(rect, hole):
    """Return up to four image rectangles (x0, y0, x1, y1) covering `rect` without `hole`."""
    hole = _rect_intersection(rect, hole)
    if hole is None:
        return [rect]
    parts = _box_minus((rect[1], rect[3], rect[0], rect[2]),
                       (hole[1], hole[3], hole[0], hole[2]))
    return [(c0, r0, c1, r1) for r0, r1, c0, c1 in parts]


def _merged_boxes(boxes):
    """
    Return raster boxes (r0, r1, c0, c1) covering `boxes`, overlapping ones merged.

    Boxes are merged while their bounding box is not much larger than the two (a char
    change inside the light window, the old and the new window): one render each.
    """
    merged = []
    for box in boxes:
        box = tuple(box)
        joined = True
        while joined:
            joined = False
            for k, other in enumerate(merged):
                bound = (min(box[0], other[0]), max(box[1], other[1]),
                         min(box[2], other[2]), max(box[3], other[3]))
                if _area(bound) <= 1.5 * (_area(box) + _area(other)):
                    box, joined = bound, True
                    del merged[k]
                    break
        merged.append(box)
    return merged


def _box_intersection(a, b):
    """Return the intersection of raster boxes (r0, r1, c0, c1), or None."""
    if a is None or b is None:
        return None
    box = (max(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), min(a[3], b[3]))
    return box if box[1] > box[0] and box[3] > box[2] else None


def _box_minus(box, hole):
    """Return up to four raster boxes covering `box` without `hole` (inside it, or None)."""
    if hole is None:
        return [box]
    r0, r1, c0, c1 = box
    h0, h1, g0, g1 = hole
    parts = [(r0, h0, c0, c1), (h1, r1, c0, c1), (h0, h1, c0, g0), (h0, h1, g1, c1)]
    return [part for part in parts if part[1] > part[0] and part[3] > part[2]]


def _area(box):
    """Return the pixels of a raster box (r0, r1, c0, c1)."""
    return max(box[1] - box[0], 0) * max(box[3] - box[2], 0)


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
    lit = np.logical_not(field.in_shadow_grid(xs, ys)).astype(np.float32)
    spot = _rays_box(field, origin, pixel_size, (r0, r1, c0, c1), CONCENTRATED_BLUR_REACH)
    if spot is not None:
        # the rays' power binned per raster pixel (one compiled pass over the rays) and
        # blurred, over the rays' box and the blur's reach: zero beyond, in the window
        s0, s1, t0, t1 = spot
        binned = np.zeros((s1 - s0, t1 - t0))
        bin_on_raster(np.ascontiguousarray(field.points, dtype=float),
                      np.ascontiguousarray(field.power, dtype=float), float(origin[0]),
                      float(origin[1]), float(pixel_size), t0, s0, binned)
        concentrated = binned / (pixel_size * pixel_size) / max(field.direct, 1e-6)
        lit[s0 - r0:s1 - r0, t0 - c0:t1 - c0] += cv2.GaussianBlur(
            concentrated.astype(np.float32), (0, 0), CONCENTRATED_BLUR_SIGMA)
    return slice(r0, r1), slice(c0, c1), lit


def _rays_box(field, origin, pixel_size, window, reach):
    """
    Return the raster box (r0, r1, c0, c1) of a field's rays, `reach` pixels wider, in `window`.

    None when the field has no rays in the window. A blur of the binned rays over this box
    equals one over the whole window: beyond the rays it sees zeros (`reach` covers the
    blur's kernel twice over, its reflected border included).
    """
    bounds = field.bounds()
    if bounds is None:
        return None
    (x_low, y_low), (x_high, y_high) = bounds
    r0, r1, c0, c1 = window
    box = (max(r0, int(math.floor((y_low - origin[1]) / pixel_size)) - reach),
           min(r1, int(math.floor((y_high - origin[1]) / pixel_size)) + 1 + reach),
           max(c0, int(math.floor((x_low - origin[0]) / pixel_size)) - reach),
           min(c1, int(math.floor((x_high - origin[0]) / pixel_size)) + 1 + reach))
    return box if box[1] > box[0] and box[3] > box[2] else None
