"""
One dot of a painting: Algorithm 1 lines 6-14 with the painter's safety rules around it.

Per dot (paper Sec. IV-B): ``focus`` at the heating distance (``HEAT``); hold while N_p <
the dot's target N_p* (``dot_cycle``, lines 6-9); retreat by delta d_lp, the paper's 3 cm
(``RETREAT``); with the paper's cooling rule wait until N_p is back to
0 (lines 10-13), with the ``window`` rule count N_p only within ``window_radius`` of the dot
(``set_window``: the previous dot's afterglow does not count) and go on at once: the move to
the next dot is one ``focus`` goal that starts with the retreat, so the arm does not stop in
between; a next dot in this one's hot region (`hot_next`) waits for N_p = 0 in its window.

Beyond the paper:

- **clouds**: a loss of sun while heating (``dot_cycle``: N_p or T_max falling) retreats the
  lens and waits for the sun (the spot seen in ``sun_back_frames`` frames in a row, at most
  ``cloud_timeout``), then heats the same dot again with its full target;
- **fire-safety watchdog**: the lens never rests at the heating distance without fresh
  thermal data. Thermal statistics older than ``thermal_stale`` (node clock, or
  ``thermal_stale_wall`` of wall time: the port's ``next_stats``), a dot held past
  ``max_heating``, a device fault or a cancel: the lens retreats at once. ``retreat`` takes
  the focus off the wood by the first way that works: the lens planner's retreat (``focus``
  at ``RETREAT``, urgent); if the arm cannot move, the wrist
  turns the lens off the sun (``wrist_escape_pitch``, away from the pitch servo's nearer
  end); if the wrist cannot move, the arm alone lifts the lens straight up by
  ``arm_escape_lift`` (``rig_kinematics.escape_lift``); when no way works (both devices at
  fault) it is tried again every ``retreat_retry_period`` for ``retreat_retry_time``, not
  under the emergency stop (its drivers take the focus off themselves). A stale stream gets
  ``thermal_back_timeout`` to come back (the dot is heated again from the start, and the
  result counts it). A window-rule frame without a camera pose is fresh data without a
  window reading: heat on while the image's N_p is below the target (the window lies in
  the image), else it counts towards ``thermal_stale``. A frozen frame (a Lepton's flat-field
  correction repeats its last frame for 0.3-1 s every few minutes) is no fresh reading: the
  dot heats on blind for at most ``thermal_freeze_max`` from the last live frame, then it is
  a stale stream (issue 29);
- **the camera's check** (issue 29): once the lens is retreated the RGB camera measures the
  char at the target (``helio_perception.char_dots``); a dot burnt that it finds not charred
  is heated again, at most ``verify_reheats`` times, then counted as failed.

The distances are the lens planner's (issue 32): it alone owns the heating distance (its
focal calibration, else its parameter) and the retreat distance (that plus its
``retreat_offset``); a dot asks to heat at a point or to retreat from it, never in metres.
``DotProcedure`` talks to the rig only through a ``PainterRigPort``. Pure Python: no rclpy.
"""

import math

from helio_control.dot_cycle import CycleSettings, Decision, DotCycle
from helio_control.procedures.painter_port import HEAT, PaintCanceled, PaintFailed, RETREAT
from helio_optics.geometry import invert_transform
from helio_optics.rig_kinematics import escape_lift, escape_pitch, JOINT_NAMES
from helio_optics.rig_kinematics import UnreachableError
from helio_perception.char_dots import CharSettings, measure_in_image
import numpy as np

# how a retreat that found no way to take the focus off the wood begins its account
RETREAT_FAILED = 'RETREAT FAILED'


def readings(stats, window):
    """Return (N_p, T_max) of the window when it is used and valid, else of the image."""
    if window and stats.window_valid:
        return stats.window_n_p, stats.window_t_max
    return stats.n_p, stats.t_max


class SunReturn:
    """The sun is back once the light spot is seen in `frames` frames in a row."""

    def __init__(self, frames):
        """Count valid spots in a row up to `frames` [-]."""
        self.frames = int(frames)
        self.in_a_row = 0

    def seen(self, valid):
        """Take one spot observation's validity; return whether the sun is back."""
        self.in_a_row = self.in_a_row + 1 if valid else 0
        return self.in_a_row >= self.frames


class DotProcedure:
    """
    Burn, retreat from and check single dots through a port; see the module docstring.

    Per goal (``begin_goal``) it counts the heatings broken off by a stale thermal stream,
    the time waited for the sun and the camera's looks. ``at_heating`` is the world target
    (x, y) [m] the lens is focused on at the heating distance, else None.
    """

    def __init__(self, port, settings):
        """Work through `port` (PainterRigPort) with `settings` (PainterSettings, live)."""
        self.port = port
        self.settings = settings
        self.at_heating = None
        self.thermal_interruptions = 0
        self.cloud_wait = 0.0
        self.verified_dots = []       # (index, char_dots.DotMeasure) of every look

    def begin_goal(self):
        """Start a goal's counts afresh."""
        self.thermal_interruptions = 0
        self.cloud_wait = 0.0
        self.verified_dots = []

    def check(self):
        """Raise PaintCanceled on a cancel, PaintFailed on a device fault or silence."""
        if self.port.cancel_requested():
            raise PaintCanceled()
        faults = [why for _, why in self.port.device_faults()]
        if faults:
            raise PaintFailed('device fault: ' + '; '.join(faults))

    async def paint(self, feedback, index, target, n_p_target, cooling, dry_run,
                    hot_next=False, expected=0.0, neighbours=(), hold=0.0):
        """
        Burn one dot and verify it with the RGB camera; return its journal record's fields.

        The dot is heated (``heat``); once the lens is retreated (the paper's cooling rule,
        or a window-rule dot whose next one lies in its hot region) the camera's verdict
        (``verify``) is recorded, a dot given up too; a dot burnt that it finds not charred
        (nothing dark of at least ``verify_min_diameter_ratio`` of `expected` [m] at the
        target) is heated again, at most ``verify_reheats`` times, then counted as failed.
        The lens is retreated through all of it: a failed verification leaves it where the
        heating left it, off the wood. `hold` [s]: once N_p reaches the target the dot is
        held there that long (``dot_cycle``: a dot wider than N_p can ask for).
        """
        port, settings = self.port, self.settings
        record = await self.heat(feedback, index, target, n_p_target, cooling, dry_run,
                                 hot_next, hold)
        record.update(verdict='', verdict_reason='', measured_diameter=0.0, reheats=0)
        if dry_run or not settings.verify_dots or not record['dwell'] > 0.0:
            return record             # nothing heated: nothing to see
        while True:
            if self.at_heating is not None:
                record['verdict_reason'] = 'not verified: the lens is not retreated'
                return record
            feedback.phase = 'verifying'
            port.publish_feedback(feedback)
            began, wall = port.now(), port.wall_now()
            measure, why = await self.verify(target, expected, neighbours)
            port.get_logger().info(
                f'dot {index}: the camera looked in {port.now() - began:.2f} s '
                f'({port.wall_now() - wall:.2f} s wall): '
                + (why if measure is None else
                   f'{measure.diameter * 1e3:.2f} mm, {measure.reason or "charred"}'))
            if measure is None:
                port.get_logger().warning(f'dot {index} not verified: {why}')
                record['verdict_reason'] = f'not verified: {why}'
                return record
            self.verified_dots.append((index, measure))
            record.update(verdict='charred' if measure.charred else 'not charred',
                          verdict_reason=measure.reason,
                          measured_diameter=float(measure.diameter))
            if measure.charred or record['outcome'] != 'burnt':
                return record         # a dot given up (max_heating) is not heated again
            if record['reheats'] >= settings.verify_reheats:
                record.update(outcome='failed', reason=(
                    f'the RGB camera sees no dot at the target ({measure.reason}) after '
                    f"{record['reheats'] + 1} heating(s)"))
                return record
            port.get_logger().warning(
                f'dot {index}: the RGB camera sees no dot ({measure.reason}): heated again')
            again = await self.heat(feedback, index, target, n_p_target, cooling, dry_run,
                                    hot_next, hold)
            record.update(reheats=record['reheats'] + 1, end=again['end'],
                          dwell=record['dwell'] + again['dwell'],
                          restarts=record['restarts'] + again['restarts'],
                          peak_n_p=max(record['peak_n_p'], again['peak_n_p']),
                          t_max=max(record['t_max'], again['t_max']))
            if again['outcome'] != 'burnt':
                record.update(outcome=again['outcome'], reason=again['reason'])
                return record

    async def verify(self, target, expected, neighbours):
        """
        Measure the dot at `target` in the first RGB frame taken from now on.

        Return (``char_dots.DotMeasure``, '') or (None, why not: no camera_info, no frame
        within ``verify_timeout`` of wall time, no joint states). The frame's camera pose is
        the joints' (at rest, retreated) through the rig and the robot-world calibration.
        """
        port, settings = self.port, self.settings
        camera = port.rgb_camera()
        if camera is None:
            return None, 'no rgb/camera_info'
        joints = port.joints()
        if not all(name in joints for name in JOINT_NAMES):
            return None, 'no joint states'
        try:
            image, undecodable = await port.next_rgb_image(port.now(),
                                                           settings.verify_timeout), None
        except ValueError as error:
            image, undecodable = None, error
        self.check()
        if undecodable is not None:
            return None, f'the frame cannot be measured: {undecodable}'
        if image is None:
            return None, f'no RGB frame within {settings.verify_timeout:g} s'
        joints = port.joints()
        rig = port.rig
        pose = rig.forward(np.array([joints[name] for name in JOINT_NAMES]))
        T_world_rgb = invert_transform(rig.parameters.T_robot_world) @ pose.T_robot_rgb
        char_settings = CharSettings(dark_ratio=settings.verify_dark_ratio,
                                     min_diameter_ratio=settings.verify_min_diameter_ratio,
                                     response=settings.verify_camera_response)
        try:
            return measure_in_image(image, camera, T_world_rgb, target, expected, neighbours,
                                    char_settings), ''
        except ValueError as error:
            return None, f'the frame cannot be measured: {error}'

    async def heat(self, feedback, index, target, n_p_target, cooling, dry_run,
                   hot_next=False, hold=0.0):
        """
        Burn one dot (Algorithm 1 lines 6-14); return its journal record's fields.

        `hot_next`: with the window rule, the next dot lies in this one's hot region, so
        this dot retreats and waits for N_p = 0 in its window before the next begins.
        `hold` [s]: heat on that long at N_p >= the target once reached.
        """
        port, settings = self.port, self.settings
        start = port.now()
        record = {'index': int(index), 'target': [float(target[0]), float(target[1])],
                  'n_p_target': n_p_target, 'start': start, 'end': start, 'dwell': 0.0,
                  'peak_n_p': 0, 't_max': -273.15, 'outcome': 'burnt', 'reason': '',
                  'restarts': 0, 'hold': float(hold), 'cooling': 0.0}
        if dry_run:
            feedback.phase = 'moving'
            port.publish_feedback(feedback)
            moved = await port.focus(target, RETREAT)
            record.update(end=port.now(), outcome='skipped' if moved.success else 'failed',
                          reason='dry run' if moved.success else moved.message)
            return record
        cycle = DotCycle(CycleSettings(n_p_target=n_p_target,
                                       max_heating=settings.max_heating,
                                       max_cooling=settings.max_cooling,
                                       wait_for_zero=(cooling == 'paper' or hot_next),
                                       hold=hold))
        window = cooling == 'window'
        port.set_window(target if window else None)
        travel = settings.window_travel_offset
        while True:                                   # again after a cloud
            feedback.phase = 'moving'
            port.publish_feedback(feedback)
            moved = await port.focus(target, HEAT, travel if window else 0.0)
            if not moved.success:
                if self.at_heating is not None:       # the last dot's heating pose
                    port.get_logger().warning(await self.retreat('the move failed'))
                record.update(end=port.now(), outcome='failed', reason=moved.message)
                return record
            self.at_heating = target
            cycle.start_heating(port.now())
            feedback.phase = 'heating'
            decision, stale, n_p, t_max, cap = await self._hold(
                feedback, record, cycle, n_p_target, window)
            if window and not hot_next and decision is Decision.RETREAT:
                # the window rule moves on at once: the move to the next dot begins with
                # the retreat along the sun ray (lens_moves), so no separate retreat here;
                # after the last dot, or when anything stops the painting, the run retreats
                decision = cycle.update(port.now(), n_p, t_max, cap)
                break
            retreat = await port.focus(target, RETREAT)
            if not retreat.success:
                raise PaintFailed(f'the retreat after dot {index} failed: {retreat.message}')
            self.at_heating = None
            if stale:
                port.get_logger().error(
                    f'dot {index}: thermal statistics stale for more than '
                    f'{settings.thermal_stale:g} s while heating ({stale}): retreated; '
                    'waiting for them')
                await self._wait_for_thermal(index)
                self.thermal_interruptions += 1
                record['restarts'] += 1
                cycle.restart()
                continue
            if decision is Decision.CLOUD:
                port.get_logger().warning(
                    f'dot {index}: sun lost ({cycle.cloud_reason}); waiting for it')
                self.cloud_wait += await self._wait_for_sun(feedback)
                record['restarts'] += 1
                cycle.restart()
                continue
            break
        record.update(dwell=float(cycle.heating_time), peak_n_p=int(cycle.peak_n_p))
        if cycle.outcome != 'charred' and cycle.peak_n_p >= n_p_target:
            record.update(outcome='failed', reason=f'held {cycle.held:.1f} of {hold:g} s at '
                          f'N_p >= {n_p_target} within {settings.max_heating + hold:g} s '
                          '(max_heating + the hold)')
        elif cycle.outcome != 'charred':
            record.update(outcome='failed', reason=f'N_p reached only {cycle.peak_n_p} of '
                          f'{n_p_target} in {settings.max_heating + hold:g} s (max_heating'
                          + (' + the hold)' if hold else ')'))
        feedback.phase = 'cooling'
        port.publish_feedback(feedback)
        while decision is not Decision.NEXT:
            stats = await port.next_stats()
            self.check()
            if stats is None:
                break                  # retreated already: a stale stream ends the wait
            if stats.frozen:
                continue               # no reading (flat-field correction)
            n_p, t_max = readings(stats, window)
            feedback.n_p, feedback.t_max = int(n_p), float(t_max)
            port.publish_feedback(feedback)
            decision = cycle.update(port.now(), n_p, t_max, stats.camera_cap)
        record['end'] = port.now()
        if math.isfinite(cycle.cooling_time):
            record['cooling'] = float(cycle.cooling_time)
        return record

    async def _hold(self, feedback, record, cycle, n_p_target, window):
        """
        Hold the lens at the heating distance while the cycle says HEAT (lines 6-9).

        Return (decision, why the watchdog ended it or '', the last N_p, T_max and camera
        cap read). A frozen camera (flat-field correction) holds its output: no reading and
        no reason to fail the dot, but blind for at most ``thermal_freeze_max`` from the
        last live frame, then a stale stream.
        """
        port, settings = self.port, self.settings
        decision = Decision.HEAT
        blind_since = None         # window rule: since when the window had no figures
        frozen = False             # the camera repeats its last frame
        n_p, t_max, cap = 0, 0.0, None    # the last reading (none yet)
        while decision is Decision.HEAT:
            budget = None
            if frozen:
                live = port.live_stats_stamp()
                budget = -1.0 if live is None else \
                    live + settings.thermal_freeze_max - port.now()
            stats = None if budget is not None and budget <= 0.0 else \
                await port.next_stats(budget)
            self.check()
            if stats is None:
                # the watchdog: off the wood, by the caller
                return decision, (f'the thermal camera frozen for more than '
                                  f'{settings.thermal_freeze_max:g} s' if frozen
                                  else 'no thermal statistics'), n_p, t_max, cap
            frozen, cap = stats.frozen, stats.camera_cap
            if frozen:
                decision = cycle.update_unread(port.now())      # max_heating only
                continue
            if window and not stats.window_valid:
                # no thermal camera pose for this image (joint states too far from its
                # stamp): no window reading. The image is fresh, and the window lies in it,
                # so the dot cannot be done while the whole image's N_p is below its target:
                # heat on. Otherwise the image's N_p (the last dot's afterglow too) says
                # nothing, and no reading for longer than thermal_stale is a stale stream
                n_p, t_max = readings(stats, window)          # the image's
                record['t_max'] = max(record['t_max'], float(t_max))
                if n_p < n_p_target:
                    blind_since = None
                    decision = cycle.update_unread(port.now())   # max_heating only
                    continue
                blind_since = port.now() if blind_since is None else blind_since
                if port.now() - blind_since > settings.thermal_stale:
                    return (decision, 'no window reading (thermal camera pose unknown)',
                            n_p, t_max, cap)
                continue
            blind_since = None
            n_p, t_max = readings(stats, window)
            feedback.n_p, feedback.t_max = int(n_p), float(t_max)
            port.publish_feedback(feedback)
            record['t_max'] = max(record['t_max'], float(t_max))
            decision = cycle.update(port.now(), n_p, t_max, cap)
        return decision, '', n_p, t_max, cap

    async def _wait_for_thermal(self, index):
        """Wait (lens retreated) for fresh thermal statistics; PaintFailed after the timeout."""
        port, settings = self.port, self.settings
        deadline = port.wall_now() + settings.thermal_back_timeout
        while port.wall_now() < deadline:
            stats = await port.next_stats()
            self.check()
            if stats is not None and not stats.frozen:
                return
        raise PaintFailed(f'thermal statistics stale for more than {settings.thermal_stale:g}'
                          f' s while heating dot {index}, and not back within '
                          f'{settings.thermal_back_timeout:g} s')

    async def _wait_for_sun(self, feedback):
        """Wait until the spot is seen in ``sun_back_frames`` frames in a row; return [s]."""
        port, settings = self.port, self.settings
        started = port.now()
        feedback.phase = 'waiting_for_sun'
        port.publish_feedback(feedback)
        returned = await port.wait_for_spots(SunReturn(settings.sun_back_frames).seen,
                                             settings.cloud_timeout)
        if port.cancel_requested():
            raise PaintCanceled()
        if not returned:
            raise PaintFailed(f'the sun did not come back within {settings.cloud_timeout:g} s')
        return port.now() - started

    async def retreat(self, why):
        """
        Put the focus off the wood; return what was done (never raises).

        A retreat that failed every way (``retreat_once``: both devices at fault at that
        moment, e.g. the Dobot's link reset while the servo driver is dead) is tried again
        every ``retreat_retry_period`` of wall time, with the devices as they are then, for
        up to ``retreat_retry_time``: a lens is never left focused on the wood while a way
        may come back (a driver reconnects within a second of a link reset). Not under the
        emergency stop, whose drivers refuse every goal and turn the lens away themselves.
        """
        port, settings = self.port, self.settings
        deadline = port.wall_now() + settings.retreat_retry_time
        done = await self.retreat_once(why)
        first, tries = done, 1
        while done.startswith(RETREAT_FAILED) and port.wall_now() < deadline \
                and port.running() and not port.emergency_engaged():
            port.get_logger().warning(f'{done}: trying again', throttle_duration_sec=2.0)
            await port.pause(settings.retreat_retry_period)
            done = await self.retreat_once(why)
            tries += 1
        return done if tries == 1 else f'{done} (at the try {tries}; the first: {first})'

    async def retreat_once(self, why):
        """Put the focus off the wood the first way that works; say what was done."""
        if self.at_heating is None:
            return 'the lens was not at the heating distance'
        port, settings = self.port, self.settings
        target = self.at_heating
        faults = port.device_faults()
        arm_fault = next((sentence for device, sentence in faults if device == 'dobot'), None)
        wrist_fault = next((sentence for device, sentence in faults if device == 'servo'),
                           None)
        if wrist_fault and arm_fault:      # nothing can move the lens now: tried again
            return f'{RETREAT_FAILED}: {arm_fault}; {wrist_fault}'
        if wrist_fault:                    # the wrist cannot move: the arm lifts the lens
            return await self._lift(wrist_fault)
        if arm_fault:                     # the arm cannot move: straight to the wrist
            failure = arm_fault
        else:
            try:
                result = await port.focus(target, RETREAT, urgent=True)
                if result.success:
                    self.at_heating = None
                    return f'retreated ({why})'
                failure = result.message
            except PaintFailed as error:
                failure = str(error)
        # the arm cannot move: tilt the lens off the sun with the wrist, from where it is,
        # away from the pitch servo's nearer end (the lens axis leaves the sun ray)
        try:
            joints = port.joints()
            yaw = float(joints.get('lens_yaw', 0.0))
            pitch = escape_pitch(float(joints.get('lens_pitch', 0.0)),
                                 settings.wrist_escape_pitch)
            result = await port.escape_wrist(yaw, pitch)
            if result.success:
                self.at_heating = None
                return f'the arm could not retreat ({failure}); the wrist turned the lens away'
            return f'{RETREAT_FAILED}: {failure}; the wrist: {result.message}'
        except PaintFailed as error:
            return f'{RETREAT_FAILED}: {failure}; the wrist: {error}'

    async def _lift(self, wrist_fault):
        """
        Lift the lens straight up (``arm_escape_lift``) with the arm alone; say what was done.

        The focus retreat of the lens planner moves the wrist too, and the wrist's driver is
        down: j1 kept and the flange level, the lens keeps its orientation and the focus
        rises off the wood (``rig_kinematics.escape_lift``).
        """
        port = self.port
        names = ('dobot_j1', 'dobot_j2', 'dobot_j3')
        try:
            joints = port.joints()
            if not all(name in joints for name in names):
                raise UnreachableError('no Dobot joint states heard yet', joint='')
            lifted = escape_lift(port.rig.arm, [joints[n] for n in names],
                                 self.settings.arm_escape_lift)
            result = await port.lift_arm([*(float(v) for v in lifted),
                                          float(joints.get('dobot_j4', 0.0))])
        except (UnreachableError, PaintFailed) as error:
            return f'{RETREAT_FAILED}: {wrist_fault}; the arm could not lift the lens: {error}'
        if not result.success:
            return (f'{RETREAT_FAILED}: {wrist_fault}; the arm could not lift the lens: '
                    f'{result.message}')
        self.at_heating = None
        return f'the wrist could not move ({wrist_fault}); the arm lifted the lens'
