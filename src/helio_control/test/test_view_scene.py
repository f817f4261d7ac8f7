"""The Foxglove view's drawings (view_scene) against the camera model and the schemas."""

import json

from helio_control.view_scene import ground_ellipse, IMAGE_ANNOTATIONS, project_to_image
from helio_control.view_scene import ray_entity, ray_line, rgb_annotations, SCENE_UPDATE
from helio_control.view_scene import scene_update, schema_bytes, schema_errors, SCHEMAS
from helio_control.view_scene import thermal_annotations, time_dict
from helio_optics.geometry import PinholeCamera
import numpy as np
import pytest

F, CX, CY, HEIGHT = 500.0, 320.0, 240.0, 0.2
CAMERA = PinholeCamera(matrix=np.array([[F, 0, CX], [0, F, CY], [0, 0, 1.0]]),
                       width=640, height=480)
# optical frame looking straight down from HEIGHT above the world origin: x along world x,
# y along world -y, z along world -z
T_WORLD_CAMERA = np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, HEIGHT],
                           [0, 0, 0, 1.0]])
MARKER = np.array([[-0.02, 0.02, 0], [0.02, 0.02, 0], [0.02, -0.02, 0], [-0.02, -0.02, 0]])


def pinhole(point):
    """Pixel of a world ground point under the camera above (similar triangles)."""
    return CX + F * point[0] / HEIGHT, CY - F * point[1] / HEIGHT


def test_projection_matches_the_pinhole_by_hand():
    points = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.03, -0.02, 0.0],
                       [0.0, 0.0, 0.5]])
    pixels, front = project_to_image(CAMERA, T_WORLD_CAMERA, points)
    assert front.tolist() == [True, True, True, False]
    for point, pixel in zip(points[:3], pixels[:3]):
        assert pixel == pytest.approx(pinhole(point), abs=1e-9)
    assert np.all(np.isnan(pixels[3]))


def test_ground_ellipse_has_its_axes():
    points = ground_ellipse((0.01, 0.02, 0.0), 0.004, 0.001, np.pi / 2, count=4)
    # the major axis along world y (orientation 90 deg)
    assert points[0] == pytest.approx((0.01, 0.024, 0.0))
    assert points[1] == pytest.approx((0.009, 0.02, 0.0))


def test_rgb_annotations_draw_the_spot_marker_and_targets_where_the_camera_sees_them():
    spot = {'center': (0.01, 0.0, 0.0), 'semi_major': 0.002, 'semi_minor': 0.001,
            'orientation': 0.0}
    message = rgb_annotations(1_500_000_000, CAMERA, T_WORLD_CAMERA, MARKER, spot,
                              current_target=(0.03, 0.03, 0.0),
                              next_targets=[(0.04, 0.03, 0.0)], burnt=[(0.02, 0.03, 0.0)])
    assert schema_errors(message, SCHEMAS[IMAGE_ANNOTATIONS]) == []
    marker, ellipse = message['points']
    assert [(p['x'], p['y']) for p in marker['points']] == \
        [pytest.approx(pinhole(c)) for c in MARKER]
    centre, burnt, following, current = message['circles']
    assert (centre['position']['x'], centre['position']['y']) == \
        pytest.approx(pinhole((0.01, 0.0)))
    # the ellipse reaches semi_major along x: 0.002 m = F * 0.002 / HEIGHT px
    xs = [p['x'] for p in ellipse['points']]
    assert max(xs) - min(xs) == pytest.approx(2 * F * 0.002 / HEIGHT)
    assert (burnt['position']['x'], burnt['position']['y']) == pytest.approx(
        pinhole((0.02, 0.03)))
    assert (following['position']['x'], current['position']['x']) == pytest.approx(
        (pinhole((0.04, 0))[0], pinhole((0.03, 0))[0]))
    assert message['texts'][0]['text'] == 'target'
    assert centre['timestamp'] == {'sec': 1, 'nsec': 500_000_000}
    json.dumps(message)      # plain JSON, no numpy values


def test_behind_the_camera_nothing_is_drawn():
    above = np.array([[0, 0, 1.0]] * 4)
    message = rgb_annotations(0, CAMERA, T_WORLD_CAMERA, above, None,
                              current_target=(0, 0, 1.0))
    assert message == {'circles': [], 'points': [], 'texts': []}


def test_thermal_annotations():
    outline = np.array([[10.0, 10.0], [20.0, 10.0], [20.0, 20.0]])
    message = thermal_annotations(7, (80, 60), 181.25, 31, (outline, 12))
    assert schema_errors(message, SCHEMAS[IMAGE_ANNOTATIONS]) == []
    assert message['circles'][0]['position'] == {'x': 80.0, 'y': 60.0}
    assert message['points'][0]['points'][2] == {'x': 20.0, 'y': 20.0}
    assert 'N_p 31' in message['texts'][0]['text'] and 'N_p 12' in message['texts'][1]['text']


def test_scene_update_holds_panel_marker_targets_frames_and_the_sun():
    frames = {'lens': np.eye(4), 'rgb': T_WORLD_CAMERA}
    ray = ray_line((0.01, 0.02, 0.0), (0.0, 0.6, -0.8), 0.5)
    assert ray[0] == pytest.approx((0.01, 0.02 - 0.3, 0.4))
    message = scene_update(2 * 10**9, MARKER, (-0.04, 0.16, -0.04, 0.16),
                           [(0.05, 0.05, 0.0), (0.06, 0.05, 0.0)], ['burnt', 'current'],
                           frames, ray)
    assert schema_errors(message, SCHEMAS[SCENE_UPDATE]) == []
    by_id = {e['id']: e for e in message['entities']}
    assert set(by_id) == {'panel', 'marker', 'targets', 'lens', 'rgb', 'sun_estimate'}
    assert by_id['panel']['cubes'][0]['size']['x'] == pytest.approx(0.2)
    assert len(by_id['targets']['spheres']) == 2
    # the rgb frame's z axis points down (world -z) from its origin
    z_axis = by_id['rgb']['lines'][2]['points']
    assert z_axis[1]['z'] - z_axis[0]['z'] < 0
    truth = ray_entity(0, 'sun_truth', ray, (1, 0, 1, 1))
    assert schema_errors(truth, SCHEMAS[SCENE_UPDATE]['properties']['entities']['items']) == []


def test_schema_errors_find_what_is_wrong():
    schema = SCHEMAS[IMAGE_ANNOTATIONS]
    assert schema_errors({'circles': [], 'points': []}, schema) == ['$: texts missing']
    bad = {'circles': [{'timestamp': time_dict(0), 'position': {'x': 'a', 'y': 0},
                        'diameter': 1, 'thickness': 1, 'fill_color': {}, 'outline_color': {}}],
           'points': [], 'texts': []}
    errors = schema_errors(bad, schema)
    assert "$.circles[0].position.x: 'a' is not an number" in errors
    assert '$.circles[0].fill_color: r missing' in errors
    assert json.loads(schema_bytes(SCENE_UPDATE))['type'] == 'object'
