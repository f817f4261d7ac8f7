"""The rig doctor's checks on hand-made facts: each fault found, with its fix."""

import datetime
import json
import os

from helio_control import doctor
from helio_control.calibration_store import list_calibrations, save_calibration
from helio_control.doctor import (
    CalibrationFacts, ClockFacts, DeviceFacts, Facts, FAIL, OK, SpotFacts, StreamFacts,
    ThermalFacts, WARN)
import pytest

UTC = datetime.timezone.utc
CALIBRATED_K = [457.0, 0.0, 319.5, 0.0, 457.0, 239.5, 0.0, 0.0, 1.0]
SITE = """/**:
  ros__parameters:
    site:
      latitude_deg: {latitude}
      longitude_deg: {longitude}
      elevation: 500.0
"""


def write_site(path, latitude, longitude):
    path.write_text(SITE.format(latitude=latitude, longitude=longitude))
    return str(path)


def stream(topic, rate, seconds=3.0, again=0):
    """Return StreamFacts of a camera at `rate` Hz for `seconds`, `again` frames sent twice."""
    stamps = [100.0 + i / rate for i in range(int(rate * seconds))]
    stamps += stamps[:again]
    return StreamFacts(topic, sorted(stamps), [s - 90.0 for s in sorted(stamps)])


def healthy_facts(tmp_path):
    """Return the facts of a healthy rig (calibrations made for its rig description)."""
    calibrations = tmp_path / 'calibration'
    for name in doctor.EXPECTED_CALIBRATIONS:
        save_calibration(str(calibrations), name, {'value': 1.0}, 'abc', 'test')
    sample = write_site(tmp_path / 'sample_site.yaml', 48.137, 11.575)
    mine = write_site(tmp_path / 'my_site.yaml', 47.3769, 8.5417)
    now = datetime.datetime(2026, 11, 27, 12, 0, tzinfo=UTC)
    return Facts(
        window=3.0,
        devices={'dobot': DeviceFacts(True, [], 'connected to /dev/ttyUSB0', '/dev/ttyUSB0'),
                 'servo': DeviceFacts(True, [], 'connected', '/dev/ttyACM0')},
        home_on_connect=True,
        images={'rgb': stream('/rgb/image_raw', 5.0),
                'thermal': stream('/thermal/image_raw', 8.7)},
        joint_states=StreamFacts('/joint_states', [100.0 + i / 20.0 for i in range(60)]),
        camera_infos={'rgb': [CALIBRATED_K] * 5, 'thermal': [CALIBRATED_K] * 8},
        thermal=[ThermalFacts(28.0, 180.9, 180.9)] * 5,
        spots=[SpotFacts('marker', 'no spot found')] * 5,
        site_files={'sun_estimator.site_file': mine, 'lens_planner.site_file': mine},
        sample_site=sample,
        clock=ClockFacts(samples=[(0.0, 10.0), (3.0, 13.0)], now=now, utc_offset=3600.0,
                         not_before=now - datetime.timedelta(days=3), ntp_synchronized=True),
        calibration=CalibrationFacts(str(calibrations), 'lens_planner.calibration_dir', 'abc',
                                     'rig.yaml', list_calibrations(str(calibrations), 'abc')),
        emergency_stop=False)


def finding(findings, name):
    """Return the one finding called `name`."""
    found = [f for f in findings if f.name == name]
    assert len(found) == 1, [f.name for f in findings]
    return found[0]


def test_a_healthy_rig_passes_every_check(tmp_path):
    findings = doctor.run_checks(healthy_facts(tmp_path))
    assert [f for f in findings if f.level != OK] == []
    assert doctor.passed(findings)
    names = {f.name for f in findings}
    for expected in ('dobot connected', 'servo connected', 'dobot alarms', 'dobot homed',
                     'rgb camera rate', 'thermal camera rate', 'rgb camera_info calibrated',
                     'thermal camera_info calibrated', 'thermal range for charring',
                     'marker visible', 'site file', 'simulated clock', 'system clock',
                     'time zone', 'calibration robot_world.yaml', 'calibration focus.yaml',
                     'emergency stop', 'time base'):
        assert expected in names


def test_an_uncalibrated_camera_info_fails_with_the_camera_calibration_fix(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.camera_infos['rgb'] = facts.camera_infos['rgb'] + [[0.0] * 9]
    facts.camera_infos['thermal'] = facts.camera_infos['thermal'] + [[0.0] * 9]
    checks = doctor.run_checks(facts)
    result = finding(checks, 'rgb camera_info calibrated')
    assert result.level == FAIL and '1 of 6' in result.finding and 'all zero' in result.finding
    assert 'helio calibrate camera' in result.fix     # the rig calibrates its RGB camera
    thermal = finding(checks, 'thermal camera_info calibrated')
    assert thermal.level == FAIL and 'camera_calibration' in thermal.fix   # a board is cold


@pytest.mark.parametrize('k, problem', [
    ([0.0] * 9, 'all zero'), ([457.0, 0, 320, 0, -1.0, 240, 0, 0, 1], 'not an intrinsic'),
    ([1.0] * 8, 'not 9'), ([float('nan')] + [1.0] * 8, 'not finite')])
def test_intrinsics_problems_are_named(k, problem):
    assert problem in doctor.intrinsics_problem(k)
    assert doctor.intrinsics_problem(CALIBRATED_K) == ''


def test_no_camera_info_fails(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.camera_infos['thermal'] = []
    result = finding(doctor.run_checks(facts), 'thermal camera_info calibrated')
    assert result.level == FAIL and 'no thermal/camera_info' in result.finding


def test_no_thermal_stream_fails_the_rate_and_the_range_with_their_fixes(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.images['thermal'] = StreamFacts('/thermal/image_raw')
    facts.thermal = []
    findings = doctor.run_checks(facts)
    rate = finding(findings, 'thermal camera rate')
    assert rate.level == FAIL and 'no image on /thermal/image_raw' in rate.finding
    assert 'plugged in' in rate.fix and '--thermal-camera' in rate.fix
    assert finding(findings, 'thermal range for charring').level == FAIL
    assert not doctor.passed(findings)


def test_a_slow_camera_fails_and_frames_sent_again_count_once(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.images['rgb'] = stream('/rgb/image_raw', 3.0, again=4)      # 3 Hz of 5 expected
    result = finding(doctor.run_checks(facts), 'rgb camera rate')
    assert result.level == FAIL and '3.00 Hz by their stamps' in result.finding
    assert '(4 sent again)' in result.finding and '--rgb-rate' in result.fix
    facts.images['rgb'] = stream('/rgb/image_raw', 5.0, again=7)
    assert finding(doctor.run_checks(facts), 'rgb camera rate').level == OK
    settings = doctor.Settings(rgb_rate=30.0)       # a webcam expected at 30 Hz
    assert finding(doctor.run_checks(facts, settings), 'rgb camera rate').level == FAIL


def test_a_thermal_read_out_below_the_pyrolysis_threshold_fails(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.thermal = [ThermalFacts(25.0, 180.9, 140.0)]      # a monitor counting above the cap
    result = finding(doctor.run_checks(facts), 'thermal range for charring')
    assert result.level == FAIL and 'stops at 140 degC' in result.finding
    assert 'low gain' in result.fix and 'camera_cap' in result.fix


def test_a_camera_counted_at_its_cap_below_the_papers_t_p_is_a_warning(tmp_path):
    # issue 29: the monitor counts a high-gain Lepton's saturated pixels (threshold = cap)
    facts = healthy_facts(tmp_path)
    facts.thermal = [ThermalFacts(25.0, 140.0, 140.0)]
    result = finding(doctor.run_checks(facts), 'thermal range for charring')
    assert result.level == WARN and 'saturated pixels' in result.finding
    assert 'lepton35_low_gain' in result.fix
    facts.thermal = [ThermalFacts(25.0, 180.9, 400.0)]      # a Lepton in low gain
    assert finding(doctor.run_checks(facts), 'thermal range for charring').level == OK


def test_thermal_readings_that_are_no_scene_fail(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.thermal = [ThermalFacts(-273.15, 180.9, 180.9)]     # counts read as kelvin * 0
    result = finding(doctor.run_checks(facts), 'thermal range for charring')
    assert result.level == FAIL and 'mono16.gain' in result.fix


def test_a_marker_out_of_view_warns_with_the_fix(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.spots = [SpotFacts('kinematics', 'marker 0 not found')] * 4 + \
        [SpotFacts('', 'marker 0 not found')]
    result = finding(doctor.run_checks(facts), 'marker visible')
    assert result.level == WARN and 'none of 5' in result.finding
    assert 'marker 0 not found' in result.finding and 'looks at the marker' in result.fix
    facts.spots = []
    assert finding(doctor.run_checks(facts), 'marker visible').level == FAIL


def test_the_sample_site_fails_by_path_or_by_its_coordinates(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.site_files['sun_estimator.site_file'] = facts.sample_site
    result = finding(doctor.run_checks(facts), 'site file')
    assert result.level == FAIL and 'sun_estimator.site_file' in result.finding
    assert 'lens_planner' not in result.finding
    assert 'site_file=PATH' in result.fix
    copy = write_site(tmp_path / 'copy.yaml', 48.137, 11.575)     # a copy left unchanged
    assert finding(doctor.run_checks(Facts(site_files={'--site': copy},
                                           sample_site=facts.sample_site)),
                   'site file').level == FAIL


def test_a_site_file_that_cannot_be_read_fails(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.site_files = {'--site': str(tmp_path / 'missing.yaml')}
    result = finding(doctor.run_checks(facts), 'site file')
    assert result.level == FAIL and 'cannot be read' in result.finding


def test_a_dobot_alarm_fails_with_clear_alarms_in_the_fix(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.devices['dobot'].alarms = ['joint limit: j2 beyond its upper limit']
    result = finding(doctor.run_checks(facts), 'dobot alarms')
    assert result.level == FAIL and 'j2 beyond its upper limit' in result.finding
    assert '/dobot/clear_alarms' in result.fix


def test_devices_not_heard_or_not_connected_fail(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.devices['servo'] = DeviceFacts(False, [], 'no reply; retrying in 1.6 s', '/dev/x')
    del facts.devices['dobot']
    findings = doctor.run_checks(facts)
    servo = finding(findings, 'servo connected')
    assert servo.level == FAIL and 'retrying' in servo.finding and 'helio udev' in servo.fix
    dobot = finding(findings, 'dobot connected')
    assert dobot.level == FAIL and 'no /dobot/status' in dobot.finding


def test_homing_that_cannot_be_observed_warns_with_the_home_service(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.home_on_connect = False
    result = finding(doctor.run_checks(facts), 'dobot homed')
    assert result.level == WARN and 'not observable' in result.finding
    assert '/dobot/home' in result.fix
    facts.devices['dobot'].message = 'homed: joints 0, 0, 0, 0'
    assert finding(doctor.run_checks(facts), 'dobot homed').level == OK


def test_no_calibration_warns_with_how_to_make_each(tmp_path):
    facts = healthy_facts(tmp_path)
    empty = tmp_path / 'empty'
    empty.mkdir()
    facts.calibration = CalibrationFacts(str(empty), '--calibration-dir', 'abc', 'rig.yaml', [])
    findings = doctor.run_checks(facts)
    world = finding(findings, 'calibration robot_world.yaml')
    focus = finding(findings, 'calibration focus.yaml')
    assert world.level == WARN and focus.level == WARN
    assert 'none in' in world.finding and 'calibrate_world' in world.fix
    assert 'calibrate_focus' in focus.fix


def test_a_calibration_made_for_another_rig_fails(tmp_path):
    facts = healthy_facts(tmp_path)
    directory = facts.calibration.directory
    save_calibration(directory, 'focus.yaml', {'value': 1.0}, 'another', 'test')
    facts.calibration.entries = list_calibrations(directory, 'abc')
    result = finding(doctor.run_checks(facts), 'calibration focus.yaml')
    assert result.level == FAIL and 'another' in result.finding
    assert 'calibrate_focus' in result.fix


def test_a_clock_before_the_build_fails_and_a_stalled_sim_clock_fails(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.clock.now = facts.clock.not_before - datetime.timedelta(days=400)
    facts.clock.samples = [(0.0, 10.0), (3.0, 10.0)]
    findings = doctor.run_checks(facts)
    assert finding(findings, 'system clock').level == FAIL
    assert 'set-ntp' in finding(findings, 'system clock').fix
    assert finding(findings, 'simulated clock').level == FAIL


def test_a_time_zone_far_from_the_site_warns(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.clock.utc_offset = -8 * 3600.0           # Pacific time for a rig in Zurich
    result = finding(doctor.run_checks(facts), 'time zone')
    assert result.level == WARN and 'set-timezone' in result.fix
    facts.clock.ntp_synchronized = False
    assert finding(doctor.run_checks(facts), 'system clock').level == WARN


def test_a_real_rig_has_no_simulated_clock_line(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.clock.samples = []
    assert 'simulated clock' not in {f.name for f in doctor.run_checks(facts)}


def test_images_on_another_clock_than_the_joint_states_fail(tmp_path):
    # the simulated world's cameras (June, simulated time) with the rig's nodes on wall time
    facts = healthy_facts(tmp_path)
    facts.joint_states.stamps = [s + 13.75e6 for s in facts.joint_states.stamps]
    result = finding(doctor.run_checks(facts), 'time base')
    assert result.level == FAIL and 'another clock' in result.finding
    assert 'use_sim_time' in result.fix
    facts.joint_states = None
    assert finding(doctor.run_checks(facts), 'time base').level == WARN


def test_the_engaged_emergency_stop_fails_with_helio_reset(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.emergency_stop = True
    result = finding(doctor.run_checks(facts), 'emergency stop')
    assert result.level == FAIL and result.fix.endswith('helio reset')


def test_nothing_heard_fails_without_an_exception():
    findings = doctor.run_checks(Facts(window=2.0))
    assert not doctor.passed(findings)
    for result in findings:
        assert result.level in doctor.LEVELS and result.finding
        assert result.level == OK or result.fix, result


def test_the_checklist_text_and_json(tmp_path):
    facts = healthy_facts(tmp_path)
    facts.devices['dobot'].alarms = ['lost step']
    findings = doctor.run_checks(facts)
    text = doctor.checklist_text(findings, facts)
    assert 'FAIL dobot alarms: 1 active: lost step\n       fix: remove the cause' in text
    assert text.splitlines()[-1].endswith(f'{len(findings) - 1} OK, 0 WARN, 1 FAIL')
    path = tmp_path / 'doctor.json'
    path.write_text(json.dumps(doctor.findings_json(findings)))
    data = json.loads(path.read_text())
    assert data['passed'] is False
    assert {'name', 'level', 'finding', 'fix'} == set(data['findings'][0])
    assert os.path.exists(path)
