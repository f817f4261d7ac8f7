"""
One joint-state buffer for every node that needs the rig's joints (paper Sec. II-B: x in R^5).

``/joint_states`` arrives in parts: ``dobot_driver`` publishes the arm joints
(``dobot_j1``..``dobot_j4``), ``servo_driver`` the wrist (``lens_yaw``, ``lens_pitch``), each
stamped on its own node clock (simulated time under ``use_sim_time``). ``JointStateBuffer``
merges the parts by joint name and keeps a short stamped history per joint, so a node can ask
for "the joints at the stamp of this image" (``at``) or "the latest joints, if fresh"
(``latest``). All times are the stamps' own clock, never the wall clock of the process that
buffers them: a node passes its clock's ``now`` for staleness. The one exception is the
optional receipt time ``add`` takes (a wall clock the caller reads): the drivers publish at a
rate of wall time, so beside a simulated world far faster than real time a driver that is
alive can leave seconds of simulated time between two messages; ``latest`` then calls a joint
stale only when it is old on both clocks, as the lens planner's focus lease judges its
heartbeat.

No rclpy import: nodes feed it messages, tests feed it numbers.
"""

import bisect
from dataclasses import dataclass
import math

from helio_optics.rig_kinematics import JOINT_NAMES
import numpy as np

# Queue depth of a camera node's joint_states subscription. rclpy takes one message per
# subscription per turn of the executor: a node whose image callbacks take longer than the
# drivers' messages come (40 a second: two partial messages at 20 Hz) works through a
# backlog, and with a deep queue its newest joints fall behind its images (depth 50 put the
# spot detector's 6-7 s of simulated time behind at 6x real time). A short queue drops the
# oldest instead, so the joints taken are at most this many messages old.
CAMERA_NODE_JOINT_STATE_DEPTH = 5


@dataclass
class JointLookup:
    """The answer of a lookup: `positions` (in the buffer's name order) or None and why."""

    positions: np.ndarray = None
    reason: str = ''
    gap: float = 0.0          # largest distance from the asked time to a sample used [s]
    waiting: bool = False     # not known yet: the samples that decide it have not come
    moving: bool = False      # refused because a joint changed around the asked time

    def __bool__(self):
        """Return whether joints were found."""
        return self.positions is not None


class JointStateBuffer:
    """
    Partial ``/joint_states`` merged by name, with a stamped history on the stamps' clock.

    `names` are the joints a lookup returns, in order (default the rig's five). Each joint
    keeps the samples of the last `history` seconds (at least the newest one). A stamp more
    than `restart_jump` seconds older than a joint's newest sample means the clock was
    restarted (a simulation started again): the history is dropped.
    """

    def __init__(self, names=JOINT_NAMES, history=10.0, restart_jump=1.0):
        """Start empty; `history` and `restart_jump` in seconds."""
        if not history > 0.0 or not restart_jump > 0.0:
            raise ValueError(f'history and restart_jump must be > 0 s, got {history} and '
                             f'{restart_jump}')
        self.names = tuple(names)
        self.history = float(history)
        self.restart_jump = float(restart_jump)
        self._stamps = {name: [] for name in self.names}
        self._values = {name: [] for name in self.names}
        self._received = {}           # name -> receipt time of its newest message (wall) [s]

    def clear(self):
        """Forget every sample."""
        for name in self.names:
            self._stamps[name].clear()
            self._values[name].clear()
        self._received.clear()

    def add(self, stamp, names, positions, received=None):
        """
        Take one (possibly partial) joint state at `stamp` [s], received at `received`.

        Joints not in the buffer's names are ignored; a name without a position or with a
        non-finite one is skipped. `received` is the wall-clock time the message came [s]
        (None: not tracked). Return what was skipped, as a sentence ('' when nothing).
        """
        stamp = float(stamp)
        if not math.isfinite(stamp):
            return f'joint state with a non-finite stamp {stamp!r} skipped'
        problems = []
        if len(positions) < len(names):
            problems.append(f'{len(names)} names but {len(positions)} positions')
        for name, value in zip(names, positions):
            if name not in self._stamps:
                continue
            value = float(value)
            if not math.isfinite(value):
                problems.append(f'{name} = {value}')
                continue
            stamps = self._stamps[name]
            if stamps and stamp < stamps[-1] - self.restart_jump:
                self.clear()     # the clock went back: a restarted simulation
            self._insert(name, stamp, value)
            if received is not None:
                self._received[name] = float(received)
        return ('joint state partly skipped: ' + ', '.join(problems)) if problems else ''

    def add_message(self, message, received=None):
        """Take a sensor_msgs/JointState (stamped in its header); return what was skipped."""
        stamp = message.header.stamp
        return self.add(stamp.sec + stamp.nanosec * 1e-9, message.name, message.position,
                        received)

    def _insert(self, name, stamp, value):
        stamps, values = self._stamps[name], self._values[name]
        if stamps and stamp >= stamps[-1]:
            index = len(stamps)
        else:
            index = bisect.bisect_right(stamps, stamp)
        if index > 0 and stamps[index - 1] == stamp:
            values[index - 1] = value        # the same stamp again: the newer message wins
            return
        stamps.insert(index, stamp)
        values.insert(index, value)
        cut = bisect.bisect_left(stamps, stamps[-1] - self.history)
        if cut > 0:
            del stamps[:cut], values[:cut]

    def newest_stamp(self):
        """Return the newest stamp over all joints [s], or None when empty."""
        newest = [s[-1] for s in self._stamps.values() if s]
        return max(newest) if newest else None

    def reaches(self, stamp):
        """
        Tell whether every joint heard of has a sample at or after `stamp` [s].

        An image stamped `stamp` then lies between samples of each joint, so its joints are
        interpolated rather than taken from a sample before it (the arm may have moved since).
        False while no joint has been heard of at all.
        """
        heard = [stamps for stamps in self._stamps.values() if stamps]
        return bool(heard) and all(stamps[-1] >= float(stamp) for stamps in heard)

    def at(self, stamp, tolerance, rest_hold=0.0, rest_epsilon=1e-6, rest_after_newest=True):
        """
        Return the joints at `stamp` [s] (JointLookup).

        Each joint is interpolated linearly between the samples around `stamp` when both lie
        within `tolerance` [s] of it; otherwise its nearest sample is used if that lies within
        `tolerance`. A joint with no sample that close makes the lookup fail, naming it.

        A joint at rest is known farther than that, up to `rest_hold` [s] (0: never): when
        the samples on both sides of `stamp` are equal (within `rest_epsilon` [rad]), or when
        `stamp` is newer than every sample and the newest two are equal. A publisher that
        samples the joints at a few hertz of wall time beside a simulation running several
        times faster leaves gaps of 0.3-0.5 s of the stamps' clock: an arm held still for a
        dot keeps its pose across them, a moving one does not pass for still.
        `rest_after_newest` False leaves out the second case (an image newer than every
        sample: the arm may have started to move since the newest).
        """
        stamp = float(stamp)
        positions, worst = [], 0.0
        for name in self.names:
            stamps, values = self._stamps[name], self._values[name]
            if not stamps:
                return JointLookup(reason=f'no {name} received yet')
            index = bisect.bisect_left(stamps, stamp)
            before = index - 1 if index > 0 else None
            after = index if index < len(stamps) else None
            if after is not None and stamps[after] == stamp:
                positions.append(values[after])
                continue
            gaps = {i: abs(stamps[i] - stamp) for i in (before, after) if i is not None}
            if before is not None and after is not None and max(gaps.values()) <= tolerance:
                weight = (stamp - stamps[before]) / (stamps[after] - stamps[before])
                positions.append(values[before] + weight * (values[after] - values[before]))
                worst = max(worst, max(gaps.values()))
                continue
            nearest = min(gaps, key=gaps.get)
            if gaps[nearest] > tolerance:
                rest = self._at_rest(stamps, values, before, after, stamp, rest_hold,
                                     rest_epsilon, rest_after_newest)
                if rest is None:
                    return JointLookup(reason=f'nearest {name} is {gaps[nearest]:.3f} s from '
                                              f'the asked time (tolerance {tolerance:g} s'
                                              + (f', at rest {rest_hold:g} s' if rest_hold > 0.0
                                                 else '') + ')',
                                       gap=gaps[nearest])
                positions.append(rest)
                worst = max(worst, gaps[nearest])
                continue
            positions.append(values[nearest])
            worst = max(worst, gaps[nearest])
        return JointLookup(positions=np.array(positions), gap=worst)

    def still_at(self, stamp, margin, hold, epsilon=1e-6, complete=False):
        """
        Return the joints at `stamp` [s] if the rig was still around it (JointLookup).

        Still: every joint's samples from the last one at or before ``stamp - margin`` to the
        first one at or after ``stamp + margin`` are equal within `epsilon` [rad], and those
        two lie within `hold` [s] of `stamp`. `margin` covers the skew between an image's
        stamp and the joint states' stamps (each node stamps on its own copy of the clock): a
        lens held still gives the same joints whichever clock is a little late, a moving one
        pairs its image with a pose from another instant (at 5 cm/s, 0.1 s is 5 mm on the
        panel). Sec. III-C's observations are taken with the rig at rest.

        While the samples after ``stamp + margin`` have not come the answer is `waiting`.
        `complete` True (an answer is needed now) takes the newest sample, if it is at or after
        `stamp`, in their place; with none after `stamp` the answer is still `waiting`.
        """
        stamp = float(stamp)
        positions, worst = [], 0.0
        for name in self.names:
            stamps, values = self._stamps[name], self._values[name]
            if not stamps:
                return JointLookup(reason=f'no {name} received yet', waiting=not complete)
            first = bisect.bisect_right(stamps, stamp - margin) - 1
            if first < 0:
                return JointLookup(reason=f'no {name} sample {margin:g} s before the image '
                                          f'(the oldest is {stamps[0] - stamp:+.3f} s from it)')
            last = bisect.bisect_left(stamps, stamp + margin)
            if last == len(stamps):
                if not complete:
                    return JointLookup(reason=f'no {name} sample {margin:g} s after the image '
                                              'yet', waiting=True)
                if stamps[-1] < stamp:
                    return JointLookup(reason=f'no {name} sample after the image (the newest '
                                              f'is {stamps[-1] - stamp:+.3f} s from it)',
                                       waiting=True)
                last = len(stamps) - 1
            gap = max(stamp - stamps[first], stamps[last] - stamp)
            if gap > hold:
                return JointLookup(reason=f'{name} samples around the image are {gap:.3f} s '
                                          f'from it (hold {hold:g} s)', gap=gap)
            span = values[first:last + 1]
            change = max(span) - min(span)
            if change > epsilon:
                return JointLookup(reason=f'moving: {name} changed by {change:.2g} rad within '
                                          f'{margin:g} s of the image', gap=gap, moving=True)
            positions.append(values[first])
            worst = max(worst, gap)
        return JointLookup(positions=np.array(positions), gap=worst)

    @staticmethod
    def _at_rest(stamps, values, before, after, stamp, rest_hold, rest_epsilon,
                 after_newest=True):
        """Return the joint's value if it rests around `stamp` (see ``at``), else None."""
        if not rest_hold > 0.0 or before is None or (after is None and not after_newest):
            return None
        if after is not None:
            still = abs(values[after] - values[before]) <= rest_epsilon
            near = max(stamp - stamps[before], stamps[after] - stamp) <= rest_hold
        else:                        # newer than every sample: the newest two agree
            still = before > 0 and abs(values[before] - values[before - 1]) <= rest_epsilon
            near = stamp - stamps[before] <= rest_hold
        return values[before] if still and near else None

    def latest(self, now, max_age=0.0, wall_now=None, max_wall_age=0.0):
        """
        Return every joint's newest value (JointLookup), if none is older than `max_age`.

        Ages count from `now` [s] on the stamps' clock; `max_age` 0 accepts any age. With
        `wall_now` and `max_wall_age` (> 0) a joint older than `max_age` is still fresh while
        its newest message was received at most `max_wall_age` [s] of wall time before
        `wall_now` (see the module docstring); a joint with no receipt time is judged on the
        stamps' clock alone.
        """
        positions, worst = [], 0.0
        for name in self.names:
            stamps = self._stamps[name]
            if not stamps:
                return JointLookup(reason=f'no {name} received yet')
            age = float(now) - stamps[-1]
            if max_age > 0.0 and age > max_age:
                reason = f'{name} last received {age:.3f} s ago (limit {max_age:g} s)'
                received = self._received.get(name)
                if wall_now is None or received is None or not max_wall_age > 0.0:
                    return JointLookup(reason=reason, gap=age)
                wall_age = float(wall_now) - received
                if wall_age > max_wall_age:
                    return JointLookup(reason=f'{reason} and {wall_age:.3f} s of wall time '
                                              f'ago (limit {max_wall_age:g} s)', gap=age)
            positions.append(self._values[name][-1])
            worst = max(worst, age)
        return JointLookup(positions=np.array(positions), gap=worst)
