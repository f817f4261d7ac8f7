"""
Which drivers' joint states stopped, as the painter can tell on the wall clock.

A driver polls its device and publishes ``joint_states`` at a steady wall rate (20 Hz by
default); a driver whose joint states stop for ``device_silence`` while the lens heats the
wood is a device fault, and the painter retreats (issue 13). The painter can only hear what
its own process gets to read: a painter that was not running for a while (starved of the
CPU by other work on the machine, stopped, its host paused) finds every driver "silent" for
as long as it was away, and its first check after the pause can run before it has read the
joint states that queued meanwhile. So the silence is counted only over time in which the
watcher itself was running: a steady tick (``tick``, every few tens of milliseconds) that
comes much later than its period says the process was away, and the silence is counted
again from then. A driver that is really silent is then reported at most ``device_silence``
after the watcher came back.

``DeviceFaults`` adds the drivers' own word (their latched ``dobot/status``,
``servo/status``: not connected, alarms) and tells when a fault is new, so the painter can
wake its heating loop at once. Pure Python: no rclpy. Times in seconds on one monotonic
clock.
"""

import math

# the device whose driver publishes a joint of this name prefix (helio_optics.rig_kinematics'
# JOINT_NAMES: dobot_j1..j4 from the Dobot driver, lens_yaw and lens_pitch from the servos')
DEVICE_OF_PREFIX = {'dobot_': 'dobot', 'lens_': 'servo'}


def device_of(joint_names):
    """Return the device ('dobot', 'servo') whose driver publishes `joint_names`, or ''."""
    for prefix, device in DEVICE_OF_PREFIX.items():
        if any(str(name).startswith(prefix) for name in joint_names):
            return device
    return ''


class DriverSilence:
    """The drivers whose joint states stopped, not counting the watcher's own pauses."""

    def __init__(self, silence=1.0, pause=0.25):
        """
        Report a driver after `silence` [s] without joint states.

        `pause` [s]: a gap between two ticks longer than this means the watcher was not
        running; it must exceed the tick period and its ordinary lateness.
        """
        if not (silence > 0.0 and pause > 0.0):
            raise ValueError(f'silence and pause must be > 0 s, got {silence} and {pause}')
        self.silence, self.pause = float(silence), float(pause)
        self._heard = {}                    # device -> time of its last joint state
        self._tick = None
        self._back = -math.inf              # when the watcher last came back from a pause
        self.pauses = 0                     # pauses of the watcher seen so far

    def heard(self, device, now):
        """Note joint states from `device` at `now`."""
        self._heard[device] = float(now)

    def heard_joints(self, joint_names, now):
        """Note joint states of `joint_names` at `now` (from their driver, ``device_of``)."""
        device = device_of(joint_names)
        if device:
            self.heard(device, now)

    def tick(self, now):
        """Note that the watcher runs at `now`; return the pause it just came back from, or 0."""
        now = float(now)
        gap = 0.0 if self._tick is None else now - self._tick
        self._tick = now
        if gap > self.pause:
            self._back = now
            self.pauses += 1
            return gap
        return 0.0

    def silent(self, now):
        """Return {device: seconds since its last joint state} of the drivers now silent."""
        now = float(now)
        return {device: now - heard for device, heard in self._heard.items()
                if now - max(heard, self._back) > self.silence}

    def faults(self, now):
        """Return [(device, why)] of the drivers silent `now`, by device."""
        return [(device, f'{device} silent for {seconds:.1f} s (no joint states: driver '
                         'stopped?)') for device, seconds in sorted(self.silent(now).items())]


class DeviceFaults:
    """
    The devices' faults: each driver's status (not connected, alarms), then its silence.

    ``status`` takes a driver's DeviceStatus fields, ``joint_states`` the names of joint
    states heard, ``watch`` the watcher's steady tick (``DriverSilence.tick``); a fault not
    reported before (a new status fault, a driver newly silent) calls `wake`.
    """

    def __init__(self, silence, pause, wake=lambda: None):
        """Count a driver silent after `silence` [s] (``DriverSilence``, `pause` [s])."""
        self.wake = wake
        self.drivers = DriverSilence(silence, pause)
        self.reported = {}              # device -> why, from its status
        self._silent_seen = set()       # the drivers silent at the last watch

    def status(self, device, connected, message, alarms):
        """Take a device's status; wake on a fault not reported before."""
        problem = ''
        if not connected:
            problem = f'{device} not connected ({message})'
        elif alarms:
            problem = f'{device} alarm: {", ".join(alarms)}'
        if not problem:
            self.reported.pop(device, None)
            return
        new = device not in self.reported
        self.reported[device] = problem
        if new:
            self.wake()

    def joint_states(self, joint_names, now):
        """Note joint states of `joint_names` heard at `now`."""
        self.drivers.heard_joints(joint_names, now)

    def watch(self, now):
        """Tick at `now`, wake on a driver newly silent; return the pause come back from [s]."""
        pause = self.drivers.tick(now)
        silent = set(self.drivers.silent(now))
        if silent - self._silent_seen:
            self.wake()
        self._silent_seen = silent
        return pause

    def faults(self, now, devices=None):
        """Return [(device, why)]: the reported faults, then the silent drivers (of `devices`)."""
        return [(device, why) for device, why in
                list(self.reported.items()) + self.drivers.faults(now)
                if devices is None or device in devices]

    def sentence(self, now, devices=None):
        """Return the faults of `devices` (None: all) `now` in one sentence, '' if none."""
        return '; '.join(why for _, why in self.faults(now, devices))
