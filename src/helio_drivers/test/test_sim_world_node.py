"""Node sim_world in-process: /clock, camera topics on simulated time, canvas, parameters."""

import os

from helio_drivers.sim_world import flat_settings, SimSettings
from helio_drivers.sim_world_node import PARAMETER_DOCS, SimWorldNode
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image
from test_sim_world import RIG_YAML
import yaml


@pytest.fixture
def context():
    """Yield a private rclpy context, shut down afterwards."""
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


def wait_for(executor, node, predicate, timeout=30.0):
    """Spin until predicate() holds (checked by a timer of `node`) or `timeout` [s] passes."""
    future = rclpy.task.Future(executor=executor)

    def check():
        if predicate() and not future.done():
            future.set_result(True)

    timer = node.create_timer(0.02, check)
    executor.spin_until_future_complete(future, timeout_sec=timeout)
    node.destroy_timer(timer)
    return future.done()


def test_sim_world_publishes_clock_cameras_and_canvas_on_sim_time(context, tmp_path):
    overrides = [Parameter('real_time_factor', value=20.0),
                 Parameter('dobot_port', value=str(tmp_path / 'dobot')),
                 Parameter('servo_port', value=str(tmp_path / 'servo')),
                 Parameter('rig_file', value=RIG_YAML),
                 Parameter('flux_rays', value=5000),
                 Parameter('canvas_rate_hz', value=2.0),
                 Parameter('output_dir', value=str(tmp_path / 'out'))]
    node = SimWorldNode(context=context, parameter_overrides=overrides)
    probe = rclpy.create_node('probe', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(probe)
    got = {'clock': [], 'thermal': [], 'rgb': [], 'info': [], 'canvas': []}
    probe.create_subscription(Clock, '/clock', lambda m: got['clock'].append(m),
                              QoSProfile(depth=10))
    probe.create_subscription(Image, '/thermal/image_raw', lambda m: got['thermal'].append(m),
                              qos_profile_sensor_data)
    probe.create_subscription(Image, '/rgb/image_raw', lambda m: got['rgb'].append(m),
                              qos_profile_sensor_data)
    probe.create_subscription(CameraInfo, '/rgb/camera_info', lambda m: got['info'].append(m),
                              qos_profile_sensor_data)
    probe.create_subscription(Image, '/sim/canvas', lambda m: got['canvas'].append(m),
                              QoSProfile(depth=1))
    try:
        assert wait_for(executor, probe, lambda: all(len(v) >= 3 for v in got.values()))
        assert (tmp_path / 'dobot').exists() and (tmp_path / 'servo').exists()
        thermal = got['thermal'][-1]
        assert (thermal.encoding, thermal.width, thermal.height) == ('16UC1', 160, 120)
        assert thermal.header.frame_id == 'thermal'
        # stamps are simulated time: they start at 0 and follow the 8.7 Hz period
        stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in got['thermal']]
        assert stamps[0] < 1.0
        assert all(0.05 < b - a < 0.2 + 1e-6 for a, b in zip(stamps, stamps[1:]))
        assert len(stamps) / (stamps[-1] - stamps[0] + 1.0 / 8.7) == pytest.approx(8.7, rel=0.25)
        rgb, info = got['rgb'][-1], got['info'][-1]
        assert (rgb.encoding, rgb.width, rgb.height) == ('rgb8', info.width, info.height)
        assert list(info.k) == pytest.approx(node.world.rgb.camera.matrix.ravel().tolist())
        assert got['canvas'][-1].encoding == 'mono8'
        clock = [m.clock.sec + 1e-9 * m.clock.nanosec for m in got['clock']]
        assert all(b > a for a, b in zip(clock, clock[1:]))
    finally:
        executor.shutdown()
        node.destroy_node()
        probe.destroy_node()
    assert (tmp_path / 'out' / 'canvas.png').exists()
    assert (tmp_path / 'out' / 'dots.csv').exists()


def test_config_file_documents_every_world_setting_with_the_code_defaults():
    # config/sim_world.yaml is what users edit: it must name every world setting, with the
    # defaults SimWorld uses without it, and each must have a description and range.
    path = os.path.join(os.path.dirname(__file__), '..', 'config', 'sim_world.yaml')
    with open(path, encoding='utf-8') as stream:
        config = yaml.safe_load(stream)['/**']['ros__parameters']
    defaults = flat_settings(SimSettings())
    optional = {'cloud_schedule'}   # commented out in the file: no scheduled cloud
    missing = set(defaults) - set(config) - optional
    assert not missing, f'sim_world.yaml lacks {sorted(missing)}'
    undocumented = set(defaults) - set(PARAMETER_DOCS)
    assert not undocumented, f'no description/range for {sorted(undocumented)}'
    for name, default in defaults.items():
        if name in config:
            value = config[name]
            if isinstance(default, float):
                assert value == pytest.approx(default), name
            else:
                assert value == default, name
