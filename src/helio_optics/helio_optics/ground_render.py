"""
Render the ground plane (z = 0 of the world frame) as a webcam sees it.

The ground is a texture of known metric extent (a top view: texture columns run along world
+x, rows along world -y, so the texture looks like the panel seen from above with x right and
y up) plus optional analytic bright ellipses (light spots). Each image pixel's ray from
`geometry.PinholeCamera.pixel_rays` (distortion included) is intersected with the ground
(paper Eq 6 via `geometry.intersect_plane`'s formula) and the texture is sampled there, so a
world point lands exactly where `PinholeCamera.project` puts it.

Light is handled the way a camera handles it, in LINEAR units (1 = the sensor's full scale):
an 8-bit texture is sRGB-encoded reflectance and is decoded to linear before it is sampled;
the spots add their radiance; pixels average `supersample` x `supersample` sub-pixel rays (box
filter, the sensor's pixel area). `Webcam` then does what a webcam does to that light
(`WebcamSettings`): exposure, optical blur and vignetting (still linear), optionally a Bayer
RGGB mosaic, sensor noise (read noise and photon shot noise), clipping at full scale,
quantisation by the ADC, demosaicing, the sRGB tone curve (IEC 61966-2-1) to 8 bits and
optionally JPEG. A blurred black-to-white edge in such a frame is not half-way between its
grey levels where the edge is: the tone curve moves that point towards the dark side, which
is what the perception code must undo (`srgb8_to_linear_table`).

Used by perception's tests (synthetic frames with known truth) and by the simulated world's
RGB camera. `make_panel_texture` builds a wood panel with an ArUco marker centred on the
world origin (marker x/y axes = world x/y, as `cv2.aruco` defines the marker frame), on an
optional white paper sheet with its own margins.
"""

from dataclasses import dataclass
import math

import cv2
from helio_optics.geometry import PinholeCamera
import numpy as np

WOOD_RGB = (196, 160, 112)  # light pine, 8-bit sRGB
TONE_CURVES = ('srgb', 'linear')


def srgb_to_linear(values):
    """Decode sRGB values in [0, 1] to linear light (IEC 61966-2-1)."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(values):
    """Encode linear light in [0, 1] (clipped) as sRGB values in [0, 1] (IEC 61966-2-1)."""
    v = np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1.0 / 2.4) - 0.055)


def srgb8_to_linear_table():
    """Return the (256,) float32 table of linear light [0-1] for each 8-bit sRGB level."""
    return srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


_SRGB8_TO_LINEAR = srgb8_to_linear_table()


def decode_srgb8(image):
    """Return linear light (float32, same shape) of an 8-bit sRGB image (a table look-up)."""
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f'decode_srgb8 needs an 8-bit image, got {image.dtype.name}')
    return cv2.LUT(image, _SRGB8_TO_LINEAR)


@dataclass
class GroundTexture:
    """
    A top-view image of the ground with its metric extent.

    `image` is (H, W) or (H, W, C); `extent` is (x_min, x_max, y_min, y_max) in the world
    frame [m]: column 0's left edge is at x_min, row 0's top edge at y_max. With `linear`
    false the image holds 8-bit sRGB reflectance (as a picture file does: 255 = white
    paper), decoded to linear light before rendering; with `linear` true it holds linear
    light already (1 = full scale of the sensor at exposure 1).
    """

    image: np.ndarray
    extent: tuple
    linear: bool = False

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

    def linear_image(self):
        """Return the image as linear light, float32 (no copy when it is linear already)."""
        if self.linear:
            return np.asarray(self.image, dtype=np.float32)
        return decode_srgb8(np.asarray(self.image, dtype=np.uint8))

    def linearised(self):
        """Return a linear copy of this texture (decode once, render many frames)."""
        return GroundTexture(image=self.linear_image().copy(), extent=tuple(self.extent),
                             linear=True)


@dataclass
class GroundEllipse:
    """
    A bright elliptical light spot on the ground, rendered analytically (exact area).

    `center` (x, y) [m] in the world frame; `semi_axes` (a, b) [m]; `angle` from world x to
    the first axis [rad]; `value` the light it adds, linear, per channel (1 = the sensor's
    full scale at exposure 1: a focused sun spot is tens of times brighter than white paper
    and saturates; a value below 1 minus the ground's light leaves it unsaturated).
    """

    center: tuple
    semi_axes: tuple
    angle: float = 0.0
    value: float = 20.0

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
                       quiet_zone=0.006, wood_rgb=WOOD_RGB, grain=0.06, seed=0,
                       sheet_margins=None, print_reflectance=(0.0, 1.0), marker_scale=1.0):
    """
    Make an RGB wood panel texture (8-bit sRGB) with an ArUco marker centred on the origin.

    `marker_side` [m] is the side of the marker's black square (cv2.aruco's marker length);
    a white quiet zone `quiet_zone` [m] wide surrounds it, or a white paper sheet whose
    margins from the black square are `sheet_margins` (left, right, bottom, top) [m] along
    world -x, +x, -y, +y. The marker image from `cv2.aruco.generateImageMarker` is placed so
    that its top-left corner is at (-side/2, +side/2): the marker frame's x/y axes are the
    world x/y axes. `grain` is the relative amplitude of a smooth random wood grain.
    `print_reflectance` (ink, paper) is the linear reflectance of the marker's black and white
    (see `draw_marker`), `marker_scale` the printed size over `marker_side` (a printer's
    scale error: the black square is then marker_side * marker_scale wide).
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
        draw_marker(texture, marker_side, marker_id, dictionary, quiet_zone, sheet_margins,
                    print_reflectance, marker_scale)
    return texture


def draw_marker(texture, side, marker_id=0, dictionary='DICT_4X4_50', quiet_zone=0.006,
                sheet_margins=None, print_reflectance=(0.0, 1.0), scale=1.0):
    """
    Draw an ArUco marker (black square `side` [m]) centred on the world origin in place.

    The white paper around it is `quiet_zone` [m] wide on every side, or `sheet_margins`
    (left, right, bottom, top) [m] from the black square along world -x, +x, -y, +y.
    `print_reflectance` (ink, paper) [0-1] is the linear reflectance of the black and the
    white: (0, 1) is an ideal print; a laser print on office paper reflects about 4-6 % and
    80-90 %, which is what decides whether the black in full sun is darker than the white
    in a shadow (only the sky's light). `scale` is the print's size over `side` (the
    sheet's margins stay): its edges then fall inside texture pixels, which take the ink's
    share of their area, mixed in linear light.
    """
    ink, paper = (float(v) for v in print_reflectance)
    if not 0.0 <= ink < paper <= 1.0:
        raise ValueError(f'print_reflectance must be (ink, paper) with 0 <= ink < paper <= 1, '
                         f'got {print_reflectance}')
    black, white = (int(round(255.0 * float(linear_to_srgb(v)))) for v in (ink, paper))
    sx, sy = texture.metres_per_pixel
    if abs(sx - sy) > 1e-12 * max(sx, sy):
        raise ValueError('draw_marker needs square texture pixels')
    left, right, bottom, top = (quiet_zone,) * 4 if sheet_margins is None else sheet_margins
    if min(left, right, bottom, top) < 0:
        raise ValueError(f'sheet margins must be >= 0 m, got {sheet_margins}')
    h = side / 2
    c0, r0 = texture.texture_coordinates(-h - left, h + top)
    c1, r1 = texture.texture_coordinates(h + right, -h - bottom)
    edges = np.array([c0, r0, c1, r1, *texture.texture_coordinates(-h, h)]) + 0.5
    if np.max(np.abs(edges - np.rint(edges))) > 1e-3:
        raise ValueError('the marker edges must fall on texture pixel edges: choose the extent '
                         'and metres_per_pixel so that side/2 and the sheet margins are '
                         'multiples of the pixel size')
    c0, r0, c1, r1 = (int(round(v + 0.5)) for v in (c0, r0, c1, r1))
    if c0 < 0 or r0 < 0 or c1 > texture.image.shape[1] or r1 > texture.image.shape[0]:
        raise ValueError('the marker and its quiet zone do not fit in the texture extent')
    texture.image[r0:r1, c0:c1] = white
    pixels = int(round(side / sx))
    marker = cv2.aruco.generateImageMarker(aruco_dictionary(dictionary), marker_id, pixels, 1)
    marker = np.where(marker > 127, white, black).astype(np.uint8)
    mc, mr = texture.texture_coordinates(-h, h)
    mc, mr = int(round(mc + 0.5)), int(round(mr + 0.5))
    if scale != 1.0:    # a pixel more on each side holds a print up to a pixel larger
        mr, mc, pixels = mr - 1, mc - 1, pixels + 2
        marker = _scaled_marker(texture, side * scale, marker_id, dictionary, ink, paper,
                                (mr, mc, pixels))
    patch = marker if texture.image.ndim == 2 else marker[:, :, None]
    texture.image[mr:mr + pixels, mc:mc + pixels] = patch
    return texture


def _scaled_marker(texture, printed_side, marker_id, dictionary, ink, paper, box,
                   supersample=8):
    """
    Return the 8-bit patch of `box` (row, column, size) with a marker `printed_side` wide.

    Each texture pixel takes the ink's share of its area (sampled `supersample`^2 times),
    mixed in linear light; the patch must hold the printed marker (a print within a pixel of
    the nominal size).
    """
    row, column, size = box
    cells = cv2.aruco.generateImageMarker(aruco_dictionary(dictionary), marker_id,
                                          aruco_dictionary(dictionary).markerSize + 2, 1)
    count = cells.shape[0]
    offsets = (np.arange(size * supersample) + 0.5) / supersample - 0.5
    x, _ = texture.world_of_texture(column + offsets, 0)
    _, y = texture.world_of_texture(0, row + offsets)
    half = printed_side / 2.0
    u = np.floor((x + half) / printed_side * count).astype(int)     # cell column
    v = np.floor((half - y) / printed_side * count).astype(int)     # cell row
    inside = (u[None, :] >= 0) & (u[None, :] < count) & (v[:, None] >= 0) & (v[:, None] < count)
    white = cells[np.clip(v, 0, count - 1)][:, np.clip(u, 0, count - 1)] > 127
    ink_share = (inside & ~white).astype(np.float32).reshape(
        size, supersample, size, supersample).mean(axis=(1, 3))
    linear = ink * ink_share + paper * (1.0 - ink_share)
    return np.rint(255.0 * linear_to_srgb(linear)).astype(np.uint8)


@dataclass(frozen=True)
class WebcamSettings:
    """
    What a webcam does to the light on its sensor (see `Webcam`).

    `tone_curve` 'srgb' (IEC 61966-2-1, what webcams deliver) or 'linear'; `blur_sigma`
    optical blur [px]; `vignetting` the light lost at the image corners [-] (natural cos^4
    fall-off scaled to it; 0: none); `read_noise` [fraction of full scale]; shot noise from
    `full_well_electrons` (variance = signal / full well; 0: none); `adc_bits` of the
    linear read-out; `bayer` an RGGB colour filter mosaic demosaiced by OpenCV (colour only);
    `jpeg_quality` 1-100 (0: no JPEG); `seed` of the noise bank.
    """

    tone_curve: str = 'srgb'
    blur_sigma: float = 0.0
    vignetting: float = 0.0
    read_noise: float = 0.0
    full_well_electrons: float = 0.0
    adc_bits: int = 10
    bayer: bool = False
    jpeg_quality: int = 0
    seed: int = 0

    def __post_init__(self):
        """Refuse settings no camera has."""
        if self.tone_curve not in TONE_CURVES:
            raise ValueError(f'tone_curve must be one of {TONE_CURVES}, got {self.tone_curve!r}')
        if not 8 <= int(self.adc_bits) <= 16:
            raise ValueError(f'adc_bits must be 8-16, got {self.adc_bits}')
        if not 0 <= int(self.jpeg_quality) <= 100:
            raise ValueError(f'jpeg_quality must be 0 (off) to 100, got {self.jpeg_quality}')
        if not 0.0 <= self.vignetting < 1.0:
            raise ValueError(f'vignetting must be in [0, 1), got {self.vignetting}')
        for name in ('blur_sigma', 'read_noise', 'full_well_electrons'):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)}')


# OpenCV names Bayer patterns after the second row; the RGGB alias exists from 4.6 on
_BAYER_RGGB_TO_RGB = getattr(cv2, 'COLOR_BayerRGGB2RGB', cv2.COLOR_BayerBG2RGB)
_NOISE_SCALE = 25.0     # the noise bank stores N(0, 1) x 25 as int8 (clipped at 5 sigma)
_NOISE_PAD = 32         # bank frames are this much larger than the image: random crops
_NOISE_FRAMES = 3


class Webcam:
    """
    The image pipeline of a webcam for one camera: linear light in, an 8-bit frame out.

    `optics(light)`: blur and vignetting (linear, so a part of an image can be done alone:
    `rect`); `sensor(light, rng)`: Bayer mosaic, noise, clipping at full scale, ADC,
    demosaic, tone curve, JPEG; `develop` = both. Noise comes from a bank of Gaussian frames
    drawn once (seeded) and cropped at a random offset per image: every frame's noise is
    white and Gaussian, and it costs a crop instead of a draw.
    """

    def __init__(self, settings, camera: PinholeCamera):
        self.settings = settings
        self.camera = camera
        top = (1 << int(settings.adc_bits)) - 1
        self._top = float(top)
        codes = np.arange(top + 1) / top
        curve = linear_to_srgb(codes) if settings.tone_curve == 'srgb' else codes
        self._tone = np.rint(255.0 * curve).astype(np.uint8)
        self._vignette = None
        if settings.vignetting > 0.0:
            u, v = np.meshgrid(np.arange(camera.width, dtype=float),
                               np.arange(camera.height, dtype=float))
            rays = camera.pixel_rays(np.stack([u.ravel(), v.ravel()], axis=-1))
            falloff = (rays[:, 2] / np.linalg.norm(rays, axis=1)) ** 4
            lowest = float(falloff.min())
            loss = (1.0 - falloff) / (1.0 - lowest) if lowest < 1.0 else 0.0 * falloff
            self._vignette = (1.0 - settings.vignetting * loss).reshape(
                camera.height, camera.width, 1).astype(np.float32)
        self._banks = {}

    def optics(self, light, rect=None):
        """
        Return the light after the lens: Gaussian blur, then vignetting (float32).

        `rect` (x0, y0, x1, y1) [px] says which part of the image `light` is (None: all);
        the blur then treats its edges as the image's edges, so render a margin around the
        part you need (`blur_margin`).
        """
        s = self.settings
        light = np.asarray(light, dtype=np.float32)
        if s.blur_sigma > 0.0:
            light = cv2.GaussianBlur(light, (0, 0), s.blur_sigma)
        if self._vignette is not None:
            x0, y0, x1, y1 = rect or (0, 0, self.camera.width, self.camera.height)
            gain = self._vignette[y0:y1, x0:x1]
            light = light * (gain if light.ndim == 3 else gain[:, :, 0])
        return light

    def blur_margin(self):
        """Return the pixels of context the blur needs around a part of the image [px]."""
        return int(math.ceil(4.0 * self.settings.blur_sigma)) + 1

    def noise_sigma(self, light):
        """Return the sensor noise's standard deviation for linear `light` (same shape)."""
        s = self.settings
        if s.full_well_electrons > 0.0:
            signal = np.maximum(np.asarray(light, np.float32), 0.0)
            return np.sqrt(signal * np.float32(1.0 / s.full_well_electrons)
                           + np.float32(s.read_noise ** 2))
        return np.full(np.shape(light), s.read_noise, np.float32)

    def sensor(self, light, rng=None):
        """Return the 8-bit frame (uint8, (H, W) or (H, W, 3)) of linear `light` on the sensor."""
        return self.expose(self.prepare(light), rng)

    def prepare(self, light):
        """
        Return the noise-free part of the sensor stage for `light` (to `expose` many times).

        The Bayer mosaic, the signal in ADC codes and the noise's sigma in codes: a caller
        whose light does not change between frames keeps this and pays only for the noise,
        the read-out and the tone curve per frame.
        """
        s = self.settings
        light = np.asarray(light, dtype=np.float32)
        if s.bayer:
            if light.ndim != 3 or light.shape[2] != 3:
                raise ValueError(f'a Bayer sensor needs RGB light, got shape {light.shape}')
            raw = np.empty(light.shape[:2], np.float32)
            raw[0::2, 0::2] = light[0::2, 0::2, 0]
            raw[0::2, 1::2] = light[0::2, 1::2, 1]
            raw[1::2, 0::2] = light[1::2, 0::2, 1]
            raw[1::2, 1::2] = light[1::2, 1::2, 2]
            light = raw
        codes = light * np.float32(self._top)
        codes += np.float32(0.5)     # rounding: the read-out truncates
        sigma = None
        if s.read_noise > 0.0 or s.full_well_electrons > 0.0:
            sigma = self.noise_sigma(light) * np.float32(self._top / _NOISE_SCALE)
        return codes, sigma

    def expose(self, prepared, rng=None):
        """Return the 8-bit frame of a `prepare`d light: noise, clipping, ADC, tone, JPEG."""
        s = self.settings
        codes, sigma = prepared
        if sigma is not None:
            codes = cv2.add(cv2.multiply(self._noise_unit(codes.shape, rng), sigma,
                                         dtype=cv2.CV_32F), codes)
        else:
            codes = codes.copy()
        np.clip(codes, 0.0, self._top, out=codes)
        codes = codes.astype(np.uint16)
        if s.bayer:
            codes = cv2.demosaicing(codes, _BAYER_RGGB_TO_RGB)
        image = np.take(self._tone, codes)
        if s.jpeg_quality > 0:
            image = jpeg_round_trip(image, s.jpeg_quality)
        return image

    def develop(self, light, rng=None):
        """Return the 8-bit frame of the linear light arriving at the lens (optics, sensor)."""
        return self.sensor(self.optics(light), rng)

    def _noise_unit(self, shape, rng):
        """Return this frame's N(0, 1) x _NOISE_SCALE noise (int8, a random crop of the bank)."""
        rng = np.random.default_rng() if rng is None else rng
        bank = self._banks.get(shape)
        if bank is None:
            draw = np.random.default_rng(self.settings.seed)
            padded = (_NOISE_FRAMES, shape[0] + _NOISE_PAD, shape[1] + _NOISE_PAD) + shape[2:]
            bank = np.clip(np.rint(draw.standard_normal(padded, dtype=np.float32)
                                   * np.float32(_NOISE_SCALE)), -127, 127).astype(np.int8)
            self._banks[shape] = bank
        k, dy, dx = (int(v) for v in rng.integers(0, (_NOISE_FRAMES, _NOISE_PAD + 1,
                                                      _NOISE_PAD + 1)))
        return bank[k, dy:dy + shape[0], dx:dx + shape[1]]


def jpeg_round_trip(image, quality):
    """Return an 8-bit image (mono or RGB) after JPEG compression at `quality` (1-100)."""
    colour = image.ndim == 3
    data = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if colour else image
    ok, encoded = cv2.imencode('.jpg', data, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise ValueError('JPEG encoding failed')
    decoded = cv2.imdecode(encoded, cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE)
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB) if colour else decoded


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
        # one row per axis (3, N): the pose's rotation then makes each row in one pass
        self._rays = np.ascontiguousarray(rays.T, dtype=np.float64)
        self._shape = (camera.height * s, camera.width * s)
        self._pose_key = None       # pose of the cached ground points
        self._ground = None         # (x, y) sub-pixel grids for that pose
        self._maps_key = None       # texture geometry of the cached full-frame maps
        self._kept_maps = None      # (column, row) float32 for that pose and geometry
        self._webcams = {}

    def ground_points(self, T_world_camera):
        """Return world (x, y) grids [m] where each sub-pixel ray meets z = 0 (NaN if never)."""
        T_world_camera = np.asarray(T_world_camera, dtype=float)
        directions = T_world_camera[:3, :3] @ self._rays       # (3, N) world directions
        origin = T_world_camera[:3, 3]
        with np.errstate(divide='ignore', invalid='ignore'):
            scale = np.divide(-origin[2], directions[2])
        scale[~((scale > 0) & np.isfinite(scale))] = np.nan
        x = directions[0] * scale
        x += origin[0]
        y = directions[1] * scale
        y += origin[1]
        return x.reshape(self._shape), y.reshape(self._shape)

    def webcam(self, settings):
        """Return the (cached) Webcam pipeline of `settings` for this camera."""
        pipeline = self._webcams.get(settings)
        if pipeline is None:
            pipeline = self._webcams[settings] = Webcam(settings, self.camera)
        return pipeline

    def cached_ground_points(self, T_world_camera):
        """
        Return the ground (x, y) sub-pixel grids of a pose, kept while the pose is unchanged.

        The camera rarely moves between frames (the arm holds the lens while the wood heats).
        """
        pose = np.asarray(T_world_camera, dtype=np.float64)
        key = pose.tobytes()
        if key != self._pose_key:
            self._ground = self.ground_points(pose)
            self._pose_key = key
            self._maps_key = None
        return self._ground

    def _maps(self, T_world_camera, texture, rect=None):
        """
        Return (x, y, column, row): ground points and texture remap grids (sub-pixel).

        The whole frame's grids are kept for the last pose and texture geometry; a `rect`
        (x0, y0, x1, y1) [px] gets its part computed from the kept ground points.
        """
        x, y = self.cached_ground_points(T_world_camera)
        if rect is None:
            key = (tuple(texture.extent), texture.image.shape[:2])
            if key == self._maps_key:
                return (x, y) + self._kept_maps
        else:
            s = self.supersample
            x0, y0, x1, y1 = rect
            x, y = x[y0 * s:y1 * s, x0 * s:x1 * s], y[y0 * s:y1 * s, x0 * s:x1 * s]
        column, row = texture.texture_coordinates(x, y)
        column = np.nan_to_num(column, nan=-1e6).astype(np.float32)
        row = np.nan_to_num(row, nan=-1e6).astype(np.float32)
        if rect is None:
            self._kept_maps, self._maps_key = (column, row), key
        return x, y, column, row

    def radiance(self, T_world_camera, texture, spots=(), background=0.0, rect=None):
        """
        Return the linear light per pixel (float32, (H, W) or (H, W, C)) at a camera pose.

        `texture` a GroundTexture (8-bit sRGB reflectance is decoded to linear), `spots`
        GroundEllipses whose light adds to the ground's, `background` [linear] where rays
        miss the texture; only the pixels of `rect` (x0, y0, x1, y1) when given.
        """
        x, y, column, row = self._maps(T_world_camera, texture, rect)
        source = texture.linear_image()
        channels = 1 if source.ndim == 2 else source.shape[2]
        border = (float(background),) * max(channels, 1)
        light = cv2.remap(source, column, row, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=border)
        for spot in spots:
            inside = spot.contains(x, y)
            light[inside] += np.float32(spot.value)
        s = self.supersample
        if s > 1:
            light = cv2.resize(light, (light.shape[1] // s, light.shape[0] // s),
                               interpolation=cv2.INTER_AREA)
        return light

    def render(self, T_world_camera, texture, spots=(), webcam=WebcamSettings(), exposure=1.0,
               background=0.05, rng=None):
        """
        Return the 8-bit frame a webcam takes of the ground at pose `T_world_camera`.

        The light of `radiance` times `exposure` (linear; 1 = full scale, above it the
        sensor saturates) goes through the `webcam` pipeline (WebcamSettings: blur,
        vignetting, noise from `rng`, tone curve, ...). Channels follow the texture.
        """
        light = self.radiance(T_world_camera, texture, spots, background)
        if exposure != 1.0:
            light *= np.float32(exposure)
        return self.webcam(webcam).develop(light, rng)


def render_ground(camera, T_world_camera, texture, spots=(), supersample=2, **kwargs):
    """Render once (see GroundRenderer.render); build a GroundRenderer to render many frames."""
    return GroundRenderer(camera, supersample).render(T_world_camera, texture, spots, **kwargs)
