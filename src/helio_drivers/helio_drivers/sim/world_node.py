"""
Node sim_world: the simulated world (issue 6), the embedded default when there is no rig.

It hosts the emulated Dobot and Maestro on pseudo-terminals (paths are parameters, logged at
start) so that ``dobot_driver`` and ``servo_driver`` connect to them as to hardware, steps
the world (``helio_drivers.sim.world.SimWorld``) on its own thread at ``real_time_factor``
and publishes:

- ``/clock`` (rosgraph_msgs/Clock, global): simulated time; run every other node with
  ``use_sim_time:=true``;
- ``rgb/image_raw`` (rgb8) and ``rgb/camera_info`` at ``rgb_rate`` of simulated time;
  ``thermal/image_raw`` (16UC1 centikelvin) and ``thermal/camera_info`` at
  ``thermal_rate`` (sensor-data QoS); each image is rendered only while someone
  subscribes to it (the camera_info always goes out); an RGB frame's scene is taken at its
  stamp and the frame developed on a thread of its own (``rgb_thread``) while the world
  steps on, published before the world passes the stamp of the frame after next;
- ``sim/canvas`` (mono8 top view of the char map, 255 bare wood) at ``canvas_rate``, while
  someone subscribes to it;
- the world's ground truth for tests and recordings, under ``sim/truth/`` (reliable,
  transient local, every ``truth_period``): ``sun_direction`` (geometry_msgs/Vector3Stamped,
  the true sun ray s0 in the robot frame), ``world_pose`` (geometry_msgs/PoseStamped, the
  true T_robot_world) and ``spot_centre`` (geometry_msgs/PointStamped, world frame: the
  power centre of the concentrated light on the panel, NaN when the lens focuses nothing);
  ``rgb_pose`` (geometry_msgs/PoseStamped, world frame: the true pose of the rgb optical
  frame, with each RGB image and its stamp); ``light`` (helio_msgs/LightTruth: the light's
  power centre, the peak irradiance on the panel and the DNI, to tell whether the focus is
  on the wood); ``build`` (std_msgs/String, once: the rig as built, ``sim.build.Build``
  as YAML, the same as ``build.yaml`` beside ``canvas.png``); ``rgb_camera_info``
  (sensor_msgs/CameraInfo, once: the RGB camera's TRUE intrinsics, which its images are
  rendered with; ``rgb/camera_info`` holds the nominal ones, or K = 0 with
  ``rgb_uncalibrated``). A ChArUco calibration board lies on the panel when ``board_pose``
  is set (issue 29).
  No controller node subscribes to them: the controller must find the sun and the marker
  itself (a test enforces that).

Set while it runs (``ros2 param set``), to play the outer edge of the world in tests and demos;
every other parameter is read-only after start:

- ``cloud_schedule``: the flat (start_s, end_s, attenuation) triples, simulated seconds since
  the start, replace the schedule (e.g. a complete cloud from now for 30 s);
- ``real_time_factor``: the pace from the next step on (e.g. as fast as possible through a
  long heating, real time to watch a retreat);
- ``unplugged``: device names (``dobot``, ``servo``) whose USB cable is out: their
  pseudo-terminal is closed and its link removed, as on an unplug; taking a name out plugs
  it back in (a new pty behind the same path). ``thermal_camera`` and ``rgb_camera``: that
  camera publishes nothing (image and camera_info) until it is plugged back in, as a USB
  camera that was pulled out or froze.

Lockstep (issue 31): a world faster than real time holds its simulated time at most
``lockstep_lead`` ahead of the newest stamp on ``lockstep_topic`` (``thermal/stats``: the
thermal monitor's answer to each thermal image) and on ``lockstep_spot_topic`` (``spot``: the
spot detector's answer to each RGB image), and, with ``lockstep_joint_states``, at most
``lockstep_joint_lead`` ahead of the newest ``joint_states`` of each driver (each
publisher's set of joint names is a source; the drivers read their device on every /clock
tick and stamp on the node clock), and at most ``lockstep_heartbeat_lead`` ahead of the
newest stamp on each of ``lockstep_heartbeats`` (``painter/heartbeat`` and, while the lens
planner holds the lens at the heating distance, ``lens/heating``; both beat on the node
clock: a painter starved of the CPU cannot leave the lens on the wood for simulated seconds,
and a beater that is merely slow never runs out its lease, node_kit.focus_lease). Real
sensors and devices never run ahead of the software reading them, and so the graph's
decisions depend on simulated time whatever the machine's load does to the ratio of the
clocks: otherwise, on 2 busy cores, the painter's fire-safety watchdog (0.5 s of simulated
time without thermal data) would trip on a world that merely ran ahead, and images would
find no joint states within their tolerance. A source that answered nothing newer for
``lockstep_timeout`` of wall time (stopped, unplugged) is left behind, so it cannot freeze the
world; the world then runs at ``lockstep_fallback_factor`` (real time), not as fast as it
can. While held, the world sends ``/clock`` and the last frame of the awaited camera again
every ``lockstep_resend``, for a source that missed them.

Topic names are relative, so the world runs under a namespace with its rig's nodes.
At shutdown it writes ``canvas.png`` (the burnt panel as a person sees it),
``canvas_mask.png`` (the char map) and ``dots.csv`` into ``output_dir`` (if set).
"""

import collections
import concurrent.futures
from dataclasses import dataclass
import threading
import time

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, PoseStamped, Vector3, Vector3Stamped
from helio_drivers.sim.build import build_from_name, BUILDS
from helio_drivers.sim.clock import Lockstep, Pacer
from helio_drivers.sim.devices import DeviceSettings, SimDevices
from helio_drivers.sim.warm_up import warm_up
from helio_drivers.sim.world import flat_settings, settings_from_flat, SimSettings, SimWorld
from helio_msgs.msg import LightTruth, SpotObservation, ThermalStats
from helio_optics.node_kit import topics
from helio_optics.node_kit.conversions import array_to_point, camera_info_from_camera
from helio_optics.node_kit.conversions import matrix_to_pose, restamped
from helio_optics.node_kit.conversions import serialized_image, serialized_pose_stamped
from helio_optics.node_kit.conversions import stamp_to_seconds
from helio_optics.node_kit.deployment import rig_file_or_default, RIG_FILE_PARAMETER
from helio_optics.node_kit.focus_lease import CLEAR, HEATING_TOPIC
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.qos import LATCHED
from helio_optics.node_kit.runner import run_node
from helio_optics.rig_kinematics import load_rig_parameters
from rcl_interfaces.msg import SetParametersResult
import rclpy
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from rclpy.qos import ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image, JointState
from std_msgs.msg import Header, String
import yaml


@dataclass(frozen=True)
class CameraTopics:
    """A camera's publishers, its image encoding and frame id, its CameraInfo serialised."""

    image: object
    info: object
    encoding: str
    frame_id: str
    info_bytes: bytes


TRUTH_QOS = LATCHED

# name: (description, minimum, maximum); ranges only for numbers.
PARAMETER_DOCS = {
    'latitude_deg': ('site latitude, degrees north (pysolar)', -90.0, 90.0),
    'longitude_deg': ('site longitude, degrees east', -180.0, 360.0),
    'elevation': ('site height above sea level [m]', -500.0, 9000.0),
    'start_time': ('simulated start, ISO 8601 with UTC offset', None, None),
    'robot_heading_deg': ('HIDDEN truth: compass azimuth of the robot x axis, clockwise from '
                          'north [deg]; the estimator must find it', -360.0, 360.0),
    'dni': ('clear-sky direct normal irradiance [W/m^2]', 0.0, 1400.0),
    'cloud_schedule': ('clouds as flat triples start_s, end_s, attenuation (DNI factor)',
                       None, None),
    'random_clouds': ('add the seeded random cloud process', None, None),
    'cloud_seed': ('seed of the random clouds', 0, 2 ** 31 - 1),
    'cloud_mean_clear': ('mean clear spell of the random clouds [s]', 1.0, 1e6),
    'cloud_mean_cloudy': ('mean cloudy spell of the random clouds [s]', 0.1, 1e6),
    'cloud_attenuation_range': ('DNI factor range of random clouds [min, max]', None, None),
    'step': ('simulated time per world step [s]', 0.005, 0.5),
    'seed': ('seed of the camera noise and ray sampling', 0, 2 ** 31 - 1),
    'lens.focal_length': ('world lens focal length f = r_s/(n-1) [m]', 0.02, 0.5),
    'lens.refractive_index': ('world lens index at 587.6 nm (design)', 1.01, 2.5),
    'lens.thickness': ('world lens plate thickness [m]', 0.0, 0.01),
    'lens.aperture_diameter': ('world lens clear aperture [m] (tuned, SIMULATION.md)',
                               0.005, 0.3),
    'lens.transmission': ('world lens transmission kappa [-]', 0.01, 1.0),
    'lens.facets': ("world lens facets: 'corrected' or 'spherical' (Eq 3)", None, None),
    'flux_rays': ('rays traced per spectral band set', 100, 10 ** 7),
    'flux_rays_moving': ('rays per band traced instead while the lens keeps moving (same '
                         'power, noisier spot)', 100, 10 ** 7),
    'beam_spread': ('world lens optical errors, Gaussian sigma per ray [rad]', 0.0, 0.1),
    'wood.density': ('wood density [kg/m^3]', 50.0, 2000.0),
    'wood.conductivity': ('wood conductivity across the grain (world y, depth) [W/(m K)]',
                          0.01, 5.0),
    'wood.conductivity_along_grain': ('wood conductivity along the face grain (world x) '
                                      '[W/(m K)]', 0.01, 5.0),
    'wood.specific_heat': ('wood specific heat [J/(kg K)]', 100.0, 5000.0),
    'wood.thickness': ('panel thickness [m]', 0.0005, 0.1),
    'wood.absorptance_wood': ('solar absorptance of bare wood [-]', 0.0, 1.0),
    'wood.absorptance_char': ('solar absorptance of char [-]', 0.0, 1.0),
    'wood.emissivity': ('thermal emissivity of the surface [-]', 0.0, 1.0),
    'wood.convection_top': ('surface heat transfer coefficient [W/(m^2 K)]', 0.0, 1000.0),
    'wood.convection_back': ('back face heat transfer coefficient [W/(m^2 K)]', 0.0, 1e6),
    'wood.ambient': ('air and initial panel temperature [degC]', -40.0, 60.0),
    'wood.pyrolysis_temperature': ('T_p: no charring below [degC]', 100.0, 600.0),
    'wood.char_preexponential': ('char rate pre-exponential factor [1/s]', 0.0, 1e20),
    'wood.char_activation_energy': ('char rate activation energy [J/mol]', 0.0, 1e6),
    'wood.charred_fraction': ('char fraction counted as charred [-]', 0.0, 1.0),
    'wood.moisture_content': ('water per dry wood mass [-]', 0.0, 0.5),
    'wood.latent_heat': ('latent heat of the water [J/kg]', 0.0, 1e7),
    'wood.boiling_temperature': ('where the water evaporates [degC]', 50.0, 200.0),
    'wood.heat_of_pyrolysis': ('heat taken per kg of wood pyrolysed (endothermic) [J/kg]',
                               0.0, 1e7),
    'grid.fine_cell': ('lateral cell and char pixel size near the spot [m]', 2e-5, 2e-3),
    'grid.fine_half_width': ('half side of the fine region [m]', 1e-3, 0.05),
    'grid.half_width': ('half side of the heat patch [m]', 2e-3, 0.2),
    'grid.lateral_growth': ('growth ratio of coarse cells [-]', 1.0, 3.0),
    'grid.top_layer': ('surface layer thickness [m]', 5e-6, 1e-3),
    'grid.depth_growth': ('growth ratio of layers with depth [-]', 1.0, 3.0),
    'grid.recentre_margin': ('re-centre the patch this close to the fine edge [m]', 0.0, 0.05),
    'panel_extent': ('panel x_min, x_max, y_min, y_max in the world frame [m]', None, None),
    'marker_side': ('ArUco marker black square side [m]', 0.0, 0.5),
    'marker_id': ('ArUco marker id', 0, 1000),
    'marker_dictionary': ('ArUco dictionary name', None, None),
    'marker_print_reflectance': ("the marker print's linear reflectance [ink, paper] [-]",
                                 None, None),
    'board_pose': ('a printed ChArUco calibration board on the panel: its centre x, y [m] and '
                   'yaw [rad] in the world frame (empty: none)', None, None),
    'board_squares': ('the board: squares (columns, rows)', None, None),
    'board_square': ("the board's square side [m]", 0.002, 0.2),
    'board_marker': ("the board's marker side [m]", 0.001, 0.2),
    'board_dictionary': ("the board's ArUco dictionary name", None, None),
    'rgb.width': ('RGB image width [px]', 16, 4096),
    'rgb.height': ('RGB image height [px]', 16, 4096),
    'rgb.horizontal_fov': ('RGB horizontal field of view [rad]', 0.1, 3.0),
    'rgb.supersample': ('RGB sub-pixel rays per pixel side', 1, 8),
    'rgb.exposure': ("sunlit white paper's share of the RGB sensor's full scale, linear [-]",
                     0.001, 100.0),
    'rgb.diffuse_fraction': ('sky light relative to the clear direct sun; clouds leave it [-]',
                             0.0, 1.0),
    'rgb.blur_sigma': ('RGB optical blur, in linear light [px]', 0.0, 10.0),
    'rgb.vignetting': ('RGB light lost at the image corners (cos^4 fall-off) [-]', 0.0, 0.95),
    'rgb.read_noise': ('RGB read noise [fraction of full scale]', 0.0, 0.2),
    'rgb.full_well_electrons': ('RGB full well: shot noise variance = signal / it (0: none) '
                                '[electrons]', 0.0, 1e7),
    'rgb.adc_bits': ('RGB linear read-out depth before the tone curve [bits]', 8, 16),
    'rgb.tone_curve': ("RGB tone curve: 'srgb' (webcams) or 'linear' [-]", None, None),
    'rgb.bayer': ('RGB through an RGGB Bayer mosaic and demosaicing [-]', None, None),
    'rgb.jpeg_quality': ('RGB JPEG compression quality, 1-100 (0: none) [-]', 0, 100),
    'rgb.exact_read_out': ('RGB noise through the exact ADC and tone table, not linearised '
                           'about each pixel (slower; Bayer sensors always) [-]', None, None),
    'thermal.width': ('thermal image width [px]', 8, 2048),
    'thermal.height': ('thermal image height [px]', 8, 2048),
    'thermal.horizontal_fov': ('thermal horizontal field of view [rad]', 0.1, 3.0),
    'thermal.cap': ('thermal read-out upper limit [degC]', 0.0, 2000.0),
    'thermal.floor': ('thermal read-out lower limit [degC]', -273.0, 100.0),
    'thermal.noise_sigma': ('thermal noise (NETD) [K]', 0.0, 10.0),
    'thermal.encoding': ("thermal image encoding, centikelvin: '16UC1' or 'mono16' (usb_cam's "
                         'Y16)', None, None),
    'thermal.offset_error': ("the thermal camera's true radiometric offset [K]", -100.0,
                             100.0),
    'thermal.gain_error': ("the thermal camera's true radiometric gain error: reading = "
                           'T (1 + gain_error) + offset_error [-]', -0.5, 0.5),
    'thermal.ffc_period': ('a flat-field correction freezes the thermal output every this '
                           '(0: never) [s sim]', 0.0, 1e6),
    'thermal.ffc_freeze_min': ('shortest flat-field freeze [s sim]', 0.0, 60.0),
    'thermal.ffc_freeze_max': ('longest flat-field freeze [s sim]', 0.0, 60.0),
    'thermal_profile': ("HIDDEN truth: a datasheet's thermal camera in place of thermal.* "
                        "('paper', 'lepton35_high_gain', 'lepton35_low_gain'; its radiometric "
                        "error drawn from seed; '': thermal.* as given)", None, None),
    'thermal_ffc_period': ("the thermal camera's flat-field correction period, replacing its "
                           "own (< 0: the camera's; tests: every few seconds) [s sim]", -1.0,
                           1e6),
}


class SimWorldNode(Node):
    """Thin node around SimWorld and SimDevices; see the module docstring."""

    # the parameters that can change at run time
    RUNTIME = ('cloud_schedule', 'unplugged', 'real_time_factor', 'thermal_stuck',
               'truth_period')
    CAMERAS = ('rgb_camera', 'thermal_camera')   # `unplugged` names of the cameras
    RGB_FRAMES_IN_FLIGHT = 2     # on the RGB thread, at most (rgb_thread)

    def __init__(self, **kwargs):
        """Declare parameters, build the world and the devices, start the stepping thread."""
        super().__init__('sim_world', **kwargs)
        flat = {}
        for name, default in flat_settings(SimSettings()).items():
            flat[name] = self._declare(name, default)
        self.settings = settings_from_flat(flat)
        self.real_time_factor = declare(
            self, 'real_time_factor', 1.0,
            'simulated seconds per wall second (0: as fast as possible)', 0.0, 1000.0,
            dynamic=True)
        self.rgb_rate = declare(self, 'rgb_rate', 5.0, 'RGB frame rate [Hz sim]', 0.0, 120.0)
        self.thermal_rate = declare(self, 'thermal_rate', 8.7,
                                    'thermal frame rate [Hz sim]', 0.0, 120.0)
        self.canvas_rate = declare(self, 'canvas_rate', 0.5,
                                   'sim/canvas rate [Hz sim]', 0.0, 10.0)
        self.truth_period = declare(self, 'truth_period', 1.0,
                                    'period of the sim/truth/* topics (a test times an event '
                                    'finer around it) [s sim]', 0.01, 3600.0, dynamic=True)
        self.output_dir = declare(self, 'output_dir', '',
                                  'write canvas.png, canvas_mask.png and dots.csv here at '
                                  'shutdown')
        rig_file = rig_file_or_default(declare(
            self, RIG_FILE_PARAMETER, '',
            "the world's TRUE rig geometry YAML (empty: the workspace's config/rig.yaml)"))
        devices = DeviceSettings(
            dobot_port=declare(self, 'dobot_port', DeviceSettings.dobot_port,
                               'pty symlink of the emulated Dobot'),
            servo_port=declare(self, 'servo_port', DeviceSettings.servo_port,
                               'pty symlink of the emulated Maestro'),
            yaw_channel=declare(self, 'servo.yaw_channel', 0, 'Maestro channel of lens_yaw',
                                0, 23),
            pitch_channel=declare(self, 'servo.pitch_channel', 1,
                                  'Maestro channel of lens_pitch', 0, 23),
            servo_us_per_rad=declare(self, 'servo.us_per_rad', DeviceSettings.servo_us_per_rad,
                                     'servo pulse per joint radian [us/rad]', 1.0, 10000.0),
            servo_centre_us=declare(self, 'servo.centre_us', DeviceSettings.servo_centre_us,
                                    'servo pulse at joint angle 0 [us]', 500.0, 2500.0),
            initial_joints_deg=tuple(declare(
                self, 'initial_joints_deg', list(DeviceSettings.initial_joints_deg),
                'Dobot j1..j4 at start [deg]')))
        build_name = declare(
            self, 'build', 'ideal',
            "HIDDEN truth: the rig as built. 'ideal': exactly the rig file and the nominal "
            "servo constants; 'drawn': a build drawn from a 3D-printed rig's tolerances "
            '(sim/build.py, SIMULATION.md), published only on sim/truth/build and written '
            'as build.yaml', choices=BUILDS)
        build_seed = declare(self, 'build_seed', 0, 'seed of the drawn build', 0, 2 ** 31 - 1)
        build_scale = declare(self, 'build_scale', 1.0,
                              "the drawn build's tolerances over a 3D-printed rig's (1/3: a "
                              'careful build) [-]', 0.0, 3.0)
        self.build = build_from_name(build_name, load_rig_parameters(rig_file), build_seed,
                                     build_scale, devices.servo_centre_us,
                                     devices.servo_us_per_rad)
        self.world = SimWorld(self.settings, build=self.build)
        # every kernel's machine code loaded (or compiled) now, before the emulated devices
        # answer: numba loads it at a kernel's first call, and those loads, at the first
        # step or the first move, held the interpreter lock longer than the drivers' 0.1 s
        # serial timeouts (the servo driver reported its link lost at the graph's first move)
        started = time.perf_counter()
        ready = warm_up(steps=2, settings=self.settings, build=self.build)
        self.get_logger().info(f'{len(ready)} compiled kernels ready in '
                               f'{time.perf_counter() - started:.2f} s')
        self.devices = SimDevices(self.world.clock, devices, self.build)
        self.world.attach_joint_source(self.devices.joint_positions)
        dobot_port, servo_port = self.devices.ports
        self.get_logger().info(
            f'emulated Dobot on {dobot_port} ({self.devices.dobot.device_name}), Maestro on '
            f'{servo_port} ({self.devices.servo.device_name}); real-time factor '
            f'{self.real_time_factor:g}; step {self.settings.step:g} s')

        self.clock_pub = self.create_publisher(Clock, '/clock', QoSProfile(depth=1))
        # camera_info holds the intrinsics the user's calibration gave, not the build's
        published = self.world.published_cameras
        uncalibrated = declare(
            self, 'rgb_uncalibrated', False,
            'rgb/camera_info says K = 0, as usb_cam does for a webcam without a calibration '
            "file (the camera calibration's starting point; the images stay the same)")
        self._rgb_topics = self._camera_topics('rgb', 'rgb8', published['rgb'], uncalibrated)
        self._thermal_topics = self._camera_topics(
            'thermal', self.world.thermal_settings.encoding, published['thermal'])
        self.canvas_pub = self.create_publisher(Image, topics.SIM_CANVAS, QoSProfile(depth=1))
        self.truth_sun_pub = self.create_publisher(Vector3Stamped, 'sim/truth/sun_direction',
                                                   TRUTH_QOS)
        self.truth_world_pub = self.create_publisher(PoseStamped, 'sim/truth/world_pose',
                                                     TRUTH_QOS)
        self.truth_spot_pub = self.create_publisher(PointStamped, 'sim/truth/spot_centre',
                                                    TRUTH_QOS)
        self.truth_light_pub = self.create_publisher(LightTruth, 'sim/truth/light', TRUTH_QOS)
        self.truth_rgb_pub = self.create_publisher(PoseStamped, 'sim/truth/rgb_pose',
                                                   TRUTH_QOS)
        self.truth_build_pub = self.create_publisher(String, 'sim/truth/build', TRUTH_QOS)
        self.truth_build_pub.publish(String(data=yaml.safe_dump(self.build.to_dict(),
                                                                sort_keys=False)))
        self.truth_rgb_camera_pub = self.create_publisher(
            CameraInfo, 'sim/truth/rgb_camera_info', TRUTH_QOS)
        self.truth_rgb_camera_pub.publish(camera_info_from_camera(
            self.world.rgb.camera, None, 'rgb'))
        self._cameras_out = set()
        self._plug(declare(
            self, 'unplugged', [''],
            "Devices whose cable is out ('dobot', 'servo', 'rgb_camera', 'thermal_camera'); set "
            'at run time to unplug and plug back in.', dynamic=True))
        self.world.thermal_stuck = declare(
            self, 'thermal_stuck', False,
            'The thermal camera hangs: it repeats its last frame (new stamps) until this is '
            'false again; set at run time (a stuck camera must stop the heating).',
            dynamic=True)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._next = {'rgb': 0.0, 'thermal': 0.0, 'canvas': 0.0, 'truth': 0.0}
        # published serialised, restamped: no message object per step
        self._clock_bytes = serialize_message(Clock())
        self._rgb_pose_key = self._rgb_pose_serialized = None    # sim/truth/rgb_pose's
        max_lag = declare(
            self, 'pace_max_lag', 0.5,
            'How far behind its pace (real_time_factor, or lockstep_fallback_factor) the '
            'world may fall and still catch up, by stepping back to back; farther behind it '
            'goes on from where it is (0: never races to catch up, simulated time never runs '
            'faster than the pace) [s wall]', 0.0, 60.0)
        self._pacer = Pacer(self.real_time_factor, max_lag)
        lockstep_topic = declare(
            self, 'lockstep_topic', topics.THERMAL_STATS,
            'helio_msgs/ThermalStats topic answering each thermal image: the world runs at '
            'most lockstep_lead ahead of its newest stamp, so a world faster than real time '
            "never outruns the graph's perception ('' : off)")
        self._lockstep = Lockstep(
            declare(self, 'lockstep_lead', 0.2,
                    'How far the world may run ahead of lockstep_topic [s simulated]',
                    0.05, 60.0),
            declare(self, 'lockstep_timeout', 1.5,
                    'A lockstep_topic silent this long is left behind; longer than the '
                    "controllers' own silence limits (the painter's device_silence, 1 s), so "
                    'the world holds until they have heard a source fall silent [s wall]',
                    0.05, 60.0))
        # a world as fast as possible whose consumer went silent runs at this pace, not free:
        # free, it would outrun the drivers' wall-clock polling and starve its own emulators
        self._left_behind_pacer = Pacer(declare(
            self, 'lockstep_fallback_factor', 1.0,
            'Real-time factor while lockstep_topic is silent past lockstep_timeout (at '
            'real_time_factor 0) [simulated s per wall s]', 0.01, 1000.0), max_lag)
        self._was_left_behind = False
        self._lockstep_heard = threading.Event()
        self._lockstep_resend = declare(
            self, 'lockstep_resend', 0.1,
            'While the world waits for a lockstep source, send /clock and the last frame of '
            'the camera it answers again this often, for a source that missed them [s wall]',
            0.01, 10.0)
        self._last_frames = {}          # camera frame id -> its last image, serialised
        self.resends = 0
        if lockstep_topic:
            self.create_subscription(
                ThermalStats, lockstep_topic,
                lambda message: self._lockstep_seen(message.header.stamp, 'thermal'),
                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        spot_topic = declare(
            self, 'lockstep_spot_topic', topics.SPOT,
            'helio_msgs/SpotObservation topic answering each RGB image (the spot detector): '
            "the world runs at most lockstep_lead ahead of its newest stamp too ('' : off)")
        if spot_topic:
            self.create_subscription(
                SpotObservation, spot_topic,
                lambda message: self._lockstep_seen(message.header.stamp, topics.SPOT),
                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        if declare(self, 'lockstep_joint_states', True,
                   "Hold the world at most lockstep_joint_lead ahead of each driver's newest "
                   'joint_states too (each set of joint names is one source)'):
            self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_states,
                                     QoSProfile(depth=10))
        # a heartbeat's lease (node_kit.focus_lease) must not expire on a beater that is merely
        # slow: with this lead plus one step under the lease's node-clock timeout (0.15 s), a
        # world held for the beats cannot run the lease out, whatever the machine's load
        self._heartbeat_lead = declare(
            self, 'lockstep_heartbeat_lead', 0.05,
            'How far the world may run ahead of the newest stamp of each lockstep_heartbeats '
            "topic [s simulated]: with one step, under the beats' leases (0.15 s)", 0.01, 60.0)
        for topic in declare(
                self, 'lockstep_heartbeats', [topics.PAINTER_HEARTBEAT, HEATING_TOPIC],
                'std_msgs/Header topics stamped on the node clock (a controller that must '
                'watch the world: the painter; the lens planner while it holds the lens at '
                'the heating distance): the world runs at most lockstep_heartbeat_lead ahead '
                "of each one's newest stamp; a beat whose frame_id is 'clear' ends the topic "
                "until its next beat ('' : none)"):
            if topic:
                self.create_subscription(
                    Header, topic, lambda message, source=topic: self._on_heartbeat(
                        message, source), QoSProfile(depth=10))
        # less than a step: the world waits for each driver's report of every step, so a
        # joint state stamped t is the device as read at simulated time t (with one step of
        # lead, a moving arm's readings ran up to 0.25 s ahead of their stamps, and images
        # at the end of a move passed for still)
        self._joint_lead = declare(
            self, 'lockstep_joint_lead', 0.05,
            "How far the world may run ahead of a driver's newest joint_states [s simulated]",
            0.01, 60.0)
        self._rgb_jobs = collections.deque()     # RGB frames developing on the RGB thread
        self._rgb_thread = concurrent.futures.ThreadPoolExecutor(
            max_workers=1, thread_name_prefix='sim-rgb') if declare(
            self, 'rgb_thread', True,
            "Develop each RGB frame (its optics and read-out, most of a moving camera's "
            'cost) on a thread of its own while the world steps on: the image goes out '
            'within two frame periods of simulated time after its stamp; false: on the '
            'stepping thread, before the next /clock') else None
        self._stop = threading.Event()
        self.achieved_real_time_factor = 0.0
        self.step_errors = 0
        self._thread = threading.Thread(target=self._run, name='sim-world', daemon=True)
        self._thread.start()

    def _camera_topics(self, name, encoding, camera, uncalibrated=False):
        """
        Return the CameraTopics of camera `name`: `name`/image_raw and `name`/camera_info.

        `uncalibrated`: the CameraInfo has the image size and nothing else (K = 0).
        """
        # the intrinsics do not change: the CameraInfo is serialised once, restamped per frame
        info = camera_info_from_camera(camera, None, name)
        if uncalibrated:
            info = CameraInfo(width=info.width, height=info.height)
            info.header.frame_id = name
        return CameraTopics(
            image=self.create_publisher(Image, f'{name}/image_raw', qos_profile_sensor_data),
            info=self.create_publisher(CameraInfo, f'{name}/camera_info',
                                       qos_profile_sensor_data),
            encoding=encoding, frame_id=name,
            info_bytes=serialize_message(info))

    def _declare(self, name, default):
        description, minimum, maximum = PARAMETER_DOCS.get(name, (name, None, None))
        dynamic = name in self.RUNTIME
        if isinstance(default, (list, bool, str)):
            return declare(self, name, default, description, dynamic=dynamic)
        return declare(self, name, default, description, minimum, maximum, dynamic=dynamic)

    # ------------------------------------------------------------------ run-time controls

    def _on_set_parameters(self, parameters):
        """Apply the run-time controls (RUNTIME); refuse a malformed value with its reason."""
        # declarations pass here too; a set of a read-only parameter never does (rclpy)
        for parameter in parameters:
            try:
                if parameter.name == 'cloud_schedule':
                    self.world.set_cloud_schedule(parameter.value)
                elif parameter.name == 'real_time_factor':
                    self.real_time_factor = float(parameter.value)
                    self._pacer.set_real_time_factor(self.real_time_factor)
                elif parameter.name == 'unplugged':
                    self._plug(parameter.value)
                elif parameter.name == 'truth_period':
                    self.truth_period = float(parameter.value)
                elif parameter.name == 'thermal_stuck':
                    self.world.thermal_stuck = bool(parameter.value)
                    self.get_logger().warning(
                        f'thermal camera {"stuck" if parameter.value else "live again"} at '
                        f'{self.world.time:.2f} s')
            except ValueError as error:
                return SetParametersResult(successful=False, reason=str(error))
        return SetParametersResult(successful=True)

    def _plug(self, unplugged):
        """Unplug the named devices and plug the others back in (ValueError: unknown name)."""
        names = {name for name in unplugged if name}
        devices = {'dobot': self.devices.dobot, 'servo': self.devices.servo}
        unknown = names - set(devices) - set(self.CAMERAS)
        if unknown:
            raise ValueError(f'unplugged: unknown device(s) {sorted(unknown)}; the devices are '
                             f'{sorted([*devices, *self.CAMERAS])}')
        cameras_out = names & set(self.CAMERAS)
        for name in sorted(cameras_out ^ self._cameras_out):
            self.get_logger().warning(
                f'{name} {"unplugged" if name in cameras_out else "plugged back in"} at '
                f'{self.world.time:.2f} s')
        self._cameras_out = cameras_out
        for name, device in devices.items():
            if name in names and device.connected:
                device.disconnect()
                self.get_logger().warning(f'{name} unplugged at {self.world.time:.2f} s')
            elif name not in names and not device.connected:
                device.reconnect()
                self.get_logger().info(f'{name} plugged back in at {self.world.time:.2f} s')

    # ------------------------------------------------------------------ loop
    def _lockstep_seen(self, stamp, source, lead=None):
        """Note a lockstep source's output stamped `stamp` (a Time message); wake the loop."""
        self._lockstep.seen(stamp_to_seconds(stamp), time.monotonic(), source, lead)
        self._lockstep_heard.set()

    def _on_heartbeat(self, message, source):
        if message.frame_id == CLEAR:        # the beater has nothing to watch any more
            self._lockstep.forget(source)
        else:
            self._lockstep_seen(message.stamp, source, self._heartbeat_lead)

    def _on_joint_states(self, message):
        if message.name:          # one source per driver: its set of joint names
            self._lockstep_seen(message.header.stamp, ','.join(message.name),
                                self._joint_lead)

    def _run(self):
        """Step the world at the real-time factor and publish what is due."""
        held_since = None
        while not self._stop.is_set():
            waiting = self._lockstep.holding(self.world.clock.nanoseconds() * 1e-9,
                                             time.monotonic())
            if waiting:
                held_since = self._resend_while_held(waiting, held_since)
                self._lockstep_heard.wait(0.01)      # woken by the consumer's next output
                self._lockstep_heard.clear()
                continue
            held_since = None
            delay = self._pace().delay(time.monotonic(), self.world.time)
            if delay > 0.0 and self._stop.wait(delay):
                break
            try:
                with self.world.one_instant():
                    self.world.step()
                    if not self.context.ok():
                        break
                    self._publish_due()
            except Exception as error:  # keep simulating; a broken frame is logged
                if not self.context.ok():
                    break
                self.step_errors += 1
                self.get_logger().error(f'sim step failed: {error!r}', throttle_duration_sec=5.0)
            self.achieved_real_time_factor = self._pacer.achieved(time.monotonic(),
                                                                  self.world.time)

    def _resend_while_held(self, waiting, held_since):
        """
        Send /clock (and the last camera frame) again while a lockstep source is waited for.

        A held world publishes nothing new, so a source that missed the last /clock (a node
        whose subscription matched after the first ticks: its clock still reads 0) or the
        last frame of its camera (best effort, dropped by a busy reader) would have nothing
        to answer, and the world would wait for it forever (or for ``lockstep_timeout``
        while its other outputs keep it heard). Every ``lockstep_resend`` of wall time held,
        the world sends them again, unchanged. Return when the hold began (wall clock).
        """
        now = time.monotonic()
        if held_since is None:
            return now
        if now - held_since < self._lockstep_resend:
            return held_since
        stamp = self._stamp()
        self.clock_pub.publish(restamped(self._clock_bytes, stamp))
        for source, camera, name in (('thermal', self._thermal_topics, 'thermal_camera'),
                                     (topics.SPOT, self._rgb_topics, 'rgb_camera')):
            frame = self._last_frames.get(camera.frame_id)
            if source in waiting and frame is not None and name not in self._cameras_out:
                camera.image.publish(frame)
        self.resends += 1
        return now

    def _pace(self):
        """Return the pacer in force: the fallback one while a lockstep consumer is silent."""
        left_behind = self.real_time_factor <= 0.0 and self._lockstep.left_behind(
            time.monotonic())
        if left_behind != self._was_left_behind:
            self._was_left_behind = left_behind
            if left_behind:
                self._left_behind_pacer.set_real_time_factor(
                    self._left_behind_pacer.real_time_factor)      # restart its reference
                silent = ', '.join(self._lockstep.silent(time.monotonic()))
                self.get_logger().warning(
                    f'lockstep: {silent} silent for {self._lockstep.timeout:g} s: running at '
                    f'{self._left_behind_pacer.real_time_factor:g}x real time until it answers')
            else:
                self.get_logger().info('lockstep: every source answers again: in lockstep')
        return self._left_behind_pacer if left_behind else self._pacer

    def _stamp(self):
        nanoseconds = self.world.clock.nanoseconds()
        return rclpy.time.Time(nanoseconds=nanoseconds).to_msg()

    def _due(self, name, rate):
        if rate <= 0.0 or self.world.time + 1e-9 < self._next[name]:
            return False
        self._next[name] = max(self._next[name] + 1.0 / rate, self.world.time)
        return True

    def _publish_due(self):
        stamp = self._stamp()
        self.clock_pub.publish(restamped(self._clock_bytes, stamp))
        if self._due('thermal', self.thermal_rate) and 'thermal_camera' not in self._cameras_out:
            self._publish_frame(self._thermal_topics, self.world.thermal_image, stamp)
        if self._due('rgb', self.rgb_rate) and 'rgb_camera' not in self._cameras_out:
            self._publish_rgb(stamp)
            self.truth_rgb_pub.publish(restamped(self._rgb_pose_bytes(), stamp))
        if self._due('canvas', self.canvas_rate) and self.canvas_pub.get_subscription_count():
            self.canvas_pub.publish(serialized_image(self.world.canvas_image(), 'mono8', stamp,
                                                     'world'))
        if self._due('truth', 1.0 / self.truth_period):
            self._publish_truth(stamp)

    def _rgb_pose_bytes(self):
        """Return the true RGB pose's PoseStamped serialised (once per pose: restamp it)."""
        T_world_rgb = self.world.camera_poses()[0]
        key = T_world_rgb.tobytes()
        if key != self._rgb_pose_key:
            self._rgb_pose_serialized = serialized_pose_stamped(T_world_rgb, Time(), 'world')
            self._rgb_pose_key = key
        return self._rgb_pose_serialized

    def _publish_frame(self, camera, render, stamp):
        """Publish a camera's CameraInfo, and its image when someone subscribes to it."""
        if camera.image.get_subscription_count() > 0:
            self._send_frame(camera, render(), stamp)
        else:
            camera.info.publish(restamped(camera.info_bytes, stamp))

    def _send_frame(self, camera, array, stamp):
        """Publish a camera's image `array` (serialised: no message object) and its CameraInfo."""
        image = serialized_image(array, camera.encoding, stamp, camera.frame_id)
        camera.image.publish(image)
        camera.info.publish(restamped(camera.info_bytes, stamp))
        self._last_frames[camera.frame_id] = image     # sent again while held (lockstep)

    def _publish_rgb(self, stamp):
        """
        Take the RGB frame now and publish it: developed on the RGB thread, or here.

        With ``rgb_thread`` the frame's lit texture, optics and read-out are made beside
        the world's next steps, at most ``RGB_FRAMES_IN_FLIGHT`` frames at a time: the
        world waits for the oldest before it takes another, so an image is published
        before the world passes the stamp of the frame after next.
        """
        while len(self._rgb_jobs) >= self.RGB_FRAMES_IN_FLIGHT:
            self._finish_rgb(self._rgb_jobs.popleft())
        if self._rgb_thread is None or self._rgb_topics.image.get_subscription_count() == 0:
            self._publish_frame(self._rgb_topics, self.world.rgb_image, stamp)
            return
        frame = self.world.stage_rgb_frame()
        self._rgb_jobs.append(self._rgb_thread.submit(
            lambda: self._send_frame(self._rgb_topics, frame(), stamp)))

    def _finish_rgb(self, job):
        """Wait until an RGB frame on the RGB thread is published; log it if it failed."""
        try:
            job.result()
        except Exception as error:  # keep simulating; a broken frame is logged
            if self.context.ok():
                self.step_errors += 1
                self.get_logger().error(f'sim RGB frame failed: {error!r}',
                                        throttle_duration_sec=5.0)

    def _publish_truth(self, stamp):
        """Publish the true sun ray (robot frame) and the true T_robot_world."""
        sun = Vector3Stamped()
        sun.header.stamp, sun.header.frame_id = stamp, 'robot'
        sun.vector = array_to_point(self.world.sun.ray_robot(self.world.clock.datetime()),
                                    Vector3)
        self.truth_sun_pub.publish(sun)
        world = PoseStamped()
        world.header.stamp, world.header.frame_id = stamp, 'robot'
        world.pose = matrix_to_pose(self.world.T_robot_world)
        self.truth_world_pub.publish(world)
        spot = PointStamped()
        spot.header.stamp, spot.header.frame_id = stamp, 'world'
        field = self.world.flux_field
        centre = None if field is None else field.centroid()
        spot.point = array_to_point([float('nan')] * 3 if centre is None else [*centre, 0.0])
        self.truth_spot_pub.publish(spot)
        light = LightTruth()
        light.header = spot.header
        light.centre = spot.point
        light.peak_irradiance = self.world.peak_irradiance()
        light.dni = float(self.world.dni_now())
        self.truth_light_pub.publish(light)

    def stop(self):
        """Stop stepping, write the outputs if asked, close the devices."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=10.0)
        while self._rgb_jobs:
            self._finish_rgb(self._rgb_jobs.popleft())
        if self._rgb_thread is not None:
            self._rgb_thread.shutdown(wait=True)
        self.get_logger().info(
            f'stopped at {self.world.time:.1f} s simulated, real-time factor achieved '
            f'{self.achieved_real_time_factor:.2f}')
        if self.output_dir:
            png, csv = self.world.write_outputs(self.output_dir)
            self.get_logger().info(f'wrote {png} and {csv}')
        self.devices.close()

    def destroy_node(self):
        """Stop the world thread and the emulators, then destroy the node."""
        self.stop()
        return super().destroy_node()


def main(args=None):
    """Run the sim_world node."""
    run_node(SimWorldNode, args)


if __name__ == '__main__':
    main()
