"""
The sun sweep procedure in-process against a model rig: the spot found, the sun measured.

The model rig's sun stands where the ephemeris puts it over the site at the fake clock's
time (the acquisition takes the elevation from there) at an azimuth in the robot frame the
procedure does not know; its spots are those the lens model casts, 0.05 mm of noise each.
The estimate (``SunEstimator`` on the sweep's spots) must be the model's sun.
"""

import math

from fake_lens_rig import FakeLensRig, START, sun_at
from fake_lens_rig import run
from helio_control.procedures.lens_rig_port import GoalFailed
from helio_control.procedures.sun_sweep_run import ACQUISITION_D_LP_OFFSETS, sweep_sun
from helio_control.procedures.sun_sweep_run import utc
from helio_msgs.action import SweepSun
from helio_optics.config_files import config_path
from helio_optics.ephemeris import load_site, sun_position
from helio_optics.spot import spot_area, spot_area_at
import numpy as np
import pytest

ELEVATION = math.degrees(sun_position(load_site(config_path('site.yaml')),
                                      utc(START)).elevation)


def angle_deg(a, b):
    return math.degrees(math.acos(min(1.0, float(np.dot(a, b)))))


@pytest.mark.parametrize('azimuth', [230.0, 160.0])
def test_without_an_estimate_the_spot_is_found_and_the_sweep_measures_the_sun(azimuth):
    true_sun = sun_at(ELEVATION, azimuth)
    rig = FakeLensRig(true_sun, world_calibrated=True, spot_noise=5e-5, seed=1)
    result = SweepSun.Result()
    run(sweep_sun(rig, SweepSun.Goal(), result))
    assert 20.0 < ELEVATION < 80.0        # the test's premise: a sun to paint with
    assert angle_deg(rig.sun, true_sun) < 0.2
    assert result.poses_used == 6 and result.observations == 4 + 6 * 4   # acquisition + sweep
    assert result.message.startswith('6 of 6 sweep poses saw the spot, 28 observations')
    phases = [f.phase for f in rig.feedbacks]
    assert phases[0] == 'acquiring' and phases[-1] == 'estimating'
    # the estimate took only the sweep's spots: since its first pose was reached
    (method, since, _), = rig.estimate_calls
    assert sum(taken > since for taken, _, _ in rig.spots) == 6 * 4
    assert len(rig.spots) == 4 + 6 * 4


def test_no_acquisition_pose_holds_the_focus_on_the_wood():
    # the search poses are planned with guessed suns, up to 15 deg off: under the true sun
    # each casts a spot at least ten times the focused one's area (1.5 mm^2)
    rig = FakeLensRig(sun_at(ELEVATION, 160.0), world_calibrated=True)
    run(sweep_sun(rig, SweepSun.Goal(), SweepSun.Result()))
    searched = rig.moves[:-6]
    assert searched
    focused = spot_area_at(rig.true_lens, 0.082)
    T = rig.T_true_robot_world
    for x in searched:
        area = spot_area(rig.true_lens, rig.true_sun, rig.true_pose(x).T_robot_lens,
                         T[:3, 3], T[:3, 2])
        assert area > 10.0 * focused
    assert all(abs(offset) > rig.settings.safe_margin for offset in ACQUISITION_D_LP_OFFSETS)


def test_with_an_estimate_the_sweep_goes_around_it_without_searching():
    true_sun = sun_at(ELEVATION, 200.0)
    rig = FakeLensRig(true_sun, believed_sun=sun_at(ELEVATION + 1.0, 201.0),
                      world_calibrated=True, spot_noise=5e-5)
    result = SweepSun.Result()
    run(sweep_sun(rig, SweepSun.Goal(poses=4), result))
    assert 'acquiring' not in [f.phase for f in rig.feedbacks]
    assert len(rig.moves) == 4
    assert angle_deg(rig.sun, true_sun) < 0.25


def test_a_sun_under_clouds_is_never_found():
    rig = FakeLensRig(sun_at(ELEVATION, 230.0), world_calibrated=True, clouds=True)
    with pytest.raises(GoalFailed, match='the spot was not found at any of'):
        run(sweep_sun(rig, SweepSun.Goal(), SweepSun.Result()))
    assert rig.sun is None
