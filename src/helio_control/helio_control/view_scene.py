"""
What the Foxglove view draws: image annotations and the 3D scene, as plain dicts (issue 33).

Pure functions, no rclpy and no foxglove import: numpy arrays and floats in, dicts out that
match Foxglove's JSON encoding of ``foxglove.ImageAnnotations`` and ``foxglove.SceneUpdate``
(times as ``{"sec", "nsec"}``, colours ``{"r", "g", "b", "a"}`` in 0..1, enums as integers).
The bridge node (``view_bridge``) converts ROS messages into the arguments and logs the dicts
on JSON channels with the schemas below (``SCHEMAS``); the same dicts can go into an MCAP.

Frames: the scene is drawn in ``world`` (the ArUco marker, z up); ground points are world
points with z = 0.
"""

import json

import numpy as np

IMAGE_ANNOTATIONS = 'foxglove.ImageAnnotations'
SCENE_UPDATE = 'foxglove.SceneUpdate'

# Foxglove enums (PointsAnnotation.type, LinePrimitive.type)
POINTS, LINE_LOOP, LINE_STRIP = 1, 2, 3
LINE_PRIMITIVE_STRIP, LINE_PRIMITIVE_LOOP = 0, 1

SPOT_COLOUR = (1.0, 0.9, 0.1, 1.0)
MARKER_COLOUR = (0.1, 0.9, 0.2, 1.0)
TARGET_COLOUR = (0.1, 0.6, 1.0, 1.0)
BURNT_COLOUR = (0.35, 0.2, 0.1, 1.0)
HOT_COLOUR = (1.0, 0.1, 0.1, 1.0)
WINDOW_COLOUR = (1.0, 1.0, 1.0, 1.0)
SUN_ESTIMATE_COLOUR = (1.0, 0.7, 0.0, 1.0)
SUN_TRUTH_COLOUR = (0.6, 0.2, 1.0, 1.0)
PANEL_COLOUR = (0.85, 0.7, 0.5, 1.0)


def _object(properties, required=()):
    return {'type': 'object', 'properties': properties, 'required': list(required)}


_NUMBER = {'type': 'number'}
_INTEGER = {'type': 'integer'}
_TIME = _object({'sec': _INTEGER, 'nsec': _INTEGER}, ('sec', 'nsec'))
_COLOR = _object({k: _NUMBER for k in 'rgba'}, 'rgba')
_POINT2 = _object({'x': _NUMBER, 'y': _NUMBER}, 'xy')
_VECTOR3 = _object({k: _NUMBER for k in 'xyz'}, 'xyz')
_QUATERNION = _object({k: _NUMBER for k in 'xyzw'}, 'xyzw')
_POSE = _object({'position': _VECTOR3, 'orientation': _QUATERNION},
                ('position', 'orientation'))


def _array(items):
    return {'type': 'array', 'items': items}


SCHEMAS = {
    IMAGE_ANNOTATIONS: _object({
        'circles': _array(_object({
            'timestamp': _TIME, 'position': _POINT2, 'diameter': _NUMBER,
            'thickness': _NUMBER, 'fill_color': _COLOR, 'outline_color': _COLOR},
            ('timestamp', 'position', 'diameter', 'thickness', 'fill_color',
             'outline_color'))),
        'points': _array(_object({
            'timestamp': _TIME, 'type': _INTEGER, 'points': _array(_POINT2),
            'outline_color': _COLOR, 'outline_colors': _array(_COLOR),
            'fill_color': _COLOR, 'thickness': _NUMBER},
            ('timestamp', 'type', 'points', 'outline_color', 'thickness'))),
        'texts': _array(_object({
            'timestamp': _TIME, 'position': _POINT2, 'text': {'type': 'string'},
            'font_size': _NUMBER, 'text_color': _COLOR, 'background_color': _COLOR},
            ('timestamp', 'position', 'text', 'font_size'))),
    }, ('circles', 'points', 'texts')),
    SCENE_UPDATE: _object({
        'deletions': _array(_object({'timestamp': _TIME, 'type': _INTEGER,
                                     'id': {'type': 'string'}})),
        'entities': _array(_object({
            'timestamp': _TIME, 'frame_id': {'type': 'string'}, 'id': {'type': 'string'},
            'lifetime': _object({'sec': _INTEGER, 'nsec': _INTEGER}),
            'frame_locked': {'type': 'boolean'},
            'arrows': _array(_object({
                'pose': _POSE, 'shaft_length': _NUMBER, 'shaft_diameter': _NUMBER,
                'head_length': _NUMBER, 'head_diameter': _NUMBER, 'color': _COLOR})),
            'cubes': _array(_object({'pose': _POSE, 'size': _VECTOR3, 'color': _COLOR})),
            'spheres': _array(_object({'pose': _POSE, 'size': _VECTOR3, 'color': _COLOR})),
            'lines': _array(_object({
                'type': _INTEGER, 'pose': _POSE, 'thickness': _NUMBER,
                'scale_invariant': {'type': 'boolean'}, 'points': _array(_VECTOR3),
                'color': _COLOR, 'colors': _array(_COLOR), 'indices': _array(_INTEGER)})),
        }, ('timestamp', 'frame_id', 'id')))}, ('deletions', 'entities')),
}


def schema_bytes(name):
    """Return the JSON schema of Foxglove message `name` as UTF-8 bytes (for a channel)."""
    return json.dumps(SCHEMAS[name]).encode()


def time_dict(nanoseconds):
    """Return a time in nanoseconds as Foxglove's ``{"sec", "nsec"}``."""
    nanoseconds = int(nanoseconds)
    return {'sec': nanoseconds // 10**9, 'nsec': nanoseconds % 10**9}


def colour(rgba):
    """Return an (r, g, b, a) tuple as Foxglove's Color."""
    return dict(zip('rgba', (float(v) for v in rgba)))


def _point2(uv):
    return {'x': float(uv[0]), 'y': float(uv[1])}


def _vector3(xyz):
    return dict(zip('xyz', (float(v) for v in xyz)))


def pose_dict(position, quaternion=(0.0, 0.0, 0.0, 1.0)):
    """Return Foxglove's Pose of a position and an (x, y, z, w) quaternion."""
    return {'position': _vector3(position),
            'orientation': dict(zip('xyzw', (float(v) for v in quaternion)))}


# ---- image annotations ----------------------------------------------------------------------

def project_to_image(camera, T_world_camera, points_world):
    """
    Return the pixels (N, 2) of world points (N, 3) and the mask of those in front.

    `camera` is a ``helio_optics.geometry.PinholeCamera``, `T_world_camera` the 4x4 pose of
    its optical frame in the world.
    """
    points = np.atleast_2d(np.asarray(points_world, dtype=float))
    T_camera_world = np.linalg.inv(np.asarray(T_world_camera, dtype=float))
    in_camera = points @ T_camera_world[:3, :3].T + T_camera_world[:3, 3]
    front = in_camera[:, 2] > 1e-6
    pixels = np.full((len(points), 2), np.nan)
    if np.any(front):
        pixels[front] = camera.project(in_camera[front])
    return pixels, front


def ground_ellipse(center, semi_major, semi_minor, orientation, count=48):
    """Return `count` points (N, 3) on an ellipse in the plane z = center's z."""
    angle = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    c, s = np.cos(orientation), np.sin(orientation)
    a, b = semi_major * np.cos(angle), semi_minor * np.sin(angle)
    center = np.asarray(center, dtype=float)
    return np.stack([center[0] + c * a - s * b, center[1] + s * a + c * b,
                     np.full(count, center[2])], axis=-1)


def ground_circle(center, radius, count=48):
    """Return `count` points (N, 3) on a circle in the plane z = center's z."""
    return ground_ellipse(center, radius, radius, 0.0, count)


def _polygon(stamp, pixels, rgba, kind=LINE_LOOP, thickness=2.0):
    return {'timestamp': stamp, 'type': kind, 'points': [_point2(p) for p in pixels],
            'outline_color': colour(rgba), 'outline_colors': [],
            'fill_color': colour((0, 0, 0, 0)), 'thickness': float(thickness)}


def _circle(stamp, uv, diameter, rgba, fill=False, thickness=2.0):
    return {'timestamp': stamp, 'position': _point2(uv), 'diameter': float(diameter),
            'thickness': float(thickness),
            'fill_color': colour(rgba if fill else (0, 0, 0, 0)),
            'outline_color': colour(rgba)}


def _text(stamp, uv, text, rgba=(1, 1, 1, 1), size=14.0):
    return {'timestamp': stamp, 'position': _point2(uv), 'text': text,
            'font_size': float(size), 'text_color': colour(rgba),
            'background_color': colour((0, 0, 0, 0.5))}


def rgb_annotations(stamp_ns, camera, T_world_camera, marker_corners, spot=None,
                    current_target=None, next_targets=(), burnt=()):
    """
    Return the RGB image's ImageAnnotations (dict).

    `marker_corners` (4, 3) world; `spot` None or a dict with ``center`` (3,), ``semi_major``,
    ``semi_minor``, ``orientation`` (world frame, metres/radians); `current_target` None or
    (3,); `next_targets` and `burnt` sequences of world points. Shapes behind the camera
    are left out.
    """
    stamp = time_dict(stamp_ns)
    circles, points, texts = [], [], []
    pixels, front = project_to_image(camera, T_world_camera, marker_corners)
    if np.all(front):
        points.append(_polygon(stamp, pixels, MARKER_COLOUR))
    if spot is not None:
        outline = ground_ellipse(spot['center'], spot['semi_major'], spot['semi_minor'],
                                 spot['orientation'])
        pixels, front = project_to_image(camera, T_world_camera, outline)
        if np.all(front):
            points.append(_polygon(stamp, pixels, SPOT_COLOUR))
        centre, front = project_to_image(camera, T_world_camera, spot['center'])
        if front[0]:
            circles.append(_circle(stamp, centre[0], 6.0, SPOT_COLOUR, fill=True))
    for point in burnt:
        uv, front = project_to_image(camera, T_world_camera, point)
        if front[0]:
            circles.append(_circle(stamp, uv[0], 5.0, BURNT_COLOUR, fill=True))
    for point in next_targets:
        uv, front = project_to_image(camera, T_world_camera, point)
        if front[0]:
            circles.append(_circle(stamp, uv[0], 8.0, TARGET_COLOUR, thickness=1.0))
    if current_target is not None:
        uv, front = project_to_image(camera, T_world_camera, current_target)
        if front[0]:
            circles.append(_circle(stamp, uv[0], 14.0, TARGET_COLOUR, thickness=3.0))
            texts.append(_text(stamp, uv[0] + (10.0, -10.0), 'target'))
    return {'circles': circles, 'points': points, 'texts': texts}


def thermal_annotations(stamp_ns, hottest_uv, t_max, n_p, window=None):
    """
    Return the thermal image's ImageAnnotations (dict).

    `hottest_uv` the hottest pixel (column, row); `window` None or a tuple of the N_p
    window's outline pixels (N, 2) (ground circle projected into the thermal image) and its
    count, drawn with its N_p.
    """
    stamp = time_dict(stamp_ns)
    circles = [_circle(stamp, hottest_uv, 6.0, HOT_COLOUR, thickness=2.0)]
    points = []
    texts = [_text(stamp, (4.0, 4.0), f'T_max {t_max:.1f} C  N_p {n_p}', size=10.0)]
    if window is not None:
        outline, window_n_p = window
        points.append(_polygon(stamp, outline, WINDOW_COLOUR, thickness=1.0))
        texts.append(_text(stamp, np.min(outline, axis=0), f'window N_p {window_n_p}',
                           size=8.0))
    return {'circles': circles, 'points': points, 'texts': texts}


# ---- 3D scene -------------------------------------------------------------------------------

def _entity(stamp, name, **primitives):
    entity = {'timestamp': stamp, 'frame_id': 'world', 'id': name,
              'lifetime': {'sec': 0, 'nsec': 0}, 'frame_locked': False, 'metadata': [],
              'arrows': [], 'cubes': [], 'spheres': [], 'cylinders': [], 'lines': [],
              'triangles': [], 'texts': [], 'models': []}
    entity.update(primitives)
    return entity


def _line(points, rgba, kind=LINE_PRIMITIVE_STRIP, thickness=0.001):
    return {'type': kind, 'pose': pose_dict((0, 0, 0)), 'thickness': float(thickness),
            'scale_invariant': False, 'points': [_vector3(p) for p in points],
            'color': colour(rgba), 'colors': [], 'indices': []}


def _sphere(position, diameter, rgba):
    return {'pose': pose_dict(position), 'size': _vector3((diameter,) * 3),
            'color': colour(rgba)}


def _axes(transform, length):
    """Three lines (x red, y green, z blue) of a frame's axes."""
    origin = transform[:3, 3]
    return [_line([origin, origin + length * transform[:3, i]], rgba, thickness=0.002)
            for i, rgba in enumerate(((1, 0, 0, 1), (0, 1, 0, 1), (0, 0, 1, 1)))]


def ray_line(to_point, direction, length):
    """Return the two ends of a ray of `direction` ending at `to_point` (`length` long)."""
    direction = np.asarray(direction, dtype=float)
    direction = direction / np.linalg.norm(direction)
    end = np.asarray(to_point, dtype=float)
    return np.stack([end - length * direction, end])


def scene_update(stamp_ns, marker_corners, panel_extent, targets=(), target_states=(),
                 frames=None, sun_ray=None):
    """
    Return the 3D scene as a SceneUpdate (dict), world frame.

    `panel_extent` (x0, x1, y0, y1) of the wood [m]; `targets` (N, 3) with `target_states`
    ('planned', 'current' or 'burnt') colouring them; `frames` a dict name -> 4x4 world pose
    (``lens``, ``rgb``, ``thermal``) drawn as axes; `sun_ray` None or (2, 3) line ends
    (``ray_line``): the sun's ray as the controller estimates it.
    """
    stamp = time_dict(stamp_ns)
    x0, x1, y0, y1 = panel_extent
    panel = {'pose': pose_dict(((x0 + x1) / 2, (y0 + y1) / 2, -0.001)),
             'size': _vector3((x1 - x0, y1 - y0, 0.002)), 'color': colour(PANEL_COLOUR)}
    entities = [
        _entity(stamp, 'panel', cubes=[panel]),
        _entity(stamp, 'marker', lines=[_line(marker_corners, MARKER_COLOUR,
                                              LINE_PRIMITIVE_LOOP, 0.002)])]
    state_colour = {'planned': TARGET_COLOUR, 'current': HOT_COLOUR, 'burnt': BURNT_COLOUR}
    entities.append(_entity(stamp, 'targets', spheres=[
        _sphere(p, 0.003, state_colour[s]) for p, s in zip(targets, target_states)]))
    for name, transform in sorted((frames or {}).items()):
        entities.append(_entity(stamp, name, lines=_axes(np.asarray(transform), 0.02)))
    if sun_ray is not None:
        entities.append(ray_entity(stamp_ns, 'sun_estimate', sun_ray, SUN_ESTIMATE_COLOUR))
    return {'deletions': [], 'entities': entities}


def ray_entity(stamp_ns, name, ends, rgba):
    """Return a scene entity of one ray (``ray_line`` ends), e.g. the simulated true sun."""
    return _entity(time_dict(stamp_ns), name, lines=[_line(ends, rgba, thickness=0.002)])


def schema_errors(value, schema, path='$'):
    """
    Return where `value` breaks the JSON `schema` (the subset ``SCHEMAS`` uses), [] if nowhere.

    Types object/array/number/integer/string/boolean, ``properties``, ``required``, ``items``:
    enough to check a message against the schema its channel advertised, without a
    jsonschema dependency.
    """
    kind = schema.get('type')
    checks = {'object': dict, 'array': list, 'string': str, 'boolean': bool}
    if kind in ('number', 'integer'):
        wanted = int if kind == 'integer' else (int, float)
        if isinstance(value, bool) or not isinstance(value, wanted):
            return [f'{path}: {value!r} is not an {kind}']
        return []
    if kind in checks and not isinstance(value, checks[kind]):
        return [f'{path}: {type(value).__name__} is not an {kind}']
    errors = []
    if kind == 'object':
        errors += [f'{path}: {key} missing' for key in schema.get('required', ())
                   if key not in value]
        for key, sub in schema.get('properties', {}).items():
            if key in value:
                errors += schema_errors(value[key], sub, f'{path}.{key}')
    if kind == 'array' and 'items' in schema:
        for index, item in enumerate(value):
            errors += schema_errors(item, schema['items'], f'{path}[{index}]')
    return errors
