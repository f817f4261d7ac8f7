"""
A painting run (one ``paint`` goal) against a modelled rig: every dot once, cancel, resume.

The rig is ``painter_rig_model.RigModel`` (wood heating as a first-order system under the
focus, a thermal camera, the sun, the clock); the run plans real dots with the rig model and
writes its plan and journal in a temporary runs directory. The truths are the model's (which
dots the focus rested on, and when) and the journal as read back.
"""

from geometry_msgs.msg import Point
from helio_control.plan import Plan
from helio_control.procedures.painting_run import PaintingRun
from helio_control.run_journal import read_journal
from helio_msgs.action import PaintPattern
from painter_rig_model import MOVE, RigModel, run, settings
import pytest

ROW = [(0.05 + 0.008 * i, 0.07) for i in range(4)]    # world [m], 8 mm apart


def goal_of(points, run_dir, **fields):
    """Return a PaintPattern goal of world `points` written in `run_dir`."""
    return PaintPattern.Goal(points=[Point(x=x, y=y, z=0.0) for x, y in points],
                             run_dir=str(run_dir), **fields)


def paint(tmp_path, goal, **model_fields):
    """Run `goal` on a fresh RigModel (its fields set); return (result, ending, model)."""
    model = RigModel(settings(tmp_path))
    for name, value in model_fields.items():
        setattr(model, name, value)
    result, ending = run(PaintingRun(model, model.settings).execute(goal))
    return result, ending, model


def burnt_in(run_dir):
    """Return the indices the run's journal says were burnt."""
    return [dot.index for dot in read_journal(str(run_dir / 'journal.jsonl')).dots
            if dot.outcome == 'burnt']


def test_a_run_burns_every_planned_dot_once_and_journals_each(tmp_path):
    result, ending, model = paint(tmp_path, goal_of(ROW, tmp_path / 'runs' / 'row'))
    assert ending == 'succeed' and result.success, result.message
    assert result.message.startswith('4 dots burnt in ')
    assert (result.dots_planned, result.dots_burnt, result.dots_resumed) == (4, 4, 0)
    assert [len(model.heated(target)) for target in ROW] == [1, 1, 1, 1]
    assert [model.true_n_p(target) for target in ROW] == [0, 0, 0, 0]   # the paper's rule
    journal = read_journal(str(tmp_path / 'runs' / 'row' / 'journal.jsonl'))
    assert [dot.index for dot in journal.dots] == [0, 1, 2, 3]
    assert journal.result.success and journal.result.dots_burnt == 4
    assert journal.result.duration == pytest.approx(result.duration)
    assert model.windows[-1] is None                       # no N_p window left behind


def test_a_cancel_while_heating_retreats_the_lens_and_ends_the_goal_canceled(tmp_path):
    run_dir = tmp_path / 'runs' / 'canceled'
    result, ending, model = paint(tmp_path, goal_of(ROW, run_dir), cancel_at=3.0)
    assert ending == 'canceled' and not result.success
    assert result.message == 'canceled: retreated (cancel)'
    [(since, until)] = model.heated(ROW[0])
    assert until == pytest.approx(3.0)                     # woken at the cancel
    at, where, d_lp, _, urgent = model.moves[-1]
    assert urgent and where == pytest.approx(ROW[0]) and d_lp == pytest.approx(
        model.heating_distance + model.retreat_offset)
    assert model.t == pytest.approx(3.0 + MOVE)
    journal = read_journal(str(run_dir / 'journal.jsonl'))
    assert journal.dots == [] and journal.result.message == result.message


def test_the_window_rule_goes_on_at_once_and_retreats_after_the_last_dot(tmp_path):
    result, ending, model = paint(tmp_path, goal_of(ROW, tmp_path / 'runs' / 'window',
                                                    cooling='window'))
    assert ending == 'succeed' and result.dots_burnt == 4, result.message
    heat, travel = model.heating_distance, model.settings.window_travel_offset
    # one focus goal per dot, travelling beyond the heating distance; no retreat between
    # the dots, one after the last
    assert [move[1:] for move in model.moves] == [
        (pytest.approx(target), heat, pytest.approx(heat + travel), False) for target in ROW
    ] + [(pytest.approx(ROW[-1]), pytest.approx(heat + model.retreat_offset), 0.0, True)]
    heatings = [model.heated(target) for target in ROW]
    assert [len(intervals) for intervals in heatings] == [1, 1, 1, 1]
    for (_, until), [(since, _)] in zip([h[0] for h in heatings], heatings[1:]):
        assert since == pytest.approx(until + MOVE)      # no wait for N_p = 0


def test_the_window_rule_waits_for_a_cool_window_when_the_next_dot_lies_in_the_hot_region(
        tmp_path):
    close = [(0.05, 0.07), (0.053, 0.07)]                 # 3 mm: within window_separation
    result, ending, model = paint(tmp_path, goal_of(close, tmp_path / 'runs' / 'close',
                                                    cooling='window'))
    assert ending == 'succeed' and result.dots_burnt == 2, result.message
    heat = model.heating_distance
    # the first dot retreats (no urgency: the plain retreat of Algorithm 1) ...
    assert [move[2:] for move in model.moves[:2]] == [
        (heat, pytest.approx(heat + model.settings.window_travel_offset), False),
        (pytest.approx(heat + model.retreat_offset), 0.0, False)]
    # ... and the second heats only once the first shows no N_p in its window
    [(_, until)], [(since, _)] = model.heated(close[0]), model.heated(close[1])
    last_look = max((t, n_p) for t, n_p in model.frames if until < t < since)
    assert last_look[1][close[0]] == 0 and 0 < since - last_look[0] <= MOVE + 1e-9


@pytest.mark.parametrize('stop, ending, message', [
    ('stop_at', 'abort', 'stopped by a stop signal: retreated (a stop signal)'),
    ('fault_at', 'abort', 'device fault: servo alarm: overload; the wrist could not move '
                          '(servo alarm: overload); the arm lifted the lens'),
])
def test_a_stop_signal_or_a_fault_while_heating_takes_the_focus_off_and_aborts(
        tmp_path, stop, ending, message):
    result, got, model = paint(tmp_path, goal_of(ROW, tmp_path / 'runs' / stop), **{stop: 3.0})
    assert (got, result.message) == (ending, message)
    [(since, until)] = model.heated(ROW[0])
    assert until == pytest.approx(3.0)                     # woken at once
    assert model.lens is None or model.lens[1] > model.heating_distance


def test_the_emergency_stop_ends_the_goal_and_moves_nothing_more(tmp_path):
    # the drivers took the focus off the wood themselves (node_kit.emergency_stop)
    result, ending, model = paint(tmp_path, goal_of(ROW, tmp_path / 'runs' / 'stop'),
                                  emergency_at=3.0)
    assert ending == 'abort' and result.message == (
        'stopped by the EMERGENCY STOP: the drivers stopped the arm and turned the lens off '
        'the sun')
    assert [at for at, *_ in model.moves if at >= 3.0] == [] and model.escapes == []


def test_the_same_goal_again_resumes_at_the_first_unburnt_dot_and_burns_none_twice(tmp_path):
    runs = tmp_path / 'runs'
    # the first run is canceled 1 s into the heating of its third dot
    first, ending, _ = paint(tmp_path, goal_of(ROW, runs / 'first'), cancel_in_heating=(3, 1.0))
    assert ending == 'canceled' and burnt_in(runs / 'first') == [0, 1]
    again, ending, model = paint(tmp_path, goal_of(ROW, runs / 'second'))
    assert ending == 'succeed', again.message
    assert (again.dots_resumed, again.dots_burnt, again.dots_skipped) == (2, 2, 0)
    assert again.message.startswith('2 dots burnt') and '2 burnt before' in again.message
    # the focus never rested on a dot burnt before; the one cut short is burnt now
    assert [len(model.heated(target)) for target in ROW] == [0, 0, 1, 1]
    assert sorted(burnt_in(runs / 'first') + burnt_in(runs / 'second')) == [0, 1, 2, 3]
    assert (runs / 'second' / 'plan.json').read_text() == \
        (runs / 'first' / 'plan.json').read_text()
    # the newest run of the goal finished: sent once more, it starts over
    third, ending, _ = paint(tmp_path, goal_of(ROW, runs / 'third'))
    assert (third.dots_resumed, third.dots_burnt) == (0, 4)


def test_start_index_skips_the_dots_before_it(tmp_path):
    result, ending, model = paint(tmp_path, goal_of(ROW, tmp_path / 'runs' / 'late',
                                                    start_index=3))
    assert ending == 'succeed' and (result.dots_burnt, result.dots_skipped) == (1, 3)
    assert [len(model.heated(target)) for target in ROW] == [0, 0, 0, 1]


@pytest.mark.parametrize('fields, words', [
    ({'image_path': 'sample:text'}, 'give exactly one source of dots'),
    ({'cooling': 'fast'}, 'cooling must be one of'),
])
def test_a_bad_goal_is_refused_before_anything_moves(tmp_path, fields, words):
    result, ending, model = paint(tmp_path, goal_of(ROW, tmp_path / 'runs' / 'bad', **fields))
    assert ending == 'abort' and words in result.message
    assert model.moves == [] and model.heatings == []


def test_the_painting_heats_retreats_and_plans_at_the_lens_planners_distances(tmp_path):
    # the lens planner's focal calibration put the focus 3 mm beyond the paper's 8.2 cm: the
    # painter never names a distance, and plans at the ones the lens planner published
    run_dir = tmp_path / 'runs' / 'calibrated'
    result, ending, model = paint(tmp_path, goal_of(ROW, run_dir), heating_distance=0.085)
    assert ending == 'succeed' and result.dots_burnt == 4, result.message
    assert [len(model.heated(target)) for target in ROW] == [1, 1, 1, 1]
    assert sorted({round(move[2], 9) for move in model.moves}) == pytest.approx(
        [0.085, 0.085 + 0.03])                         # heated there, retreated 3 cm beyond
    plan = Plan.from_json((run_dir / 'plan.json').read_text())
    assert plan.parameters['d_lp'] == pytest.approx(0.085)
    assert plan.parameters['retreat'] == pytest.approx(0.03)


def test_without_the_lens_planners_distances_the_goal_fails_before_any_move(tmp_path):
    model = RigModel(settings(tmp_path))
    model.focus_distances = lambda: None           # no lens planner has said them
    result, ending = run(PaintingRun(model, model.settings).execute(
        goal_of(ROW, tmp_path / 'runs' / 'none')))
    assert ending == 'abort' and not result.success
    assert "the lens planner's distances (focus/distances) is not available" in result.message
    assert model.moves == [] and model.heatings == []
