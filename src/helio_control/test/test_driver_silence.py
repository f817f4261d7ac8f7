"""DriverSilence: a driver's silence counts only while the watcher runs; DeviceFaults."""

from helio_control.driver_silence import DeviceFaults, DriverSilence
import pytest


def ticking(watch, start, end, period=0.05):
    """Tick `watch` every `period` from `start` to `end` [s]."""
    t = start
    while t <= end + 1e-9:
        watch.tick(t)
        t += period


def test_a_driver_silent_past_the_limit_while_the_watcher_runs_is_reported_with_its_gap():
    watch = DriverSilence(silence=1.0)
    watch.heard('servo', 10.0)
    watch.heard('dobot', 10.0)
    ticking(watch, 10.0, 11.5)
    watch.heard('dobot', 11.4)
    assert watch.silent(10.95) == {}
    assert watch.silent(11.5) == {'servo': pytest.approx(1.5)}


def test_a_pause_of_the_watcher_is_not_the_drivers_silence():
    watch = DriverSilence(silence=1.0, pause=0.25)
    watch.heard('servo', 10.0)
    ticking(watch, 10.0, 10.2)
    # the watcher's process gets no CPU from 10.2 to 11.6: the joint states sent meanwhile
    # are still queued when it looks again
    assert watch.tick(11.6) == pytest.approx(1.4)
    assert watch.pauses == 1
    assert watch.silent(11.61) == {}               # the 1.41 s gap is the watcher's
    watch.heard('servo', 11.62)                    # the queued joint states are read
    assert watch.silent(11.7) == {}


def test_a_driver_still_silent_after_the_pause_is_reported_a_silence_after_it():
    watch = DriverSilence(silence=1.0, pause=0.25)
    watch.heard('servo', 10.0)
    ticking(watch, 10.0, 10.2)
    watch.tick(11.6)                               # back from a pause
    ticking(watch, 11.65, 12.7)
    assert watch.silent(12.55) == {}               # 0.95 s since the watcher came back
    assert watch.silent(12.65) == {'servo': pytest.approx(2.65)}


def test_ordinary_tick_lateness_is_not_a_pause_and_an_unheard_driver_is_not_reported():
    watch = DriverSilence(silence=1.0, pause=0.25)
    watch.heard('dobot', 0.0)
    assert watch.tick(0.0) == 0.0                  # the first tick has nothing to compare
    assert watch.tick(0.2) == 0.0                  # late, but within the pause
    assert watch.pauses == 0
    assert watch.silent(1.3) == {'dobot': pytest.approx(1.3)}     # no 'servo': never heard


@pytest.mark.parametrize('silence, pause', [(0.0, 0.25), (1.0, 0.0), (-1.0, 0.25)])
def test_limits_that_are_not_positive_are_refused(silence, pause):
    with pytest.raises(ValueError, match='must be > 0'):
        DriverSilence(silence, pause)


def test_each_joint_name_belongs_to_the_driver_that_publishes_it():
    from helio_control.driver_silence import device_of
    from helio_optics.rig_kinematics import JOINT_NAMES
    # the drivers' joint state messages (helio_drivers: dobot_driver, servo_driver)
    assert device_of(['dobot_j1', 'dobot_j2', 'dobot_j3', 'dobot_j4']) == 'dobot'
    assert device_of(['lens_yaw', 'lens_pitch']) == 'servo'
    assert {device_of([name]) for name in JOINT_NAMES} == {'dobot', 'servo'}
    assert device_of(['wheel_left']) == '' and device_of([]) == ''


def watching(faults, start, end, period=0.05):
    """Watch `faults` every `period` from `start` to `end` [s]."""
    for t in [start + k * period for k in range(int(round((end - start) / period)) + 1)]:
        faults.watch(t)


def test_device_faults_list_status_faults_then_silent_drivers_and_wake_once_per_new_fault():
    woken = []
    faults = DeviceFaults(silence=1.0, pause=0.25, wake=lambda: woken.append(True))
    faults.joint_states(['dobot_j1', 'dobot_j2'], 10.0)
    faults.joint_states(['lens_yaw', 'lens_pitch'], 10.0)
    faults.status('servo', True, '', [])                # a status without a fault
    assert woken == [] and faults.faults(10.0) == []
    faults.status('dobot', True, '', ['LIMIT', 'PLAN'])
    faults.status('dobot', True, '', ['LIMIT'])        # the same device again: no wake
    assert len(woken) == 1
    assert faults.faults(10.0) == [('dobot', 'dobot alarm: LIMIT')]
    watching(faults, 10.0, 10.9)
    faults.joint_states(['dobot_j1'], 10.9)
    watching(faults, 10.95, 11.5)
    assert len(woken) == 2                              # the servo driver fell silent
    assert faults.faults(11.5) == [('dobot', 'dobot alarm: LIMIT'), (
        'servo', 'servo silent for 1.5 s (no joint states: driver stopped?)')]
    assert faults.sentence(11.5, devices=('servo',)) == \
        'servo silent for 1.5 s (no joint states: driver stopped?)'
    faults.status('dobot', False, 'link reset', [])
    assert faults.faults(11.5, devices=('dobot',)) == [
        ('dobot', 'dobot not connected (link reset)')]
    faults.status('dobot', True, '', [])                # cleared
    assert faults.faults(11.5, devices=('dobot',)) == []
