"""
A test's painting with the world's TRUE sun, through the real driver clients, in-process.

``TrueSunPainting`` hosts the simulated world with its emulated Dobot and Maestro on
pseudo-terminals, connects ``DobotClient`` and ``MaestroClient`` (the drivers' serial
libraries) to those ports and runs Algorithm 1 of the paper (``helio_control.dot_cycle``) on
a few dots: the lens moved so the focus lands on the dot at d_lp = 8.2 cm (Eqs 14-15 and the
rig's inverse kinematics), held while N_p (``helio_perception.thermal`` on the simulated
16UC1 image) is below its target, retreated by 3 cm until N_p is back to 0, then the next
dot. The world steps in lockstep with it, so a dot costs seconds of wall time.

It aims with the world's TRUE sun (``helio_drivers.sim.truth``): a test double of the
controller, for the tests that need a painted run quickly (the report's). The product
paints through the graph (``helio paint``); this was shipped as ``helio_control.sim_demo``
(the interim demo) until issue 32 retired it.
"""

import os

from helio_control.dot_cycle import CycleSettings, Decision, DotCycle
from helio_drivers.dobot_client import DobotClient
from helio_drivers.dobot_protocol import PtpMode
from helio_drivers.maestro_client import MaestroClient
from helio_drivers.sim.devices import DeviceSettings, SimDevices
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_perception.thermal import ThermalAnalyzer, ThermalConfig
import numpy as np

DEFAULT_DOTS = ((0.060, 0.060), (0.064, 0.060), (0.068, 0.060), (0.060, 0.064),
                (0.060, 0.068), (0.068, 0.068))


class TrueSunPainting:
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
        return true_sun_focus_joints(self.world, target_world, d_lp)

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
    def paint(self, dots, d_lp=0.082, retreat=0.03, settings=None):
        """Run Algorithm 1 (helio_control.dot_cycle) over `dots` (world x, y); return records."""
        records = []
        for number, dot in enumerate(dots, 1):
            self.move(self.joints_for(dot, d_lp))
            cycle = DotCycle(settings or CycleSettings())
            cycle.start_heating(self.world.time)
            decision = Decision.HEAT
            while decision is not Decision.NEXT:
                n_p, _ = self.next_thermal_np()
                decision = cycle.update(self.world.time, n_p)
                if decision is Decision.RETREAT:
                    self.move(self.joints_for(dot, d_lp + retreat))
            if cycle.outcome != 'charred':
                raise RuntimeError(f'dot {number}: N_p stayed at most {cycle.peak_n_p} for '
                                   f'{cycle.heating_time:.0f} s')
            records.append({'target': dot, 'heated_s': cycle.heating_time,
                            'cooled_s': cycle.cooling_time})
            self.log(f'dot {number}/{len(dots)} at ({dot[0] * 100:.1f}, {dot[1] * 100:.1f}) cm: '
                     f'N_p >= {cycle.settings.n_p_target} after {cycle.heating_time:.1f} s, '
                     f'back to 0 after {cycle.cooling_time:.1f} s (sim time '
                     f'{self.world.time:.1f} s)')
        return records
