"""The waits on the painter's streams (stream_waits), and the endings of a paint goal."""

from types import SimpleNamespace

from helio_control.procedures.painter_port import as_message, GoalStops, PaintFeedback
from helio_control.stream_waits import CameraModel, ThermalWaits, Waits
from helio_msgs.action import PaintPattern
import pytest


def test_a_wait_takes_only_what_is_offered_while_it_waits_and_from_its_time_on():
    frames, early, late = Waits(), [], []
    assert not frames
    frames.offer('before any wait', 1.0)
    with frames.waiting(early.append), frames.waiting(late.append, since=2.0):
        assert frames
        frames.offer('frame at 1.5', 1.5)
        frames.offer('frame at 2.0', 2.0)
    frames.offer('after the waits', 3.0)
    assert not frames
    assert early == ['frame at 1.5', 'frame at 2.0'] and late == ['frame at 2.0']


def test_a_wait_ended_by_an_error_is_removed():
    stats = ThermalWaits()
    with pytest.raises(RuntimeError):
        with stats.waiting(lambda message: None):
            raise RuntimeError('the wait failed')
    assert not stats


def test_thermal_waits_keep_the_last_live_stamp_and_wake_every_wait_with_none():
    stats, got = ThermalWaits(), []
    with stats.waiting(got.append):
        live, frozen = SimpleNamespace(frozen=False), SimpleNamespace(frozen=True)
        stats.take(live, 10.0)
        stats.take(frozen, 10.1)          # a flat-field correction's repeat: no fresh reading
        stats.wake()
    assert stats.live_stamp == 10.0 and got == [live, frozen, None]


def test_the_camera_model_is_built_again_only_when_its_calibration_changes():
    built = []

    def build(info):
        built.append(info)
        if info.k[0] == 0.0:
            raise ValueError('K = 0: uncalibrated')
        return f'camera fx {info.k[0]}'
    camera = CameraModel(build)

    def info(fx, width=640):
        return SimpleNamespace(k=[fx, 0, 320, 0, fx, 240, 0, 0, 1], d=[], width=width,
                               height=480)
    camera.take(info(600.0))
    camera.take(info(600.0))
    assert camera.model == 'camera fx 600.0' and len(built) == 1
    camera.take(info(0.0))
    assert camera.model is None
    camera.take(info(610.0, width=320))
    assert camera.model == 'camera fx 610.0' and len(built) == 3


def test_goal_stops_wake_the_heating_and_a_stop_counts_only_while_a_goal_runs():
    woken = []
    stops = GoalStops(lambda: woken.append(True))
    stops.stop('a stop signal')                          # no goal runs: nothing to stop
    assert (stops.requested, stops.signal, woken) == (False, '', [])
    handle = SimpleNamespace(is_cancel_requested=False)
    stops.begin(handle)
    stops.stop('the EMERGENCY STOP')
    assert (stops.requested, stops.signal, len(woken)) == (True, 'the EMERGENCY STOP', 1)
    assert not stops.client_canceled()
    stops.begin(handle)                                  # the next goal starts afresh
    assert (stops.requested, stops.signal) == (False, '')
    handle.is_cancel_requested = True
    stops.cancel()
    assert stops.requested and stops.client_canceled() and len(woken) == 2


def test_feedback_becomes_the_actions_message_field_for_field():
    feedback = PaintFeedback(index=3, total=9, phase='heating', t_max=181.5, n_p=12,
                             elapsed=40.0, eta=120.0)
    message = as_message(feedback, PaintPattern.Feedback)
    assert (message.index, message.total, message.phase, message.t_max, message.n_p,
            message.elapsed, message.eta) == (3, 9, 'heating', 181.5, 12, 40.0, 120.0)
