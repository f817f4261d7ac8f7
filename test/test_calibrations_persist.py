"""
Calibrations read back at start (issue 30): the lens planner as its own process.

The lens planner saves the robot-world and focal calibrations in ``calibration_dir``
(``helio_control.calibration_store``, with the digest of the rig file they were made for).
Started again on that directory it must publish and use them (``calibration/world_pose``,
``calibration/focus``, both latched, which the other nodes follow) without calibrating again;
files made for another rig description are refused, named in its log, and not used.
"""

import math
import shutil

from conftest import graph_of_processes
from geometry_msgs.msg import PoseStamped
from helio_control.calibration_store import rig_description, save_calibration
from helio_msgs.msg import FocalCalibration
from helio_optics.config_files import config_path
from helio_optics.node_kit.conversions import pose_to_matrix
from helio_optics.node_kit.in_process_graph import GraphTimeout, TRANSIENT_LOCAL_QOS
import pytest

WORLD = {'world_in_robot': [0.1472, -0.0981, -0.1403], 'world_yaw': 0.0123}
HEATING_DISTANCE = 0.0846


def saved(directory, rig_file):
    """Save both calibrations in `directory` as the lens planner does, for `rig_file`."""
    description = rig_description(rig_file)
    save_calibration(directory, 'robot_world.yaml', {'rig': WORLD}, description,
                     'lens_planner', {'residual_position_m': 1e-5})
    save_calibration(directory, 'focus.yaml', {'heating_distance': HEATING_DISTANCE,
                                               'min_area': 1.9e-6, 'samples': 35},
                     description, 'lens_planner')


def started(tmp_path, name, rig_file, calibrations):
    """Start the lens planner on `calibrations`; return (group, graph) context."""
    overrides = {'lens_planner': {'calibration_dir': str(calibrations),
                                  'rig_file': str(rig_file)}}
    return graph_of_processes(tmp_path / name, ('lens_planner',), overrides)


def test_both_calibrations_survive_a_restart_and_another_rigs_are_refused(tmp_path):
    rig_file = tmp_path / 'rig.yaml'
    shutil.copy(config_path('rig.yaml'), rig_file)
    calibrations = tmp_path / 'calibration'
    saved(calibrations, rig_file)
    for run in ('first', 'restarted'):         # read back, and again after a restart
        with started(tmp_path, run, rig_file, calibrations) as (_, graph):
            world = graph.collect(PoseStamped, 'calibration/world_pose', TRANSIENT_LOCAL_QOS)
            focus = graph.collect(FocalCalibration, 'calibration/focus', TRANSIENT_LOCAL_QOS)
            pose = world.wait_for_count(1, 60.0)[0]
            transform = pose_to_matrix(pose.pose)
            assert transform[:3, 3] == pytest.approx(WORLD['world_in_robot'], abs=1e-9)
            assert math.atan2(transform[1, 0], transform[0, 0]) == pytest.approx(
                WORLD['world_yaw'], abs=1e-9)
            assert focus.wait_for_count(1, 60.0)[0].heating_distance == pytest.approx(
                HEATING_DISTANCE)
    # the rig file edited (a link measured again): the saved calibrations are another rig's
    with open(rig_file, 'a') as stream:
        stream.write('# j2 link measured again\n')
    with started(tmp_path, 'edited', rig_file, calibrations) as (group, graph):
        focus = graph.collect(FocalCalibration, 'calibration/focus', TRANSIENT_LOCAL_QOS)
        world = graph.collect(PoseStamped, 'calibration/world_pose', TRANSIENT_LOCAL_QOS)
        log = tmp_path / 'edited' / 'logs' / 'lens_planner.log'
        graph.wait_until(lambda: log.exists() and 'lens_planner: rig from' in log.read_text(),
                         60.0, 'the lens planner started')
        text = log.read_text()
        assert text.count('calibration not used') == 2, text
        assert 'was made for rig description' in text and 'calibrate again' in text
        with pytest.raises(GraphTimeout):
            focus.wait_for_count(1, 3.0)
        assert world.messages == []
