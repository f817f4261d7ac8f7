"""Thermal statistics against direct counts on synthetic Lepton-like frames."""

from helio_perception.image_conversion import image_to_numpy, numpy_to_image
from helio_perception.thermal import raw_threshold, ThermalAnalyzer, ThermalConfig
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
    stats = ThermalAnalyzer().statistics(celsius, '32FC1')
    assert (stats.t_max, stats.n_p, stats.hottest_u, stats.hottest_v) == (190.0, 1, 2, 1)
    with pytest.raises(ValueError, match='all NaN'):
        ThermalAnalyzer().statistics(np.full((2, 2), np.nan, np.float32), '32FC1')
    with pytest.raises(ValueError, match="got 'rgb8'"):
        ThermalAnalyzer().statistics(np.zeros((2, 2), np.uint8), 'rgb8')
    with pytest.raises(ValueError, match='gain must be > 0'):
        ThermalAnalyzer(ThermalConfig(mono16_gain=0.0)).statistics(
            np.zeros((2, 2), np.uint16), 'mono16')
