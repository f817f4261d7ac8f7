"""
Calibrations saved to, and read back from, one calibration directory (issue 30, item 4).

A calibration file is a ROS parameters file (``/**: ros__parameters: {...}``, so it can also
be passed with ``--params-file``) whose parameters hold the values, plus a
``calibration_record`` entry: when it was made, by what, and the rig description it was made
for (``rig_description``: a digest of the rig file's text). A calibration made for another rig
description (a changed link length, another camera mount) measured a different rig: it is
refused on load with the reason, never applied. ``list_calibrations`` says, for each file of
a directory, what it is and whether it would be used (``helio calibrations``).
"""

import datetime
import hashlib
import os

import yaml

RECORD = 'calibration_record'


class CalibrationRefused(ValueError):
    """A saved calibration that must not be used here; the message says why."""


def rig_description(rig_file):
    """Return the digest (16 hex digits) of the rig file a calibration is made for."""
    with open(rig_file, 'rb') as stream:
        return hashlib.sha256(stream.read()).hexdigest()[:16]


def save_calibration(directory, name, values, description, made_by, notes=None):
    """Write `values` (a parameter tree) as `directory`/`name`; return the path."""
    os.makedirs(directory, exist_ok=True)
    record = {'made_by': made_by, 'rig_description': description,
              'saved_at': datetime.datetime.now(datetime.timezone.utc).isoformat(
                  timespec='seconds')}
    record.update(notes or {})
    path = os.path.join(directory, name)
    with open(path, 'w') as stream:
        stream.write(f'# {name}: written by {made_by}; read back at start when made for '
                     'this rig description\n')
        yaml.safe_dump({'/**': {'ros__parameters': {**values, RECORD: record}}}, stream,
                       default_flow_style=False)
    return path


def load_calibration(directory, name, description):
    """
    Return (values, record) saved as `directory`/`name`, or None when there is no such file.

    Raises CalibrationRefused naming the file and the reason when it cannot be read or was
    made for another rig description.
    """
    path = os.path.join(directory, name)
    if not os.path.exists(path):
        return None
    try:
        with open(path) as stream:
            tree = yaml.safe_load(stream)
        values = dict(tree['/**']['ros__parameters'])
        record = values.pop(RECORD)
        made_for = record['rig_description']
    except (OSError, yaml.YAMLError, KeyError, TypeError) as error:
        raise CalibrationRefused(f'{path}: not a calibration file ({error!r})') from None
    if made_for != description:
        raise CalibrationRefused(
            f'{path} was made for rig description {made_for} (saved '
            f'{record.get("saved_at", "at an unknown time")}), this rig is {description}: the '
            'rig file changed since; calibrate again')
    return values, record


def list_calibrations(directory, description):
    """
    Return one dict per calibration file of `directory`: what each calibration is.

    First each ``*.yaml`` (sorted), then each camera_info file of its ``camera_info``
    folder (``helio calibrate camera``).

    Keys: ``name``, ``usable`` (it would be read back for the rig description
    `description`), ``reason`` (why not, '' when usable), and from its record ``made_by``,
    ``saved_at``, ``rig_description`` and the rest of the record (residuals, notes).
    """
    entries = []
    if not os.path.isdir(directory):
        return entries
    for name in sorted(os.listdir(directory)):
        if not name.endswith('.yaml'):
            continue
        entry = {'name': name, 'usable': True, 'reason': ''}
        try:
            loaded = load_calibration(directory, name, description)
            entry.update(loaded[1])
        except CalibrationRefused as refused:
            entry.update(usable=False, reason=str(refused))
            try:
                with open(os.path.join(directory, name)) as stream:
                    entry.update(yaml.safe_load(stream)['/**']['ros__parameters'][RECORD])
            except (OSError, yaml.YAMLError, KeyError, TypeError):
                pass
        entries.append(entry)
    return entries + _camera_infos(directory)


def _camera_infos(directory):
    """
    Return the entries of ``camera_info/*.yaml`` (``helio calibrate camera``'s files).

    A camera's intrinsics do not depend on the rig description, so they are listed, not
    judged by it: usable when the file is a camera_info file with a camera matrix; its first
    comment line (when and by what) as ``made_by``.
    """
    from helio_perception.camera_calibration import read_camera_info
    entries = []
    folder = os.path.join(directory, 'camera_info')
    if not os.path.isdir(folder):
        return entries
    for name in sorted(os.listdir(folder)):
        if not name.endswith('.yaml'):
            continue
        path = os.path.join(folder, name)
        entry = {'name': f'camera_info/{name}', 'usable': True, 'reason': ''}
        try:
            camera, camera_name = read_camera_info(path)
            entry.update(camera=camera_name, size=f'{camera.width}x{camera.height}',
                         fx_px=float(camera.matrix[0, 0]))
            with open(path) as stream:
                first = stream.readline()
            if first.startswith('#'):
                entry['made_by'] = first[1:].strip()
        except (OSError, ValueError) as error:
            entry.update(usable=False, reason=str(error))
        entries.append(entry)
    return entries
