"""
spot_detector's camera_info_file (issue 29, item 5): a calibration for a camera sent uncalibrated.

A webcam driven by usb_cam without a calibration file sends camera_info with the image size
and K = 0; spot_detector refuses to map a spot without intrinsics. Given the file ``helio
calibrate camera`` writes, it uses the file's intrinsics for that camera; a file for another
image size is refused with the reason; a calibrated camera_info is used as it comes.
"""

from helio_msgs.msg import SpotObservation
from helio_optics.node_kit.conversions import camera_info_from_camera, numpy_to_image
from helio_optics.node_kit.conversions import stamp_from_seconds
from helio_optics.node_kit.in_process_graph import InProcessGraph
from helio_perception.camera_calibration import write_camera_info
from helio_perception.spot_detector_node import SpotDetectorNode
from helio_perception.synthetic_scene import SyntheticScene
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo, Image


@pytest.fixture
def graph():
    """Yield an InProcessGraph; close it afterwards."""
    with InProcessGraph('camera_info_file_test') as in_process:
        yield in_process


def feed(graph, info):
    """Publish `info` on rgb/camera_info; return the rgb/image_raw publisher."""
    images = graph.helper.create_publisher(Image, 'rgb/image_raw', 10)
    infos = graph.helper.create_publisher(CameraInfo, 'rgb/camera_info', 10)
    graph.wait_until(lambda: min(p.get_subscription_count() for p in (images, infos)) > 0,
                     what='the node subscribing to its inputs')
    infos.publish(info)
    return images


def test_an_uncalibrated_camera_takes_the_files_calibration(graph, tmp_path):
    scene = SyntheticScene(640, 480)
    rng = np.random.default_rng(5)
    T_world_camera, (spot,) = scene.random_view(rng, spot_options={'value': 0.8})
    frame = scene.render(T_world_camera, [spot], rng=rng)
    path = write_camera_info(tmp_path / 'rgb.yaml', scene.camera, 'rgb_camera')
    node = graph.add(SpotDetectorNode(**graph.node_options(
        **{'marker.side': scene.marker_side, 'camera_info_file': str(path)})))
    received = graph.collect(SpotObservation, 'spot')
    images = feed(graph, CameraInfo(width=640, height=480))    # K = 0, as usb_cam
    graph.wait_until(lambda: node.camera is not None, what='the file taken as the camera')
    np.testing.assert_allclose(node.camera.matrix, scene.camera.matrix)
    message = numpy_to_image(frame.image, 'rgb8')
    message.header.stamp = stamp_from_seconds(10.0)
    images.publish(message)
    first = received.wait_for_count(1)[0]
    assert first.valid, first.reason
    assert np.hypot(first.center.x - spot.center[0], first.center.y - spot.center[1]) < 2e-4


def test_a_file_for_another_image_size_is_refused_with_the_reason(graph, tmp_path):
    scene = SyntheticScene(640, 480)
    other = SyntheticScene(1280, 720).camera
    path = write_camera_info(tmp_path / 'rgb.yaml', other, 'rgb_camera')
    node = graph.add(SpotDetectorNode(**graph.node_options(camera_info_file=str(path))))
    feed(graph, CameraInfo(width=640, height=480))
    graph.wait_until(lambda: node.file_refused, what='the file refused')
    assert node.camera is None
    assert 'is for 1280x720 images, rgb/camera_info says 640x480' in node.file_refused
    # a calibrated camera_info is used as it comes, the file aside
    calibrated = camera_info_from_camera(scene.camera, stamp_from_seconds(1.0), 'rgb')
    feed(graph, calibrated)
    graph.wait_until(lambda: node.camera is not None, what='the driver calibration taken')
    np.testing.assert_allclose(node.camera.matrix, scene.camera.matrix)
