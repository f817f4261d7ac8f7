"""
The robot-world calibration procedure in-process against a model rig: the marker found.

The rig file puts the marker 5.4 mm and 2 deg off where the model rig has it (as the
simulated graph's controller rig file); the procedure sees only the noisy marker poses of
the true camera and the reported joints, and must give the true T_robot_world back.
"""

import math

from fake_lens_rig import FakeLensRig, moved_world, nominal_rig, run, sun_at
from helio_control.procedures.lens_rig_port import GoalCanceled, GoalFailed
from helio_control.procedures.world_calibration_run import calibrate_world
from helio_msgs.action import CalibrateWorld
from helio_optics.rig_kinematics import Rig
import numpy as np
import pytest

SUN = sun_at(50.0, 230.0)
TRUE_SHIFT = np.array([0.005, -0.002, 0.0])        # 5.4 mm
TRUE_TURN_DEG = 2.0


def model_rig(**options):
    true = Rig(moved_world(nominal_rig(), TRUE_SHIFT, TRUE_TURN_DEG))
    return FakeLensRig(SUN, true_rig=true, **options)


def test_the_true_marker_comes_back_from_noisy_views_and_is_used_and_saved():
    rig = model_rig(marker_noise=(2e-4, math.radians(0.1)), seed=4)
    result = CalibrateWorld.Result()
    run(calibrate_world(rig, CalibrateWorld.Goal(apply=True), result))
    truth = rig.true_rig.parameters
    error = np.linalg.norm(np.asarray(rig.rig.parameters.world_in_robot)
                           - np.asarray(truth.world_in_robot))
    # 8 poses of 4 frames, 0.2 mm and 0.1 deg each: a fraction of a millimetre
    assert error < 3e-4
    assert math.degrees(abs(rig.rig.parameters.world_yaw - truth.world_yaw)) < 0.1
    assert rig.world_calibrated
    assert result.poses_used == 32 and len(rig.moves) == 8
    assert result.shift_from_rig_file == pytest.approx(np.linalg.norm(TRUE_SHIFT), abs=4e-4)
    assert math.degrees(result.turn_from_rig_file) == pytest.approx(TRUE_TURN_DEG, abs=0.1)
    tree, notes = rig.saved['robot_world.yaml']
    assert tree['rig']['world_yaw'] == rig.rig.parameters.world_yaw
    assert notes['poses_used'] == 32
    assert result.saved_to == 'memory:robot_world.yaml'
    assert result.message.startswith('T_robot_world from 32 poses (0 left out): marker at ')
    assert [f.phase for f in rig.feedbacks[:2]] == ['moving', 'observing']


def test_without_apply_the_rig_keeps_its_belief():
    rig = model_rig()
    before = rig.rig.parameters.world_in_robot
    result = CalibrateWorld.Result()
    run(calibrate_world(rig, CalibrateWorld.Goal(poses=5, apply=False), result))
    assert rig.rig.parameters.world_in_robot == before and not rig.saved
    assert result.message.endswith('(not applied)')
    # exact views: the estimate is the truth to numerical precision
    assert result.shift_from_rig_file == pytest.approx(np.linalg.norm(TRUE_SHIFT), abs=1e-9)


def test_no_marker_in_view_fails_naming_the_count():
    # the model's marker 30 cm from where the rig file puts it: no view shows it
    rig = FakeLensRig(SUN, true_rig=Rig(moved_world(nominal_rig(), [0.3, 0.0, 0.0], 0.0)))
    with pytest.raises(GoalFailed, match='robot-world calibration failed: '):
        run(calibrate_world(rig, CalibrateWorld.Goal(), CalibrateWorld.Result()))
    assert sum(warning for warning, _ in rig.logs) == 8


def test_a_cancel_ends_the_calibration_unapplied():
    rig = model_rig(cancel_after=3)
    before = rig.rig.parameters
    with pytest.raises(GoalCanceled):
        run(calibrate_world(rig, CalibrateWorld.Goal(apply=True), CalibrateWorld.Result()))
    assert rig.rig.parameters == before and not rig.saved
