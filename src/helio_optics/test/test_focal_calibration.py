"""Focal calibration (Sec. V-A) against analytic curves and a lens of known focus."""

import math

from helio_optics.focal_calibration import calibrate_focus, fit_focus_curve, FocusFit
from helio_optics.focal_calibration import paper_sweep
from helio_optics.lens import LensParameters, paraxial_focus_distance
from helio_optics.spot import spot_area_curve
import numpy as np
import pytest


def test_fit_recovers_an_analytic_focus_curve():
    truth = FocusFit(d_0=0.0823, waist_radius=0.6e-3, slope=0.35, rms_relative=0.0)
    d_lp = paper_sweep()
    assert d_lp.size == 35 and d_lp[0] == 0.064 and d_lp[-1] == 0.098
    fit = fit_focus_curve(d_lp, truth.area(d_lp))
    assert fit.d_0 == pytest.approx(0.0823, abs=1e-7)
    assert fit.waist_radius == pytest.approx(0.6e-3, rel=1e-4)
    assert fit.slope == pytest.approx(0.35, rel=1e-4)


def test_calibration_finds_the_focus_of_a_lens_that_differs_from_the_model():
    # The "real" lens focuses 2 mm further than the nominal one; measured areas carry
    # 5% multiplicative noise.
    real = LensParameters(focal_length=0.082)
    d_lp = paper_sweep()
    rng = np.random.default_rng(3)
    measured = spot_area_curve(real, d_lp) * (1.0 + 0.05 * rng.standard_normal(d_lp.size))
    result = calibrate_focus(d_lp, measured, lens=LensParameters())
    assert result.best_d_lp == pytest.approx(paraxial_focus_distance(real), abs=1.5e-3)
    assert result.model_best_d_lp == pytest.approx(
        paraxial_focus_distance(LensParameters()), abs=1.5e-3)
    assert result.offset == pytest.approx(0.002, abs=1.5e-3)
    assert result.model_areas.shape == d_lp.shape
    assert math.isfinite(result.fit.rms_relative)


def test_bad_sweeps_are_refused_with_the_reason():
    d_lp = paper_sweep()
    with pytest.raises(ValueError, match='one length'):
        calibrate_focus(d_lp, np.ones(3))
    with pytest.raises(ValueError, match='at least 5'):
        calibrate_focus(d_lp[:3], np.ones(3))
    with pytest.raises(ValueError, match='> 0'):
        calibrate_focus(d_lp, np.zeros(d_lp.size))
    with pytest.raises(ValueError, match='end of the sweep'):
        calibrate_focus(d_lp, d_lp * 1.0)  # monotone: the focus is outside the sweep
