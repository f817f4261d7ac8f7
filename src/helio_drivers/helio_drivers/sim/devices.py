"""
The emulated devices hosted by the simulated world (issue 6, item 8).

The Dobot Magician and the Maestro servo controller run as ``helio_drivers.dobot_emulator``
and ``helio_drivers.maestro_emulator`` on pseudo-terminals (symlinked at the configured
paths) so that ``dobot_driver`` and ``servo_driver`` connect to them exactly as to hardware.
Their motion follows the world's simulated clock; the world reads the true joint positions
in-process: x = (dobot_j1, dobot_j2, dobot_j3, lens_yaw, lens_pitch) [rad].
"""

from dataclasses import dataclass
import math

from helio_drivers.dobot_emulator import DobotEmulator
from helio_drivers.maestro_emulator import MaestroEmulator
from helio_drivers.sim.build import BuiltJoints, ideal_build


@dataclass(frozen=True)
class DeviceSettings:
    """Ports, servo wiring and the arm's starting joints."""

    dobot_port: str = '/tmp/helio_sim_dobot'
    servo_port: str = '/tmp/helio_sim_servo'
    yaw_channel: int = 0
    pitch_channel: int = 1
    servo_us_per_rad: float = 2000.0 / math.pi
    servo_centre_us: float = 1500.0
    # The Maestro as the drivers' README sets it up (Min 500, Max 2500 us, start at the
    # centre), not a factory-new one (992..2000 us, pulses off).
    servo_min_us: float = 500.0
    servo_max_us: float = 2500.0
    initial_joints_deg: tuple = (0.0, 30.0, 30.0, 0.0)   # dobot j1..j4 [deg]
    # the servos start at their centre pulse: lens yaw = lens pitch = 0


class SimDevices:
    """Both emulators on their ptys, moving on the given clock."""

    def __init__(self, clock, settings=None, build=None):
        """
        Open the two pseudo-terminals and start the emulators' reader threads.

        `build` (``sim.build.Build``): the servos' true calibration and play, the Dobot's
        zero offsets and repeatability; default the ideal build (the settings' constants).
        """
        self.settings = settings or DeviceSettings()
        s = self.settings
        if build is None:
            build = ideal_build(None, s.servo_centre_us, s.servo_us_per_rad)
        self.build = build
        self._true = BuiltJoints(build, seed=build.seed)
        # the emulated Maestro turns its pulses into angles with the TRUE servos; it reports
        # the pulses, which the driver turns back with the nominal constants
        self.calibrations = (build.servo('lens_yaw').calibration(s.yaw_channel),
                             build.servo('lens_pitch').calibration(s.pitch_channel))
        self.dobot = DobotEmulator(port_path=s.dobot_port, clock=clock,
                                   initial_joints_deg=s.initial_joints_deg)
        try:
            self.servo = MaestroEmulator(port_path=s.servo_port, clock=clock,
                                         calibrations=self.calibrations,
                                         initial_pulse_us=s.servo_centre_us,
                                         min_pulse_us=s.servo_min_us,
                                         max_pulse_us=s.servo_max_us)
        except Exception:
            self.dobot.close()
            raise

    @property
    def ports(self):
        """Return the (dobot, servo) port paths the drivers should open."""
        return self.dobot.port_path, self.servo.port_path

    def joint_positions(self):
        """
        Return the TRUE x = (j1, j2, j3, lens_yaw, lens_pitch) [rad] at the clock's time.

        The build's (``BuiltJoints``): the Dobot's reported angles plus its zero offsets and
        scatter, the servos' angles through their play. Read it once per instant (the play
        and the scatter keep state).
        """
        return self._true.true_joints(self.dobot.joint_positions(),
                                      self.servo.joint_positions())

    def close(self):
        """Close both pseudo-terminals and stop the emulators."""
        self.dobot.close()
        self.servo.close()
