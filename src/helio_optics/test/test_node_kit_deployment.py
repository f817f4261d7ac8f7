"""A node follows the calibrations on real topics: robot-world and the rig as built."""

import math

from geometry_msgs.msg import PoseStamped
from helio_optics.node_kit.conversions import matrix_to_pose
from helio_optics.node_kit.deployment import follow_world_calibration
from helio_optics.node_kit.in_process_graph import InProcessGraph, TRANSIENT_LOCAL_QOS
from helio_optics.rig_kinematics import Rig, RigParameters
import numpy as np
import pytest
from std_msgs.msg import String
import yaml


def test_a_node_takes_a_rig_calibration_and_refuses_a_malformed_one():
    rig, updates = Rig(RigParameters()), []
    x = np.array([0.2, 0.6, 0.5, 0.3, -0.4])
    before = rig.forward(x).T_robot_lens[:3, 3]
    with InProcessGraph() as graph:
        _, rig_subscription = follow_world_calibration(graph.helper, rig, updates.append)
        rigs = graph.helper.create_publisher(String, 'calibration/rig', TRANSIENT_LOCAL_QOS)
        worlds = graph.helper.create_publisher(PoseStamped, 'calibration/world_pose',
                                               TRANSIENT_LOCAL_QOS)
        # malformed ones, handed to the callback itself (no message is lost to the history
        # depth): each refused with a warning, nothing changed
        for malformed in ('- not\n- a mapping', yaml.safe_dump({'lens_ofset': [0, 0, 0]}),
                          'rig: [unclosed', yaml.safe_dump({'lens_offset': 'two'})):
            rig_subscription.callback(String(data=malformed))
        assert rig.calibrations_applied == 0 and updates == []
        # then a good one on the topic: the lens centre moves 2 mm along the holder's x
        rigs.publish(String(data=yaml.safe_dump({'lens_offset': [0.002, 0.0, 0.0],
                                                 'calibration_id': 'c1'})))
        graph.wait_until(lambda: rig.calibration_id == 'c1', 10.0, 'the rig calibration')
        assert rig.calibrations_applied == 1 and len(updates) == 1
        moved = rig.forward(x).T_robot_lens
        assert np.linalg.norm(moved[:3, 3] - before) == pytest.approx(0.002, abs=1e-12)
        assert moved[:3, 0] @ (moved[:3, 3] - before) == pytest.approx(0.002, abs=1e-12)
        # a robot-world calibration after it keeps the rig calibration's terms
        world = np.eye(4)
        world[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
        world[:3, 3] = [0.15, -0.1, -0.14]
        message = PoseStamped()
        message.header.frame_id = 'robot'
        message.pose = matrix_to_pose(world)
        worlds.publish(message)
        graph.wait_until(lambda: len(updates) == 2, 10.0, 'the world calibration')
        assert rig.parameters.world_yaw == pytest.approx(math.pi / 2)
        assert rig.parameters.lens_offset == pytest.approx((0.002, 0.0, 0.0))


def test_the_camera_info_file_is_the_named_one_else_the_calibration_directorys(tmp_path):
    from helio_optics.node_kit.deployment import camera_info_file_or_default
    from helio_optics.node_kit.deployment import calibration_dir_or_default, RGB_CAMERA_INFO_FILE
    import os
    directory = str(tmp_path)
    assert camera_info_file_or_default('', directory) == ''          # nothing saved: none
    saved = tmp_path / RGB_CAMERA_INFO_FILE
    saved.parent.mkdir(parents=True)
    saved.write_text('image_width: 640\n')
    assert camera_info_file_or_default('', directory) == str(saved)  # helio calibrate camera's
    assert camera_info_file_or_default('none', directory) == ''      # asked for none
    assert camera_info_file_or_default('/etc/cam.yaml', directory) == '/etc/cam.yaml'
    assert calibration_dir_or_default('') == os.path.expanduser('~/.helio/calibration')
    assert calibration_dir_or_default('~/rig') == os.path.expanduser('~/rig')
