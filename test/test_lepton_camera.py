"""
A FLIR Lepton 3.5 in high gain as the thermal camera, in the whole graph (issue 29).

The world's thermal camera is the datasheet's (``sim_world thermal_profile
lepton35_high_gain``: 57 deg, reads up to 140 degC, a radiometric error drawn within its
accuracy, mono16 as ``usb_cam`` publishes Y16) and ``thermal_monitor`` knows it by the same
name (``camera_profile``: only its cap, 140 degC, from the datasheet). Its flat-field
corrections come every 3 s of simulated time here (every 3 minutes on the camera), each
freezing the output 0.3-1 s. Judged by the world's truth (``sim/canvas``, ``sim/truth/light``):

- dots paint and char on target, N_p counted at the cap (140 degC, below the paper's T_p of
  180.9: the saturated pixels), and the freezes, seen by the monitor as frozen frames while
  the dots heat, never retreat the lens nor fail a dot (before: a high-gain Lepton never
  showed N_p above 0, and every dot was held to ``max_heating`` and failed);
- a camera that hangs mid-dot, repeating its last frame for good (``thermal_stuck``), is a
  stale stream once its frames have been frozen for ``thermal_freeze_max`` (1.5 s): from
  then, the focus off the wood within the watchdog's 0.5 s, as for a stream that stops, and
  the dot heated again once the camera is back;
- last, the Dobot driver killed (SIGKILL) mid-dot (issue 30): the painter hears its joint
  states stop and the wrist turns the lens away, the focus off the wood within 0.5 s.
"""

from conftest import graph_of_processes
from helio_control.run_journal import read_journal
from helio_msgs.action import PaintPattern
from helio_optics.node_kit.conversions import stamp_to_seconds
import pytest
from test_painter_safety import (dots_along, killed_driver_mid_dot, nearest, NODES, OFF_BOUND,
                                 painting_interrupted, Rig, TIMEOUT)

CAMERA = 'lepton35_high_gain'
CAP = 140.0                   # its datasheet's high-gain read-out cap [degC]
FFC_PERIOD = 3.0              # a flat-field correction every this, here [s sim]
FREEZE_MAX = 1.5              # the painter's default thermal_freeze_max [s]
N_P_TARGET = 20               # the dots' (the word's in test_painter.py): a shorter dwell


@pytest.fixture(scope='module')
def rig(tmp_path_factory):
    """Run the whole graph with a high-gain Lepton for the module."""
    tmp_path = tmp_path_factory.mktemp('lepton')
    overrides = {'sim_world': {'real_time_factor': 0.0, 'flux_rays': 20000,
                               'canvas_rate': 1.0, 'truth_period': 0.05, 'pace_max_lag': 0.0,
                               'thermal_profile': CAMERA, 'thermal_ffc_period': FFC_PERIOD},
                 'thermal_monitor': {'camera_profile': CAMERA},
                 'lens_planner': {'calibration_dir': str(tmp_path / 'calibration')},
                 'painter': {'runs_dir': str(tmp_path / 'runs')}}
    # the module's last test kills the Dobot driver
    with graph_of_processes(tmp_path, NODES, overrides, may_die=('dobot_driver',)) \
            as (group, graph):
        yield Rig(group, graph, tmp_path / 'runs')


@pytest.fixture(autouse=True)
def tidy(rig):
    """Leave no painting running and the camera live."""
    yield
    rig.set_world(thermal_stuck=False)
    rig.tidy()


def test_dots_char_on_target_through_the_flat_field_freezes_without_a_retreat(rig):
    targets = dots_along(0.08, 1)
    goal = PaintPattern.Goal(points=targets, fresh=True, run_dir=str(rig.runs / 'ffc'),
                             n_p_target=N_P_TARGET)
    handle = rig.graph.send_goal(rig.client, goal, None, 60.0)
    assert handle.accepted
    rig.handles.append(handle)
    result = rig.graph.goal_result(handle, TIMEOUT).result
    print(f'\nffc: {result.message}')
    assert result.success, result.message
    dots = read_journal(str(rig.runs / 'ffc' / 'journal.jsonl')).dots
    assert [d.outcome for d in dots] == ['burnt']
    assert [d.restarts for d in dots] == [0], 'a freeze retreated the lens'
    heating = [(d.start, d.end) for d in dots]
    during = [m for m in rig.stats.messages
              if any(a <= stamp_to_seconds(m.header.stamp) <= b for a, b in heating)]
    frozen = [m for m in during if m.frozen]
    print(f'ffc: {len(frozen)} frozen of {len(during)} thermal frames while the dots were '
          f'painted; dwell {[round(d.dwell, 1) for d in dots]} s')
    assert frozen, 'no flat-field freeze while the dots heated'
    assert all(m.threshold == CAP and m.camera_cap == CAP for m in during)
    assert max(m.n_p for m in during) >= dots[0].n_p_target
    charred = [nearest(rig.charred_dots(), t) for t in targets]
    assert all(dot is not None for dot in charred), 'a dot is not charred'
    print(f'ffc: diameters {[round(d.diameter * 1e3, 2) for d in charred]} mm')


def test_a_camera_stuck_mid_dot_puts_the_focus_off_once_its_freeze_is_too_long(rig):
    def stick(_handle):
        heard = len(rig.stats.messages)
        rig.set_world(thermal_stuck=True)
        rig.stats.wait_until(lambda m: any(s.frozen for s in m[heard:]), 60.0,
                             'a frozen thermal frame')
        first = next(i for i, s in enumerate(rig.stats.messages) if i >= heard and s.frozen)
        live = [s for s in rig.stats.messages[:first] if not s.frozen]
        # frozen since the frame after the last live one: stale once that is FREEZE_MAX old
        return stamp_to_seconds(live[-1].header.stamp) + FREEZE_MAX

    def unstick():
        count = len(rig.stats.messages)
        rig.set_world(thermal_stuck=False)
        rig.stats.wait_for_count(count + 1, 60.0)

    delay, handle = painting_interrupted(rig, 'stuck', 0.10, stick, restore=unstick)
    assert delay <= OFF_BOUND, rig.logs()
    result = rig.graph.goal_result(handle, TIMEOUT).result    # live again: heated again
    print(f'stuck: {result.message}')
    assert result.success and 'stale thermal stream' in result.message, result.message


def test_a_killed_dobot_driver_leaves_the_retreat_to_the_wrist(rig):
    # the module's last test: the Dobot driver is not started again
    delay, result = killed_driver_mid_dot(rig, 'dobot_driver', 0.09)
    assert 'the wrist turned the lens away' in result.message
    assert delay <= OFF_BOUND, rig.logs()
