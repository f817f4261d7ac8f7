"""Calibration files: round trip, the rig description they were made for, bad files."""

import math
import os

from helio_control.calibration_store import (
    CalibrationRefused, list_calibrations, load_calibration, rig_description, save_calibration)
from helio_control.cli import main
from helio_optics.geometry import PinholeCamera
from helio_perception.camera_calibration import write_camera_info
import pytest
import yaml


def test_a_calibration_reads_back_for_its_rig_and_is_refused_for_another(tmp_path):
    rig = tmp_path / 'rig.yaml'
    rig.write_text('rig:\n  link_2: 0.135\n')
    made_for = rig_description(str(rig))
    values = {'rig': {'world_in_robot': [0.145, -0.1, -0.14], 'world_yaw': 0.01}}
    path = save_calibration(str(tmp_path / 'cal'), 'robot_world.yaml', values, made_for,
                            'lens_planner', {'residual_position_m': 2e-5})
    # a ROS parameters file: the values under /**, the record beside them
    with open(path) as stream:
        tree = yaml.safe_load(stream)['/**']['ros__parameters']
    assert tree['rig'] == values['rig']
    assert tree['calibration_record']['rig_description'] == made_for
    back, record = load_calibration(str(tmp_path / 'cal'), 'robot_world.yaml', made_for)
    assert back == values and record['made_by'] == 'lens_planner'
    assert record['residual_position_m'] == 2e-5 and record['saved_at'].endswith('+00:00')
    # one character more in the rig file: another rig description, refused with the reason
    rig.write_text('rig:\n  link_2: 0.1351\n')
    with pytest.raises(CalibrationRefused, match='was made for rig description .*calibrate'):
        load_calibration(str(tmp_path / 'cal'), 'robot_world.yaml', rig_description(str(rig)))
    assert load_calibration(str(tmp_path / 'cal'), 'focus.yaml', made_for) is None


@pytest.mark.parametrize('text', ['', 'just text', '/**:\n  ros__parameters:\n    a: 1\n'])
def test_a_file_that_is_not_a_calibration_is_refused_by_name(tmp_path, text):
    (tmp_path / 'focus.yaml').write_text(text)
    with pytest.raises(CalibrationRefused, match='focus.yaml: not a calibration file'):
        load_calibration(str(tmp_path), 'focus.yaml', '0123456789abcdef')


def test_helio_calibrations_lists_each_file_and_says_which_this_rig_refuses(tmp_path, capsys):
    rig = tmp_path / 'rig.yaml'
    rig.write_text('rig:\n  link_2: 0.135\n')
    directory = str(tmp_path / 'cal')
    save_calibration(directory, 'robot_world.yaml', {'rig': {'world_yaw': 0.01}},
                     rig_description(str(rig)), 'lens_planner', {'residual_position_m': 2e-5})
    other = tmp_path / 'other_rig.yaml'
    other.write_text('rig:\n  link_2: 0.136\n')
    save_calibration(directory, 'focus.yaml', {'heating_distance': 0.083},
                     rig_description(str(other)), 'lens_planner')
    (tmp_path / 'cal' / 'notes.txt').write_text('not a calibration')
    entries = list_calibrations(directory, rig_description(str(rig)))
    assert [(e['name'], e['usable']) for e in entries] == [
        ('focus.yaml', False), ('robot_world.yaml', True)]
    assert 'was made for rig description' in entries[0]['reason']
    assert entries[1]['residual_position_m'] == 2e-5
    # the command: one line each, exit 1 because one is refused
    assert main(['calibrations', '--dir', directory, '--rig', str(rig)]) == 1
    out = capsys.readouterr().out
    assert 'robot_world.yaml: saved ' in out and 'residual_position_m 2e-05; used' in out
    assert 'focus.yaml' in out and 'REFUSED' in out
    # a camera calibration (helio calibrate camera): listed whatever the rig description
    camera = PinholeCamera.from_fov(640, 480, math.radians(60.0))
    os.makedirs(tmp_path / 'cal' / 'camera_info')
    write_camera_info(str(tmp_path / 'cal' / 'camera_info' / 'rgb.yaml'), camera, 'rgb',
                      ['written by helio calibrate camera at 2026-11-28T04:00:00+00:00'])
    (tmp_path / 'cal' / 'camera_info' / 'thermal.yaml').write_text('image_width: 160\n')
    entries = list_calibrations(directory, rig_description(str(other)))
    cameras = {e['name']: e for e in entries if e['name'].startswith('camera_info/')}
    assert cameras['camera_info/rgb.yaml']['usable']
    assert cameras['camera_info/rgb.yaml']['fx_px'] == pytest.approx(camera.matrix[0, 0])
    assert 'helio calibrate camera' in cameras['camera_info/rgb.yaml']['made_by']
    assert not cameras['camera_info/thermal.yaml']['usable']
    assert 'not a camera_info file' in cameras['camera_info/thermal.yaml']['reason']
    assert main(['calibrations', '--dir', str(tmp_path / 'none'), '--rig', str(rig)]) == 0
    assert 'no calibration saved' in capsys.readouterr().out
