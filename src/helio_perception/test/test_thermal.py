"""Thermal statistics against direct counts on synthetic Lepton-like frames."""

import math

from helio_optics.geometry import PinholeCamera
from helio_optics.node_kit.conversions import image_to_numpy, numpy_to_image
from helio_perception.ground_plane import GroundMapping
from helio_perception.thermal import camera_range_report, FreezeDetector
from helio_perception.thermal import raw_threshold, ThermalAnalyzer, ThermalConfig
from helio_perception.thermal import window_mask
import numpy as np
import pytest

CAP_RAW = 45405  # 180.9 degC in centikelvin: the paper's Lepton read-out cap


def lepton_frame(seed=0, peak=260.0, width=160, height=120):
    """
    Return raw centikelvin (H, W) uint16: 25 degC wood with a charring dot, capped at 180.9.

    The dot is a Gaussian of 3 px radius peaking at `peak` degC (above the cap: saturated).
    """
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:height, 0:width]
    centre = rng.uniform([40, 30], [120, 90])
    celsius = 25.0 + (peak - 25.0) * np.exp(-((u - centre[0]) ** 2 + (v - centre[1]) ** 2)
                                            / (2 * 3.0 ** 2))
    celsius += rng.normal(0.0, 0.05, celsius.shape)  # NETD ~50 mK
    raw = np.rint((celsius + 273.15) * 100.0)
    return np.minimum(raw, CAP_RAW).astype(np.uint16)


@pytest.mark.parametrize('seed, peak', [(0, 260.0), (1, 181.0), (2, 150.0), (3, 400.0)])
def test_all_three_encodings_match_a_direct_count(seed, peak):
    raw = lepton_frame(seed, peak)
    kelvin_100 = raw.astype(np.int64)
    direct_n_p = int(np.sum(kelvin_100 >= CAP_RAW))  # reading >= 180.90 degC
    direct_t_max = kelvin_100.max() / 100.0 - 273.15
    analyzer = ThermalAnalyzer(ThermalConfig(threshold=180.9, camera_cap=180.9))
    centikelvin = analyzer.statistics(raw, '16UC1')
    celsius = (raw / 100.0 - 273.15).astype(np.float32)
    floats = analyzer.statistics(celsius, '32FC1')
    # mono16 with another linear calibration: 0.02 degC per count from -40 degC
    counts = np.rint((raw / 100.0 - 273.15 + 40.0) / 0.02).astype(np.uint16)
    mono = ThermalAnalyzer(ThermalConfig(mono16_gain=0.02, mono16_offset=-40.0))
    mono16 = mono.statistics(counts, 'mono16')
    mono_celsius = 0.02 * counts.astype(np.float64) - 40.0
    for stats in (centikelvin, floats):
        assert stats.n_p == direct_n_p
        assert stats.t_max == pytest.approx(direct_t_max, abs=1e-4)
        assert raw[stats.hottest_v, stats.hottest_u] == raw.max()
    assert mono16.n_p == int(np.sum(mono_celsius >= 180.9))
    assert mono16.t_max == pytest.approx(mono_celsius.max(), abs=1e-9)
    assert mono16.n_p == pytest.approx(direct_n_p, abs=2)  # 0.02 K steps round differently
    assert centikelvin.saturated == (peak > 180.9) == floats.saturated


def test_threshold_edge_values_count_as_reached():
    raw = np.array([[CAP_RAW - 1, CAP_RAW, CAP_RAW + 1, 29815]], dtype=np.uint16)
    stats = ThermalAnalyzer().statistics(raw, '16UC1')
    assert stats.n_p == 2 and stats.hottest_u == 2
    assert raw_threshold(180.9, '16UC1', ThermalConfig()) == CAP_RAW
    floats = ThermalAnalyzer().statistics((raw / 100.0 - 273.15).astype(np.float32), '32FC1')
    assert floats.n_p == 2


@pytest.mark.parametrize('encoding', ['16UC1', 'mono16', '32FC1'])
def test_big_endian_and_padded_messages_give_the_same_answer(encoding):
    raw = lepton_frame(5)
    array = (raw / 100.0 - 273.15).astype(np.float32) if encoding == '32FC1' else raw
    analyzer = ThermalAnalyzer()
    plain = analyzer.statistics(image_to_numpy(numpy_to_image(array, encoding)), encoding)
    row = array.shape[1] * array.itemsize
    for big_endian, step in [(True, row), (False, row + 6), (True, row + 4)]:
        msg = numpy_to_image(array, encoding, is_bigendian=big_endian, step=step)
        assert analyzer.statistics(image_to_numpy(msg), encoding) == plain


def test_threshold_and_cap_are_parameters():
    raw = lepton_frame(0, peak=170.0)
    celsius = raw / 100.0 - 273.15
    stats = ThermalAnalyzer(ThermalConfig(threshold=150.0, camera_cap=300.0)).statistics(
        raw, '16UC1')
    assert stats.n_p == int(np.sum(celsius >= 150.0)) > 0
    assert not stats.saturated and stats.threshold == 150.0 and stats.camera_cap == 300.0


def test_nan_pixels_are_ignored_and_bad_input_is_refused():
    celsius = np.full((4, 4), 20.0, np.float32)
    celsius[1, 2] = 190.0
    celsius[0, 0] = np.nan
    stats = ThermalAnalyzer(ThermalConfig(camera_cap=200.0)).statistics(celsius, '32FC1')
    assert (stats.t_max, stats.n_p, stats.hottest_u, stats.hottest_v) == (190.0, 1, 2, 1)
    with pytest.raises(ValueError, match='no plausible pixel'):
        ThermalAnalyzer().statistics(np.full((2, 2), np.nan, np.float32), '32FC1')
    with pytest.raises(ValueError, match="got 'rgb8'"):
        ThermalAnalyzer().statistics(np.zeros((2, 2), np.uint8), 'rgb8')
    with pytest.raises(ValueError, match='gain must be > 0'):
        ThermalAnalyzer(ThermalConfig(mono16_gain=0.0)).statistics(
            np.zeros((2, 2), np.uint16), 'mono16')


def test_non_finite_32fc1_pixels_are_ignored_not_read():
    """Finding 9: +inf counted as a reading (T_max inf, N_p + 1) while NaN was ignored."""
    celsius = np.full((120, 160), 25.0, np.float32)
    celsius[50, 60] = 181.5
    celsius[10, 10], celsius[11, 11], celsius[12, 12] = np.inf, -np.inf, np.nan
    stats = ThermalAnalyzer().statistics(celsius, '32FC1')
    assert stats.t_max == pytest.approx(181.5) and (stats.hottest_u, stats.hottest_v) == (60, 50)
    assert stats.n_p == 1 and stats.ignored == 3
    with pytest.raises(ValueError, match='no plausible pixel'):
        ThermalAnalyzer().statistics(np.full((2, 2), np.inf, np.float32), '32FC1')


def test_a_stuck_pixel_above_the_camera_cap_is_ignored():
    """Finding 9: a stuck 65535 cK pixel reported 382 degC from a camera capped at 180.9."""
    raw = lepton_frame(4, peak=150.0)
    hottest = raw.max()
    raw[7, 9] = 65535
    stats = ThermalAnalyzer().statistics(raw, '16UC1')
    assert stats.t_max == pytest.approx(hottest / 100.0 - 273.15, abs=1e-9)
    assert stats.ignored == 1 and not stats.saturated and stats.n_p == 0
    # a reading within the margin above the cap is still a reading (at the cap: saturated)
    raw[7, 9] = CAP_RAW + 50   # 0.5 K above
    stats = ThermalAnalyzer().statistics(raw, '16UC1')
    assert stats.ignored == 0 and stats.saturated and stats.n_p == 1


def test_a_big_endian_array_is_read_by_value():
    """Finding 9: a big-endian uint16 array was misread (or refused as 'not uint16')."""
    raw = lepton_frame(5)
    swapped = raw.astype('>u2')
    assert swapped.dtype != np.uint16 and np.array_equal(swapped, raw)
    analyzer = ThermalAnalyzer()
    assert analyzer.statistics(swapped, '16UC1') == analyzer.statistics(raw, '16UC1')
    with pytest.raises(ValueError, match='16-bit integer'):
        analyzer.statistics(raw.astype(np.float32), '16UC1')


@pytest.mark.parametrize('encoding', ['16UC1', 'mono16', '32FC1'])
def test_a_reading_exactly_at_t_p_counts_for_every_decimal_threshold(encoding):
    """Finding 9: 238.9 degC = 51205 cK read 238.89999999999998 < T_p: the pixel was missed."""
    missed = []
    for tenths in range(-300, 3820, 7):   # 16UC1 reaches 382.35 degC
        threshold = tenths / 10.0
        config = ThermalConfig(threshold=threshold, camera_cap=700.0, mono16_gain=0.05,
                               mono16_offset=-300.0)
        if encoding == '16UC1':
            at, below = np.uint16(round((threshold + 273.15) * 100)), -1
        elif encoding == 'mono16':
            at, below = np.uint16(round((threshold + 300.0) / 0.05)), -1
        else:
            at, below = np.float32(threshold), -0.01
        image = np.zeros((2, 2), type(at)) if encoding != '32FC1' else \
            np.full((2, 2), -100.0, np.float32)
        image[0, 0] = at
        image[1, 1] = at + below if encoding == '32FC1' else at - 1
        stats = ThermalAnalyzer(config).statistics(image, encoding)
        if stats.n_p != 1:
            missed.append((threshold, stats.n_p))
    assert not missed, missed[:5]


def looking_down(height=0.15, width_px=160, height_px=120, fov=math.radians(57.0)):
    """Return (camera, GroundMapping) of a thermal camera `height` [m] over the origin."""
    camera = PinholeCamera.from_fov(width_px, height_px, fov)
    T_world_camera = np.diag([1.0, -1.0, -1.0, 1.0])     # optical z down onto z = 0
    T_world_camera[2, 3] = height
    return camera, GroundMapping(camera, T_world_camera)


def test_the_window_holds_the_pixels_of_its_disc_on_the_ground():
    camera, mapping = looking_down()
    radius, centre = 0.005, (0.01, -0.02)
    mask = window_mask(mapping, (120, 160), centre, radius)
    # analytic: a pixel covers (h / f)^2 of ground straight below; the disc is pi r^2
    pixel = 0.15 / camera.matrix[0, 0]
    expected = math.pi * radius ** 2 / pixel ** 2
    assert abs(np.count_nonzero(mask) - expected) <= 0.08 * expected
    # and it sits where the camera sees the centre
    u, v = camera.project(np.array([[centre[0], -centre[1], 0.15]]))[0]
    rows, cols = np.nonzero(mask)
    assert abs(cols.mean() - u) < 0.5 and abs(rows.mean() - v) < 0.5


def test_n_p_in_the_window_leaves_out_the_previous_dots_afterglow():
    camera, mapping = looking_down()
    raw = np.full((120, 160), 29815, np.uint16)              # 25 degC
    previous = camera.project(np.array([[0.0, 0.0, 0.15]]))[0].round().astype(int)
    current = camera.project(np.array([[0.012, 0.0, 0.15]]))[0].round().astype(int)
    raw[previous[1] - 1:previous[1] + 2, previous[0] - 1:previous[0] + 2] = CAP_RAW  # 9 px
    raw[current[1], current[0]:current[0] + 2] = CAP_RAW - 2000                      # 2 px
    raw[current[1] + 1, current[0]] = CAP_RAW                                        # 1 px
    analyzer = ThermalAnalyzer()
    window = window_mask(mapping, raw.shape, (0.012, 0.0), 0.004)
    result = analyzer.statistics(raw, '16UC1', window)
    assert result.n_p == 10 and result.window_n_p == 1
    assert result.t_max == pytest.approx(180.9) and \
        result.window_t_max == pytest.approx(180.9)
    cooler = analyzer.statistics(np.where(raw == CAP_RAW, CAP_RAW - 1000, raw), '16UC1', window)
    assert cooler.window_n_p == 0 and cooler.window_t_max == pytest.approx(170.9)
    # no window: no window figures; a mask of another size is refused
    assert math.isnan(analyzer.statistics(raw, '16UC1').window_t_max)
    with pytest.raises(ValueError, match='window mask'):
        analyzer.statistics(raw, '16UC1', window[:-1])


@pytest.mark.parametrize('seed, peak', [(0, 260.0), (1, 150.0), (2, 139.0)])
def test_a_camera_capped_below_t_p_counts_its_saturated_pixels(seed, peak):
    # issue 29: a Lepton 3.5 in high gain reads up to 140 degC; every hotter pixel reads 140
    raw = lepton_frame(seed, peak)
    true_celsius = raw / 100.0 - 273.15
    high_gain = np.minimum(raw, 41315).astype(np.uint16)           # 140.00 degC
    analyzer = ThermalAnalyzer(ThermalConfig(threshold=180.9, camera_cap=140.0))
    stats = analyzer.statistics(high_gain, 'mono16')
    # the direct count, on the true temperatures: the pixels at or above the cap
    assert stats.n_p == int(np.sum(true_celsius >= 140.0))
    assert stats.threshold == 140.0 and stats.camera_cap == 140.0
    assert stats.saturated == (peak >= 140.0)
    assert (stats.n_p > 0) == (peak >= 140.0)


def test_the_papers_rule_is_the_case_where_the_cap_is_t_p():
    raw = lepton_frame(0, 260.0)
    config = ThermalConfig(threshold=180.9, camera_cap=180.9)
    assert config.counting_level == 180.9
    assert camera_range_report(config) == ''
    wider = ThermalConfig(threshold=180.9, camera_cap=400.0)     # a low-gain Lepton
    assert wider.counting_level == 180.9 and camera_range_report(wider) == ''
    assert ThermalAnalyzer(config).statistics(raw, '16UC1').n_p == \
        ThermalAnalyzer(wider).statistics(raw, '16UC1').n_p


def test_a_camera_range_below_t_p_is_reported_and_one_that_cannot_see_charring_refused():
    warning = camera_range_report(ThermalConfig(threshold=180.9, camera_cap=140.0))
    assert '140' in warning and 'saturated' in warning
    with pytest.raises(ValueError, match='low gain'):
        camera_range_report(ThermalConfig(threshold=180.9, camera_cap=60.0))


def test_a_frame_repeated_bit_for_bit_under_a_newer_stamp_is_frozen():
    detector = FreezeDetector()
    live = [lepton_frame(seed) for seed in range(3)]
    assert not detector.frozen(live[0], 1.0)
    assert not detector.frozen(live[1], 1.1)
    assert detector.frozen(live[1].copy(), 1.2)          # the camera holds its output
    assert detector.frozen(live[1].copy(), 1.2)          # sent again: the verdict stands
    assert detector.frozen(live[1], 1.3)
    assert not detector.frozen(live[2], 1.4)             # the shutter opens again
    assert not detector.frozen(live[2].copy(), 1.4)      # a resend of a live frame is live
    assert detector.frozen_frames == 2
