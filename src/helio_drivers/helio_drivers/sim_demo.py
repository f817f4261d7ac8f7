"""
Interim demo: paint a handful of dots in the simulated world through the real driver code.

``python -m helio_drivers.sim_demo --out DIR`` starts the simulated world with its emulated
Dobot and Maestro on pseudo-terminals, connects ``DobotClient`` and ``MaestroClient`` (the
drivers' serial libraries) to those ports and runs Algorithm 1 of the paper on a few dots:
move the lens so the focus lands on the dot at d_lp = 8.2 cm (Eqs 14-15 and the rig's inverse
kinematics), hold it while N_p (thermal pixels at the 180.9 degC read-out cap, computed by
``helio_perception.thermal`` from the simulated 16UC1 thermal image) is below 30, retreat
by 3 cm and wait until N_p is back to 0, then the next dot. At the end it writes
``canvas.png`` and ``dots.csv`` (the charred dots' ground truth) into DIR and prints the
placement error of every dot.

SHORTCUT (clearly not the product): the demo aims with the simulated world's TRUE sun
direction. In the real graph the sun comes from ``sun_estimator`` (Eqs 11-12) and the lens
pose from ``lens_planner``; those are other issues. Everything else is as on hardware: the
motion goes over the serial protocol, the world reads where the emulated arm truly is, and
the charring is judged from the thermal image only.

The world steps in lockstep with the demo (simulated time runs as fast as the machine
allows), so the run is deterministic and takes well under a minute of wall time per dot.
"""

import argparse
import math
import os
import sys
import tempfile
import time

from helio_drivers.dobot_client import DobotClient
from helio_drivers.dobot_protocol import PtpMode
from helio_drivers.maestro_client import MaestroClient
from helio_drivers.sim_devices import DeviceSettings, SimDevices
from helio_drivers.sim_world import SimSettings, SimWorld
from helio_optics.geometry import transform_points
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
from helio_optics.rig_kinematics import RigParameters
from helio_perception.thermal import ThermalAnalyzer, ThermalConfig
import numpy as np

DEFAULT_DOTS = ((0.060, 0.060), (0.064, 0.060), (0.068, 0.060), (0.060, 0.064),
                (0.060, 0.068), (0.068, 0.068))


class Demo:
    """The world, its devices and the two driver clients, stepped in lockstep."""

    def __init__(self, port_dir, settings=None, rig_parameters=None, log=print):
        """Build the world, host the emulators in `port_dir`, connect the clients."""
        self.log = log
        self.world = SimWorld(settings or SimSettings(), rig_parameters)
        device_settings = DeviceSettings(dobot_port=os.path.join(port_dir, 'dobot'),
                                         servo_port=os.path.join(port_dir, 'servo'))
        self.devices = SimDevices(self.world.clock, device_settings)
        self.world.attach_joint_source(self.devices.joint_positions)
        self.dobot = DobotClient(device_settings.dobot_port)
        self.servo = MaestroClient(device_settings.servo_port)
        self.dobot.connect()
        self.servo.connect()
        self.log(f'emulated Dobot on {self.devices.ports[0]}, Maestro on {self.devices.ports[1]}')
        self._next_frame = 0.0
        cap = self.world.settings.thermal.cap   # T_p taken as the camera cap (Sec. IV-B)
        self.thermal = ThermalAnalyzer(ThermalConfig(threshold=cap, camera_cap=cap))

    def close(self):
        """Disconnect the clients and close the emulators."""
        self.dobot.close()
        self.servo.close()
        self.devices.close()

    # ------------------------------------------------------------------ motion
    def joints_for(self, target_world, d_lp):
        """SHORTCUT: joints focusing the TRUE sun on `target_world` at `d_lp` (Eqs 14-15)."""
        world = self.world
        s0_robot = world.sun.ray_robot(world.clock.datetime())
        target = transform_points(world.T_robot_world, [target_world[0], target_world[1], 0.0])
        lens = world.rig.lens_pose_for_target(target, s0_robot, d_lp)
        if lens.x is None:
            raise RuntimeError(f'dot {target_world} unreachable at d_lp {d_lp}: {lens.reason}')
        return lens.x

    def move(self, x, timeout=30.0):
        """Send x to both devices over serial and step the world until both arrived."""
        index = self.dobot.move(PtpMode.MOVJ_ANGLE, (x[0], x[1], x[2], 0.0))
        for calibration, angle in zip(self.devices.calibrations, (x[3], x[4])):
            self.servo.set_target(calibration.channel, round(4.0 * calibration.pulse_us(angle)))
        end = self.world.time + timeout
        while self.world.time < end:
            for _ in range(4):
                self.world.step()
            if self.dobot.executed_index() >= index and not self.servo.moving():
                return
        raise RuntimeError(f'move to {np.round(x, 4)} not finished within {timeout} s simulated')

    # ------------------------------------------------------------------ sensing
    def next_thermal_np(self, rate=8.7):
        """Step to the next thermal frame (8.7 Hz simulated) and return (N_p, T_max)."""
        while self.world.time + 1e-9 < self._next_frame:
            self.world.step()
        self._next_frame = self.world.time + 1.0 / rate
        stats = self.thermal.statistics(self.world.thermal_image(), '16UC1')  # thermal_monitor
        return stats.n_p, stats.t_max

    # ------------------------------------------------------------------ Algorithm 1
    def paint(self, dots, d_lp=0.082, retreat=0.03, np_threshold=30, hold_timeout=90.0):
        """Run Algorithm 1 over `dots` (world x, y); return one record per dot."""
        records = []
        for number, dot in enumerate(dots, 1):
            self.move(self.joints_for(dot, d_lp))
            start = self.world.time
            n_p, t_max = self.next_thermal_np()
            while n_p < np_threshold:                     # lines 6-9: heat at d_lp
                if self.world.time - start > hold_timeout:
                    raise RuntimeError(f'dot {number}: N_p stayed {n_p} for {hold_timeout} s')
                n_p, t_max = self.next_thermal_np()
            heated = self.world.time - start
            self.move(self.joints_for(dot, d_lp + retreat))
            retreated = self.world.time
            while n_p > 0:                                # lines 10-13: retreat until N_p = 0
                if self.world.time - retreated > hold_timeout:
                    raise RuntimeError(f'dot {number}: N_p still {n_p} {hold_timeout} s after '
                                       'the retreat')
                n_p, t_max = self.next_thermal_np()
            records.append({'target': dot, 'heated_s': heated,
                            'cooled_s': self.world.time - start - heated})
            self.log(f'dot {number}/{len(dots)} at ({dot[0] * 100:.1f}, {dot[1] * 100:.1f}) cm: '
                     f'N_p >= {np_threshold} after {heated:.1f} s, back to 0 after '
                     f'{records[-1]["cooled_s"]:.1f} s (sim time {self.world.time:.1f} s)')
        return records


def match_dots(targets, charred):
    """Pair every target with the nearest charred dot: list of (target, dot or None, error)."""
    pairs = []
    for target in targets:
        best, error = None, math.inf
        for dot in charred:
            distance = math.hypot(dot.x - target[0], dot.y - target[1])
            if distance < error:
                best, error = dot, distance
        pairs.append((target, best, error))
    return pairs


def main(argv=None):
    """Run the demo (see the module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', required=True, help='directory for canvas.png and dots.csv')
    parser.add_argument('--dots', type=int, default=len(DEFAULT_DOTS),
                        help=f'how many of the {len(DEFAULT_DOTS)} preset dots to paint')
    parser.add_argument('--rig', default=None, help='rig YAML (default: helio_optics config)')
    args = parser.parse_args(argv)
    if not 1 <= args.dots <= len(DEFAULT_DOTS):
        parser.error(f'--dots must be in 1..{len(DEFAULT_DOTS)}')
    rig_file = args.rig or default_rig_file()
    rig = load_rig_parameters(rig_file) if rig_file else RigParameters()
    print(f'[sim_demo] rig geometry from {rig_file or "built-in defaults"}')
    print('[sim_demo] SHORTCUT: aiming with the simulated TRUE sun (the sun estimator and lens '
          'planner are not part of this demo)')
    wall = time.monotonic()
    with tempfile.TemporaryDirectory(prefix='helio_demo_') as port_dir:
        demo = Demo(port_dir, rig_parameters=rig, log=lambda m: print(f'[sim_demo] {m}'))
        try:
            targets = DEFAULT_DOTS[:args.dots]
            demo.paint(targets)
            png, csv = demo.world.write_outputs(args.out)
            charred = demo.world.charred_dots()
        finally:
            demo.close()
    errors = []
    for target, dot, error in match_dots(targets, charred):
        if dot is None:
            print(f'[sim_demo] target ({target[0]:.4f}, {target[1]:.4f}) m: no charred dot')
            continue
        errors.append(error)
        print(f'[sim_demo] target ({target[0]:.4f}, {target[1]:.4f}) m -> dot ({dot.x:.4f}, '
              f'{dot.y:.4f}) m, error {error * 1e3:.2f} mm, diameter {dot.diameter * 1e3:.2f} mm')
    print(f'[sim_demo] {len(charred)} charred dots for {len(targets)} targets; mean placement '
          f'error {np.mean(errors) * 1e3 if errors else float("nan"):.2f} mm; '
          f'{time.monotonic() - wall:.0f} s wall')
    print(f'[sim_demo] wrote {png} and {csv}')
    return 0 if len(errors) == len(targets) else 1


if __name__ == '__main__':
    sys.exit(main())
