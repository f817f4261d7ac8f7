"""
The frames of a still lens pose merged into one observation, and its sigma (issue 35).

The truth here is built by hand: poses, centres and the sun the model casts them with.
"""

import math

from helio_optics.centre_noise import CentreNoise, frame_verdicts, merge_holds
from helio_optics.geometry import homogeneous, rotation_y, rotation_z, unit
from helio_optics.lens import LensParameters
from helio_optics.sun_estimation import Observation, SunEstimator, TrustSettings
import numpy as np
import pytest

NOISE = CentreNoise(floor=0.02e-3, per_cot=0.08e-3, frame=0.01e-3, frame_tolerance=0.3e-3,
                    max_tilt=math.radians(15.0))


def pose(x, tilt_deg=0.0, height=0.07):
    """Return a lens pose at (x, 0, height), its axis tilted about y by `tilt_deg`."""
    return homogeneous(rotation_y(math.radians(tilt_deg)), [x, 0.0, height])


def frames(centres, lens_pose):
    """Return observations of one lens pose at the given centres (plane z = 0)."""
    return [Observation(np.array(c, dtype=float), lens_pose) for c in centres]


def test_sigma_grows_as_the_chief_ray_comes_in_flatter_and_falls_with_frames():
    overhead = NOISE.sigma(0.5 * math.pi, frames=1)
    assert overhead == pytest.approx(math.hypot(0.02e-3, 0.01e-3))
    assert NOISE.sigma(math.radians(30.0)) == pytest.approx(math.sqrt(
        0.02e-3 ** 2 + (0.08e-3 / math.tan(math.radians(30.0))) ** 2 + 0.01e-3 ** 2))
    assert NOISE.sigma(math.radians(30.0)) > NOISE.sigma(math.radians(60.0)) > overhead
    assert NOISE.sigma(0.5 * math.pi, frames=4) < overhead
    # the chief ray of an observation: lens centre to spot centre, 15 deg off a level lens'
    # axis, so 75 deg above the ground
    lens = pose(0.2, tilt_deg=0.0, height=0.07)
    spot = Observation(np.array([0.2 + 0.07 * math.tan(math.radians(15.0)), 0.0, 0.0]), lens)
    assert math.degrees(NOISE.tilt(spot)) == pytest.approx(15.0)
    assert math.degrees(NOISE.elevation(spot)) == pytest.approx(75.0)
    assert NOISE.of(spot, frames=2).sigma == pytest.approx(NOISE.sigma(math.radians(75.0), 2))


@pytest.mark.parametrize('name, value', [('floor', -1e-3), ('per_cot', math.nan),
                                         ('frame_tolerance', math.inf), ('max_tilt', -0.1)])
def test_values_out_of_range_are_refused_by_name(name, value):
    with pytest.raises(ValueError, match=name):
        CentreNoise(**{name: value})
    with pytest.raises(ValueError, match='sigma of 0'):
        CentreNoise(floor=0.0, frame=0.0)


def test_consecutive_frames_of_one_pose_merge_and_a_stray_frame_is_left_out():
    first, second = pose(0.2), pose(0.25, tilt_deg=10.0)
    hold_a = frames([[0.21, 0.0, 0.0], [0.21002, 0.0, 0.0], [0.20998, 0.0, 0.0],
                     [0.2115, 0.0, 0.0]], first)          # the last 1.5 mm off: a stray
    hold_b = frames([[0.26, 0.01, 0.0], [0.26, 0.01002, 0.0]], second)
    back = frames([[0.21, 0.0, 0.0]], first)               # the first pose again, later
    holds = merge_holds(hold_a + hold_b + back, NOISE)
    assert [h.members for h in holds] == [[0, 1, 2, 3], [4, 5], [6]]
    assert holds[0].left_out == [3]
    np.testing.assert_allclose(holds[0].observation.centre, [0.21, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(holds[1].observation.centre, [0.26, 0.01001, 0.0], atol=1e-12)
    assert holds[0].observation.sigma == pytest.approx(NOISE.sigma(NOISE.elevation(
        holds[0].observation), 3))
    # the second hold's chief ray comes in flatter (its spot farther from the lens foot)
    assert NOISE.elevation(holds[1].observation) < NOISE.elevation(holds[0].observation)
    assert holds[1].observation.sigma > holds[0].observation.sigma


def test_the_hold_takes_the_mean_time_offset_and_stays_on_the_plane():
    lens = pose(0.2)
    tilted = unit([0.0, 0.1, 1.0])
    observations = [Observation(np.array([0.21, 0.0, 0.0]), lens, (0.0, 0.0, 0.0), tilted,
                                angle_offset=(1e-4 * k, -2e-4 * k)) for k in range(3)]
    (hold,) = merge_holds(observations, NOISE)
    assert hold.observation.angle_offset == pytest.approx((1e-4, -2e-4))
    assert float(hold.observation.centre @ tilted) == pytest.approx(0.0, abs=1e-15)


def test_a_frame_without_a_centre_stays_apart_to_be_screened_out():
    lens = pose(0.2)
    observations = frames([[0.21, 0.0, 0.0], [math.nan, 0.0, 0.0], [0.21, 0.0, 0.0]], lens)
    assert [h.members for h in merge_holds(observations, NOISE)] == [[0], [1], [2]]


def test_the_fit_on_holds_is_told_per_frame():
    """Six holds of three frames of one sun, one hold 3 mm off: its frames are named."""
    estimator = SunEstimator(LensParameters(), contour_fraction=0.7)
    sun = unit([0.3, -0.2, -0.8])
    observations, shifted = [], 4
    for k in range(6):
        lens = homogeneous(rotation_y(math.radians(-8.0 + 3.0 * k)), [0.2 + 0.01 * k, 0.0, 0.06])
        one = estimator.synthetic_observation(sun, lens)
        for _ in range(3):
            centre = one.centre + ([0.003, 0.0, 0.0] if k == shifted else 0.0)
            observations.append(Observation(centre, lens))
    holds = merge_holds(observations, NOISE)
    assert len(holds) == 6
    result = estimator.estimate([h.observation for h in holds])
    assert result.trustworthy, result.reason
    assert math.degrees(math.acos(min(1.0, result.direction @ sun))) < 0.01
    verdicts = frame_verdicts(holds, result, NOISE)
    assert [i for i, _ in verdicts.left_out] == [12, 13, 14]
    assert sorted(verdicts.used) == [i for i in range(18) if i not in (12, 13, 14)]
    assert len(verdicts.deviations) == len(verdicts.used)
    # the hold's deviation, squared over the holds, is the fit's chi-square
    assert sum(d ** 2 for d in verdicts.deviations[::3]) == pytest.approx(result.chi2)


def test_twin_suns_of_a_level_lens_are_flagged_with_the_measured_noise():
    """
    Twin suns (a false minimum) stay flagged with the measured, tighter sigma.

    Three suns cast the same spots through a level lens (built by root finding,
    ``test_sun_estimation.level_lens_pair``); four frames a yaw, noise drawn at the measured
    sigma of each hold. Unscreened the estimate is ambiguous with the truth among its
    minima; with the node's chief-ray limit (the sun stands 22 deg off the level lens' axis)
    it is refused outright.
    """
    from test_sun_estimation import level_lens_pair, RIM_ESTIMATOR, YAWS
    lens, suns = level_lens_pair()
    truth = suns[0]
    rng = np.random.default_rng(5)
    observations = []
    for yaw in YAWS:
        model = RIM_ESTIMATOR.synthetic_observation(truth, homogeneous(rotation_z(yaw), lens))
        sigma = NOISE.of(model).sigma
        shared = rng.normal(0.0, sigma, 2)              # the hold's own error
        for _ in range(4):
            centre = model.centre + [*(shared + rng.normal(0.0, 0.002e-3, 2)), 0.0]
            observations.append(Observation(centre, model.T_robot_lens))
    holds = merge_holds(observations, NOISE)
    assert len(holds) == len(YAWS)
    merged = [h.observation for h in holds]
    result = RIM_ESTIMATOR.estimate(merged)
    assert result.converged and result.ambiguous and not result.trustworthy, result.reason
    found = [result.direction] + [a.direction for a in result.alternatives]
    assert min(math.degrees(math.acos(min(1.0, d @ truth))) for d in found) < 0.1
    screened = RIM_ESTIMATOR.estimate(merged, trust=TrustSettings(
        max_chief_ray_tilt=NOISE.max_tilt))
    assert not screened.trustworthy and 'off its lens axis' in screened.reason
