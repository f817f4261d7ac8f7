"""
Thermal cameras as their datasheets describe them (issue 29, item 1): what a user knows.

The nominal values of each camera a helio rig may carry, in one place: the simulated world
builds its true camera from them (plus a radiometric error drawn within the stated accuracy:
``helio_drivers.sim.cameras``), and ``thermal_monitor`` takes its read-out cap from the
profile a user names. Neither side may read the other's truth; both read the datasheet.

- ``paper``: the camera of the paper (Sec. IV-B): reads up to 180.9 degC, the paper's
  pyrolysis threshold T_p; its field of view was not given, 45 deg is the footprint the
  simulated N_p target of 30 was tuned with. No flat-field freezes modelled (the paper's
  figures are comparable with it).
- ``lepton35_high_gain`` and ``lepton35_low_gain``: a FLIR Lepton 3.5 on a PureThermal
  board, radiometric (TLinear, 0.01 K resolution), as ``usb_cam`` publishes it with
  ``pixel_format:=mono16`` (V4L2 Y16: centikelvin counts, encoding ``mono16``). FLIR Lepton
  Engineering Datasheet (document 500-0659-00-09, rev. 203): 160 x 120 pixels, 57 deg
  horizontal field of view (Lepton 3.5, 71 deg diagonal), 8.7 Hz, thermal sensitivity
  < 50 mK; scene dynamic range -10 to 140 degC in high gain and -10 to 400 degC (typical;
  up to 450) in low gain; radiometric accuracy the greater of +-5 degC or 5 % in high gain,
  +-10 degC or 10 % in low gain (typical, 25 degC ambient). Automatic flat-field correction
  (FFC, datasheet p. 20): at start-up, every 3 minutes by default and after a camera
  temperature change of 1.5 K; it lasts nominally 23 frames at 26 Hz (0.9 s), during which
  the output repeats the last frame (the FFC state shows only in the telemetry rows, which
  the Y16 stream does not carry). Modelled as freezes of 0.3-1 s (issue 29).
"""

from dataclasses import dataclass
import math

KELVIN = 273.15


@dataclass(frozen=True)
class ThermalCameraSpec:
    """A thermal camera's nominal values (a datasheet's, or the paper's)."""

    width: int                       # [px]
    height: int                      # [px]
    horizontal_fov_deg: float        # [deg]
    frame_rate: float                # [Hz]
    floor: float                     # lowest reading [degC]
    cap: float                       # highest reading: hotter pixels read this [degC]
    netd: float                      # noise (NETD) [K]
    accuracy_abs: float              # radiometric accuracy: the greater of this [K] ...
    accuracy_rel: float              # ... and this share of the reading [-]
    encoding: str                    # the image encoding its driver publishes
    ffc_period: float                # flat-field correction every this [s] (0: none)
    ffc_freeze: tuple                # (shortest, longest) freeze of the frames [s]

    @property
    def horizontal_fov(self):
        """Return the horizontal field of view [rad]."""
        return math.radians(self.horizontal_fov_deg)

    def accuracy_at(self, temperature):
        """Return the stated radiometric accuracy at a reading of `temperature` [K]."""
        return max(self.accuracy_abs, self.accuracy_rel * abs(temperature))


PAPER = ThermalCameraSpec(
    width=160, height=120, horizontal_fov_deg=45.0, frame_rate=8.7, floor=-10.0,
    cap=180.9, netd=0.05, accuracy_abs=0.0, accuracy_rel=0.0, encoding='16UC1',
    ffc_period=0.0, ffc_freeze=(0.0, 0.0))
LEPTON35_HIGH_GAIN = ThermalCameraSpec(
    width=160, height=120, horizontal_fov_deg=57.0, frame_rate=8.7, floor=-10.0,
    cap=140.0, netd=0.05, accuracy_abs=5.0, accuracy_rel=0.05, encoding='mono16',
    ffc_period=180.0, ffc_freeze=(0.3, 1.0))
LEPTON35_LOW_GAIN = ThermalCameraSpec(
    width=160, height=120, horizontal_fov_deg=57.0, frame_rate=8.7, floor=-10.0,
    cap=400.0, netd=0.05, accuracy_abs=10.0, accuracy_rel=0.10, encoding='mono16',
    ffc_period=180.0, ffc_freeze=(0.3, 1.0))
THERMAL_CAMERAS = {'paper': PAPER, 'lepton35_high_gain': LEPTON35_HIGH_GAIN,
                   'lepton35_low_gain': LEPTON35_LOW_GAIN}


def thermal_camera(name):
    """Return the ThermalCameraSpec called `name`; ValueError naming the known ones."""
    try:
        return THERMAL_CAMERAS[name]
    except KeyError:
        raise ValueError(f'unknown thermal camera {name!r}: known are '
                         f'{", ".join(sorted(THERMAL_CAMERAS))}') from None
