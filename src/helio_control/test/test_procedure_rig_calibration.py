"""
The rig calibration procedure in-process against a drawn build: the focus placed by it.

The model rig is a build of the simulated world (``helio_drivers.sim.build.draw_build``: its
own kinematics, the Dobot's zero offsets, the servos' true neutral and travel), fed the true
joints of the reported ones; the procedure starts from the rig file, sees marker poses (0.2
mm, 0.1 deg of noise) and spot centres (0.05 mm), and must place the focus where the build
puts it: the lens poses it plans for a grid of targets, cast by the build's true lens, land
within the issue's bounds of the targets.
"""

from dataclasses import replace
import math

from fake_lens_rig import FakeLensRig, run, sun_at
from helio_control.procedures.lens_rig_port import GoalFailed
from helio_control.procedures.rig_calibration_run import calibrate_rig
from helio_drivers.sim.build import BuiltRig, draw_build
from helio_msgs.action import CalibrateRig
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
import numpy as np
import pytest
from test_rig_calibration import placement_errors, true_joints

SUN = sun_at(62.0, 300.0)   # the marker and the spot in view of a sweep at 0-10 deg


def build_rig(seed, **options):
    build = draw_build(load_rig_parameters(default_rig_file()), seed)
    return FakeLensRig(SUN, true_rig=BuiltRig(build),
                       true_joints=lambda x: true_joints(build, x), believed_sun=SUN,
                       marker_noise=(2e-4, math.radians(0.1)), spot_noise=5e-5, seed=seed,
                       **options)


@pytest.fixture(scope='module')
def calibrated():
    rig = build_rig(0)
    before = rig.rig.parameters
    result = CalibrateRig.Result()
    run(calibrate_rig(rig, CalibrateRig.Goal(poses=24, apply=True), result))
    return rig, before, result


def test_the_calibrated_rig_places_the_focus_where_the_build_puts_it(calibrated):
    rig, before, result = calibrated
    # the rig file misses by millimetres
    assert np.mean(placement_errors(before, SUN, rig.true_spot_centre)) > 1e-3
    after = placement_errors(rig.rig.parameters, rig.sun, rig.true_spot_centre)
    assert np.mean(after) < 3e-4 and np.percentile(after, 95) < 6e-4, after
    # the sun estimated again with the calibrated rig, named by the calibration
    assert math.degrees(math.acos(min(1.0, float(rig.sun @ SUN)))) < 0.3
    assert rig.estimate_calls[-1][2] == rig.saved['rig_build.yaml'][0]['calibration_id']


def test_the_result_names_what_was_measured_and_it_is_saved(calibrated):
    rig, _, result = calibrated
    assert result.views_used >= 12 and result.spots_used >= 4
    assert result.residual_position < 1e-3 and result.spot_residual < 5e-4
    assert len(result.names) == len(result.values) == len(result.sigmas)
    tree, notes = rig.saved['rig_build.yaml']
    assert set(tree['rig']) and notes['views_used'] == result.views_used
    assert rig.world_calibrated
    assert result.message.startswith(f'rig calibrated from {result.views_used} marker views')
    assert 'fitting the lens centre' in [f.phase for f in rig.feedbacks]


def test_a_refused_fit_leaves_the_rig_as_it_was():
    # a bound no fit of noisy views meets: the camera chain must fit them within 1 um
    rig = build_rig(1)
    rig.settings = replace(rig.settings, rig_max_residual=(1e-6, 0.01, 5e-4))
    before = rig.rig.parameters
    with pytest.raises(GoalFailed, match='the marker views miss the camera chain by'):
        run(calibrate_rig(rig, CalibrateRig.Goal(poses=12, apply=True),
                          CalibrateRig.Result()))
    assert rig.rig.parameters == before and not rig.saved and not rig.world_calibrated
