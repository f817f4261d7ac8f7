"""
A painting run: Algorithm 1 of the paper for one ``paint`` goal (helio_msgs/PaintPattern).

Per goal (paper Sec. IV-B and IV-C, Algorithm 1):

1. the goal checked (``check_goal``: one source of dots, a picture file that exists, a
   cooling rule, the plan options) before anything moves;
2. the rig calibration (``calibrate_rig`` of the lens planner, issue 28: the build's errors
   measured from the marker and the spot) when asked by ``calibrate_rig`` (``missing``: no
   calibration of the rig as built has come on ``calibration/rig``; ``always``; ``never``,
   the default until it places as well as the paper), else the robot-world calibration
   (``calibrate_world``; once per node, or every goal, by parameter); without a sun
   estimate, the sun sweep (``sweep_sun``): lines 1-2;
3. the dot-size test row (``dot_size_run``, issue 29) when ``calibrate_dots`` asks for it
   (``missing``: no ``dots.yaml`` for this rig yet); then the plan (``helio_control.plan``):
   the picture (or the goal's points) to ordered world dots with per-dot N_p targets (for
   the width asked, with the calibration), checked against the rig's reach for the
   estimated sun at the lens planner's heating and retreat distances (``focus_distances``:
   it owns them, issue 32; they follow its focal calibration);
4. per dot, Algorithm 1 lines 6-14 (``helio_control.procedures.dot_procedure``); the sun estimate
   follows the sun by Eq 18 (``sun_estimator`` republishes it).

Beyond the paper:

- **resume**: every finished dot is appended (and flushed) to the run's ``journal.jsonl``;
  the same goal sent again continues an unfinished run at its first unburnt dot, with the
  same plan, none lost and none doubled (``helio_control.run_journal``; ``fresh`` starts
  over; ``start_index`` skips the dots before it);
- **dry run**: the whole painting with the lens at the retreat distance: reach and timing
  without burning;
- **tones**: each dot's own N_p target (the plan's, Fig. 8d);
- **the sky** (``helio_control.sky``, ``helio sky``): a goal the sun cannot serve is refused
  before its first dot: without a sun estimate, a sun lower than the sweep estimates
  (``sky.min_sweep_elevation_deg``, at the site: before the sweep); with one, none of the
  goal's points (its dots, or a grid over its canvas) within reach of it. The reason names
  ``helio sky`` (with the robot heading the estimate implies) and when the sun serves next;
- **endings**: a failure, a cancel, a stop signal or a bug retreats the lens
  (``DotProcedure.retreat``) and says so in the result; under the emergency stop the drivers
  have taken the focus off the wood and nothing is moved.

The run directory (``run_dir`` of the goal, else ``runs_dir``/<UTC time>) holds
``plan.json``, ``journal.jsonl`` and ``resume.json``. ``PaintingRun`` talks to the rig only
through a ``PainterRigPort``. Pure Python: no rclpy.
"""

import datetime
import os
import traceback

from helio_control import sky
from helio_control.dot_check import dot_hold, expected_dot
from helio_control.dot_size_calibration import dot_size_for_painting
from helio_control.dot_size_calibration import sized_options
from helio_control.picture_input import picture_from_image_msg, PictureError
from helio_control.plan import options_from_goal, Plan, plan_dots, plan_picture
from helio_control.plan import PlanError, PlanOptionsError
from helio_control.procedures import dot_size_run
from helio_control.procedures.dot_procedure import DotProcedure
from helio_control.procedures.painter_port import COOLING_RULES, PaintCanceled, PaintFailed
from helio_control.procedures.painter_port import PaintFeedback, PaintResult
from helio_control.run_journal import dots_left, goal_key, start_run, unfinished_run
import numpy as np

UTC = datetime.timezone.utc


def check_goal(goal):
    """Raise PaintFailed naming what is wrong with a PaintPattern goal, before any move."""
    sources = [bool(goal.image_path), goal.image.width > 0, len(goal.points) > 0]
    if sum(sources) != 1:
        raise PaintFailed('give exactly one source of dots: image_path, image or points '
                          f'(got {sum(sources)})')
    if goal.image_path and not goal.image_path.startswith('sample:') \
            and not os.path.isfile(goal.image_path):
        raise PaintFailed(f"image_path {goal.image_path!r}: no such file on the painter's "
                          'machine (or sample:NAME for a picture the project makes)')
    if goal.cooling and goal.cooling not in COOLING_RULES:
        raise PaintFailed(f'cooling must be one of {COOLING_RULES} or empty, got '
                          f'{goal.cooling!r}')
    try:
        options_from_goal(goal).validate()
    except PlanOptionsError as error:
        raise PaintFailed(f'bad goal: {error}') from None


class PaintingRun:
    """
    The ``paint`` goals of one painter, run through a port; see the module docstring.

    ``world_calibrated`` holds across goals (the ``once`` rule); ``dot`` is the dot
    procedure, whose ``at_heating`` says whether the lens is focused on the wood.
    """

    def __init__(self, port, settings):
        """Work through `port` (PainterRigPort) with `settings` (PainterSettings, live)."""
        self.port = port
        self.settings = settings
        self.dot = DotProcedure(port, settings)
        self.world_calibrated = False
        self._journal = None             # the running goal's JournalWriter
        self.dot_calibration_note = ''   # what the test row before the goal's plan gave

    async def execute(self, goal):
        """
        Run one goal; return (PaintResult, how the goal ends: 'succeed', 'abort', 'canceled').

        The journal's result line is written before this returns; a goal that ends early
        retreats the lens first (see the module docstring: endings).
        """
        port = self.port
        result = PaintResult()
        self.dot.begin_goal()
        wall_started = port.unix_now()
        try:
            # under use_sim_time the clock reads 0 until the first /clock arrives: every
            # duration of the run would be counted from 1970
            await port.wait_until(lambda: port.now() > 0.0,
                                  'the clock (/clock, with use_sim_time)')
        except TimeoutError as error:
            result.message = str(error)
            return result, 'abort'
        started = port.now()
        try:
            await self._paint(goal, result)
            ending = 'succeed' if result.success else 'abort'
        except (PaintCanceled, PaintFailed) as ended:
            ending = 'abort'
            if port.emergency_engaged():
                # no retreat: the drivers refuse every move now; they stopped the arm and the
                # servo driver turned the lens off the sun (node_kit.emergency_stop)
                self.dot.at_heating = None
                result.message = 'stopped by the EMERGENCY STOP: the drivers stopped the ' \
                    'arm and turned the lens off the sun' + (f' ({ended})' if str(ended) else '')
            elif isinstance(ended, PaintFailed):
                result.message = f'{ended}; {await self.dot.retreat(str(ended))}'
            elif port.stop_signal() and not port.client_canceled():
                # the node stopped (Ctrl-C, SIGTERM), not the client: the goal aborts
                result.message = (f'stopped by {port.stop_signal()}: '
                                  + await self.dot.retreat(port.stop_signal()))
            else:
                result.message = 'canceled: ' + await self.dot.retreat('cancel')
                ending = 'canceled'
        except Exception as error:           # a bug: retreat, then say what happened
            port.get_logger().error(traceback.format_exc())
            result.message = (f'internal error: {type(error).__name__}: {error}; '
                              f'{await self.dot.retreat("internal error")}')
            ending = 'abort'
        finally:
            port.set_window(None)
            result.duration = port.now() - started
            result.cloud_wait = self.dot.cloud_wait
            if self._journal is not None:
                self._journal.result(
                    success=bool(result.success), dots_burnt=int(result.dots_burnt),
                    dots_skipped=int(result.dots_skipped), duration=float(result.duration),
                    wall_duration=port.unix_now() - wall_started, message=result.message)
                self._journal.close()
                self._journal = None
        return result, ending

    async def _prepare(self, feedback):
        """Calibrate the rig or the world, estimate the sun when needed (Alg. 1 lines 1-2)."""
        port, settings = self.port, self.settings
        if settings.calibrate_rig == 'always' or (settings.calibrate_rig == 'missing'
                                                  and not port.rig.calibrations_applied):
            feedback.phase = 'calibrating'
            port.publish_feedback(feedback)
            taken = port.rig.calibrations_applied
            rig = await port.calibrate_rig()
            if not rig.success:
                raise PaintFailed(f'rig calibration failed: {rig.message}')
            # planned with the calibrated rig only: its calibration/rig message may come
            # after the result
            await port.wait_until(lambda: port.rig.calibrations_applied > taken,
                                  'the rig calibration on calibration/rig')
            self.world_calibrated = True
            if rig.estimate.converged and not rig.estimate.ambiguous:
                port.use_sun_estimate(rig.estimate)
        elif settings.calibrate_world == 'always' or (settings.calibrate_world == 'once'
                                                      and not self.world_calibrated):
            feedback.phase = 'calibrating'
            port.publish_feedback(feedback)
            world = await port.calibrate_world()
            if not world.success:
                raise PaintFailed(f'robot-world calibration failed: {world.message}')
            self.world_calibrated = True
        self.dot.check()
        if port.sun_ray() is None:
            feedback.phase = 'estimating_sun'
            port.publish_feedback(feedback)
            sweep = await port.sweep_sun()
            if not sweep.success:
                raise PaintFailed(f'sun estimation failed: {sweep.message}')
            port.use_sun_estimate(sweep.estimate)
        self.dot.check()

    async def _distances(self):
        """Return the lens planner's (heating, retreat distance) [m], waiting for them."""
        port = self.port
        try:
            await port.wait_until(lambda: port.focus_distances() is not None,
                                  "the lens planner's distances (focus/distances)")
        except TimeoutError as error:
            raise PaintFailed(str(error)) from None
        return port.focus_distances()

    async def _refuse_what_the_sun_cannot_serve(self, goal):
        """Raise PaintFailed when the sun cannot serve `goal` now (see the module: the sky)."""
        port, settings = self.port, self.settings
        now = datetime.datetime.fromtimestamp(port.now(), UTC)
        sun = port.sun_ray()
        if sun is None:
            refusal = sky.sweep_refusal(settings.site, now,
                                        settings.sky_min_sweep_elevation_deg)
        else:
            options = options_from_goal(goal)
            points = [[p.x, p.y] for p in goal.points] if goal.points else sky.canvas_points(
                options.offset_x, options.offset_y, options.canvas_size,
                settings.sky_reach_spacing)
            direction, estimated = sun
            heating, retreat = await self._distances()
            refusal = sky.reach_refusal(
                port.rig, points, direction, heating, retreat - heating, settings.site, now,
                settings.sky_min_sweep_elevation_deg,
                ray_time=datetime.datetime.fromtimestamp(estimated, UTC)
                if estimated > 0.0 else None)
        if refusal is not None:
            raise PaintFailed(f'refused: {refusal}')

    def _make_plan(self, goal, distances):
        """Plan the goal's dots for the sun and the lens planner's `distances` [m]."""
        port, settings = self.port, self.settings
        try:
            dot_size, note = dot_size_for_painting(settings.calibration_dir, settings.rig_file)
            if note:
                port.get_logger().warning(note)
            n_p_given = goal.n_p_target > 0
            options, hold = sized_options(options_from_goal(goal), dot_size, n_p_given)
            if dot_size is not None and not n_p_given and not dot_size.within(
                    options.dot_radius):
                port.get_logger().warning(
                    f'dots {options.dot_radius * 1e3:.2f} mm wide lie outside what the '
                    'dot-size calibration measured: N_p target and hold extrapolated '
                    f'(N_p {options.n_p_target}, held {hold:.0f} s)')
            heating, retreat = distances
            options.d_lp, options.retreat = heating, retreat - heating
            if (goal.cooling or settings.cooling) == 'window':
                options.min_separation = settings.window_separation   # no hot neighbour next
                options.cooling_wait = False                          # and no wait
            sun = port.sun_ray()[0]
            if goal.points:
                points = np.array([[p.x, p.y] for p in goal.points], dtype=float)
                return plan_dots(points, options, port.rig, sun, dot_size=dot_size, hold=hold)
            picture = goal.image_path if goal.image_path else \
                picture_from_image_msg(goal.image)
            return plan_picture(picture, options, port.rig, sun, dot_size=dot_size, hold=hold)
        except (PictureError, PlanError, PlanOptionsError, ValueError) as error:
            raise PaintFailed(f'cannot plan the painting: {error}') from None

    async def _burn_test_row(self, goal, feedback):
        """Burn the dot-size test row first when asked (dot_size_run); return a note or ''."""
        port, settings = self.port, self.settings
        present, refused = dot_size_for_painting(settings.calibration_dir, settings.rig_file)
        if not dot_size_run.needs_test_row(settings.calibrate_dots, present is not None,
                                           goal.dry_run):
            return ''
        options = options_from_goal(goal)
        row_settings = settings.dot_row or dot_size_run.DotRowSettings()
        row = row_settings.row()
        conflict = dot_size_run.row_conflict(
            row, None if goal.points else dot_size_run.canvas_of(options),
            [[p.x, p.y] for p in goal.points],
            dot_size_run.clearance_of(row_settings.pitch, options.dot_radius))
        if conflict:
            note = f'dot-size calibration not made: {conflict}'
            port.get_logger().warning(note)
            return note
        port.get_logger().info('burning the dot-size test row first (calibrate_dots '
                               f'{settings.calibrate_dots}' + (f'; {refused}' if refused
                                                               else '') + ')')
        calibration, note = await dot_size_run.burn_test_row(
            self.dot, feedback, settings, row, port.get_logger().info)
        if calibration is None:
            port.get_logger().warning(note)
        return note

    def _plan_or_resume(self, goal, resumed, distances):
        """Return (plan, the dots burnt before, the run resumed or '') of the goal."""
        if resumed is None:
            return self._make_plan(goal, distances), set(), ''
        run_dir, burnt = resumed
        try:
            with open(os.path.join(run_dir, 'plan.json')) as stream:
                return Plan.from_json(stream.read()), burnt, run_dir
        except (OSError, ValueError, KeyError) as error:
            raise PaintFailed(f'cannot resume {run_dir}: {error}') from None

    async def _paint(self, goal, result):
        """Check, prepare, plan (or resume) and paint the goal's dots into `result`."""
        port, settings, dot = self.port, self.settings, self.dot
        feedback = PaintFeedback(phase='planning')
        began = port.now()
        check_goal(goal)                                  # before anything moves
        key = goal_key(goal)
        await self._refuse_what_the_sun_cannot_serve(goal)     # no sweep for a sun too low
        await self._prepare(feedback)
        await self._refuse_what_the_sun_cannot_serve(goal)     # nor a canvas out of its reach
        resumed = None if goal.fresh else unfinished_run(settings.runs_dir, key)
        self.dot_calibration_note = ''
        row_began = port.now()
        if resumed is None:                               # a new plan: sized as measured
            self.dot_calibration_note = await self._burn_test_row(goal, feedback)
        row_time = port.now() - row_began                 # not the plan's: the report's
        plan, burnt, resumed_from = self._plan_or_resume(goal, resumed, await self._distances())
        painted_from = port.now()                         # the dots' time, the estimate's
        run_dir = os.path.abspath(goal.run_dir) if goal.run_dir else os.path.join(
            settings.runs_dir, datetime.datetime.fromtimestamp(port.unix_now(), UTC).strftime(
                '%Y%m%dT%H%M%SZ'))
        self._journal = start_run(run_dir, plan.to_json(), key, burnt, resumed_from)
        self._journal.run(goal, began, port.unix_now(), row_time)
        result.run_dir = run_dir
        result.dots_planned = len(plan.dots)
        result.dots_resumed = len(burnt)
        if not len(plan.dots):
            raise PaintFailed('the plan has no dot: ' + '; '.join(
                f'{reason}' for _, reason in plan.rejected[:3]) if plan.rejected else
                'the plan has no dot')
        cooling = goal.cooling or settings.cooling
        per_dot = plan.time_estimate.get('per_dot_s', 0.0)
        todo = dots_left(len(plan.dots), burnt, goal.start_index)
        result.time_estimated = per_dot * len(todo)
        result.dots_skipped = len(plan.dots) - len(todo) - len(burnt)
        feedback.total = len(plan.dots)
        cycles = []
        failed = 0
        for position, i in enumerate(todo):
            dot.check()
            target = plan.dots[i]
            feedback.index = i
            feedback.elapsed = port.now() - began
            feedback.eta = (float(np.mean(cycles)) if cycles else per_dot) * (len(todo)
                                                                              - position)
            # the window rule goes on at once, but not into this dot's hot region
            hot_next = cooling == 'window' and position + 1 < len(todo) and float(np.hypot(
                *(plan.dots[todo[position + 1]] - target))) < settings.window_separation
            expected, neighbours = expected_dot(plan, i)
            outcome = await dot.paint(feedback, i, target, int(plan.n_p_targets[i]), cooling,
                                      goal.dry_run, hot_next, expected, neighbours,
                                      hold=dot_hold(plan, i))
            cycles.append(outcome['end'] - outcome['start'])
            self._journal.dot(**outcome)
            if outcome['outcome'] == 'burnt':
                result.dots_burnt += 1
            elif outcome['outcome'] == 'failed':
                failed += 1
            else:
                result.dots_skipped += 1
        if dot.at_heating is not None:                # the window rule's last dot
            retreated = await dot.retreat('the painting is done')
            if not retreated.startswith('retreated'):
                raise PaintFailed(f'after the last dot: {retreated}')
        feedback.phase, feedback.index = 'done', len(plan.dots)
        port.publish_feedback(feedback)
        result.success = failed == 0
        result.message = self._summary(goal, result, plan, len(todo), failed,
                                       port.now() - painted_from)

    def _summary(self, goal, result, plan, painted, failed, seconds):
        """Return the result message of a run that went through its `painted` dots."""
        dot = self.dot
        if goal.dry_run:
            message = (f'dry run: {painted - failed} of {painted} dots reached at the retreat '
                       'distance')
        else:
            message = f'{result.dots_burnt} dots burnt'
        message += (f' in {seconds:.0f} s (the plan estimated {result.time_estimated:.0f} s); '
                    f'{result.dots_resumed} burnt before, {result.dots_skipped} skipped, '
                    f'{failed} failed, of {len(plan.dots)}; waited {dot.cloud_wait:.0f} s for '
                    f'the sun; run in {result.run_dir}')
        if plan.rejected:
            message += f'; {len(plan.rejected)} picture dots left out by the plan'
        if self.dot_calibration_note:
            message += f'; {self.dot_calibration_note}'
        if dot.thermal_interruptions:
            message += (f'; {dot.thermal_interruptions} heating(s) broken off by a stale '
                        'thermal stream and done again')
        if self.settings.verify_dots and not goal.dry_run:
            seen = sum(measure.charred for _, measure in dot.verified_dots)
            message += (f'; {seen} dots verified by the camera, '
                        f'{len(dot.verified_dots) - seen} looks found no dot')
        return message
