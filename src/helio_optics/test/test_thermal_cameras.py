"""The thermal cameras' datasheet values (issue 29, item 1)."""

import math

from helio_optics.thermal_cameras import thermal_camera, THERMAL_CAMERAS
import pytest


def test_the_lepton_modes_carry_the_datasheets_ranges_and_accuracies():
    # FLIR Lepton Engineering Datasheet 500-0659-00-09 rev 203: Lepton 3.5, 160 x 120, 57 deg
    # HFOV, 8.7 Hz; high gain -10..140 degC, +-5 degC or 5 %; low gain -10..400 degC,
    # +-10 degC or 10 %; radiometric TLinear centikelvin (usb_cam's Y16: mono16)
    high, low = thermal_camera('lepton35_high_gain'), thermal_camera('lepton35_low_gain')
    for spec in (high, low):
        assert (spec.width, spec.height, spec.frame_rate) == (160, 120, 8.7)
        assert spec.horizontal_fov == pytest.approx(math.radians(57.0))
        assert spec.encoding == 'mono16' and spec.floor == -10.0
        assert spec.ffc_period == 180.0 and spec.ffc_freeze == (0.3, 1.0)
    assert (high.cap, low.cap) == (140.0, 400.0)
    assert high.accuracy_at(50.0) == 5.0 and high.accuracy_at(130.0) == pytest.approx(6.5)
    assert low.accuracy_at(50.0) == 10.0 and low.accuracy_at(300.0) == pytest.approx(30.0)


def test_the_papers_camera_caps_at_its_pyrolysis_threshold_without_freezes():
    paper = thermal_camera('paper')
    assert paper.cap == 180.9 and paper.encoding == '16UC1'
    assert paper.ffc_period == 0.0 and paper.accuracy_at(180.0) == 0.0


def test_an_unknown_camera_is_refused_naming_the_known_ones():
    with pytest.raises(ValueError) as error:
        thermal_camera('lepton2')
    for name in THERMAL_CAMERAS:
        assert name in str(error.value)
