"""
Node sim_world: the simulated world (issue 6), the embedded default when there is no rig.

It hosts the emulated Dobot and Maestro on pseudo-terminals (paths are parameters, logged at
start) so that ``dobot_driver`` and ``servo_driver`` connect to them as to hardware, steps
the world (``helio_drivers.sim_world.SimWorld``) on its own thread at ``real_time_factor``
and publishes:

- ``/clock`` (rosgraph_msgs/Clock): simulated time; run every other node with
  ``use_sim_time:=true``;
- ``/rgb/image_raw`` (rgb8, rendered only while someone subscribes) and ``/rgb/camera_info``
  at ``rgb_rate_hz`` of simulated time; ``/thermal/image_raw`` (16UC1 centikelvin) and
  ``/thermal/camera_info`` at ``thermal_rate_hz`` (sensor-data QoS);
- ``/sim/canvas`` (mono8 top view of the char map, 255 bare wood) at ``canvas_rate_hz``.

At shutdown it writes ``canvas.png`` and ``dots.csv`` into ``output_dir`` (if set). The world's
truth (sun, heading, lens focus) is published nowhere: the controller must find it.
"""

import threading
import time

from helio_drivers.sim_clock import Pacer
from helio_drivers.sim_devices import DeviceSettings, SimDevices
from helio_drivers.sim_world import flat_settings, settings_from_flat, SimSettings, SimWorld
from helio_optics.node_parameters import declare
from helio_optics.node_runner import run_node
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
from helio_optics.rig_kinematics import RigParameters
from helio_perception.image_conversion import numpy_to_image
from rcl_interfaces.msg import ParameterDescriptor, ParameterType
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import qos_profile_sensor_data, QoSProfile
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import CameraInfo, Image

# name: (description, minimum, maximum); ranges only for numbers.
PARAMETER_DOCS = {
    'latitude_deg': ('site latitude, degrees north (pysolar)', -90.0, 90.0),
    'longitude_deg': ('site longitude, degrees east', -180.0, 360.0),
    'elevation_m': ('site height above sea level [m]', -500.0, 9000.0),
    'start_time': ('simulated start, ISO 8601 with UTC offset', None, None),
    'robot_heading_deg': ('HIDDEN truth: compass azimuth of the robot x axis, clockwise from '
                          'north [deg]; the estimator must find it', -360.0, 360.0),
    'dni': ('clear-sky direct normal irradiance [W/m^2]', 0.0, 1400.0),
    'cloud_schedule': ('clouds as flat triples start_s, end_s, attenuation (DNI factor)',
                       None, None),
    'random_clouds': ('add the seeded random cloud process', None, None),
    'cloud_seed': ('seed of the random clouds', 0, 2 ** 31 - 1),
    'cloud_mean_clear_s': ('mean clear spell of the random clouds [s]', 1.0, 1e6),
    'cloud_mean_cloudy_s': ('mean cloudy spell of the random clouds [s]', 0.1, 1e6),
    'cloud_attenuation_range': ('DNI factor range of random clouds [min, max]', None, None),
    'step_s': ('simulated time per world step [s]', 0.005, 0.5),
    'seed': ('seed of the camera noise and ray sampling', 0, 2 ** 31 - 1),
    'lens.focal_length': ('world lens focal length f = r_s/(n-1) [m]', 0.02, 0.5),
    'lens.refractive_index': ('world lens index at 587.6 nm (design)', 1.01, 2.5),
    'lens.thickness': ('world lens plate thickness [m]', 0.0, 0.01),
    'lens.aperture_diameter': ('world lens clear aperture [m] (tuned, SIMULATION.md)',
                               0.005, 0.3),
    'lens.transmission': ('world lens transmission kappa [-]', 0.01, 1.0),
    'lens.facets': ("world lens facets: 'corrected' or 'spherical' (Eq 3)", None, None),
    'flux_rays': ('rays traced per spectral band set', 100, 10 ** 7),
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
    'rgb.width': ('RGB image width [px]', 16, 4096),
    'rgb.height': ('RGB image height [px]', 16, 4096),
    'rgb.horizontal_fov': ('RGB horizontal field of view [rad]', 0.1, 3.0),
    'rgb.supersample': ('RGB sub-pixel rays per pixel side', 1, 8),
    'rgb.sunlit_level': ('image level of sunlit wood relative to its albedo [-]', 0.01, 10.0),
    'rgb.diffuse_fraction': ('sky light relative to the direct sun [-]', 0.0, 1.0),
    'rgb.blur_sigma': ('RGB optical blur [px]', 0.0, 10.0),
    'rgb.noise_sigma': ('RGB sensor noise [8-bit levels]', 0.0, 50.0),
    'thermal.width': ('thermal image width [px]', 8, 2048),
    'thermal.height': ('thermal image height [px]', 8, 2048),
    'thermal.horizontal_fov': ('thermal horizontal field of view [rad]', 0.1, 3.0),
    'thermal.cap': ('thermal read-out upper limit [degC]', 0.0, 2000.0),
    'thermal.floor': ('thermal read-out lower limit [degC]', -273.0, 100.0),
    'thermal.noise_sigma': ('thermal noise (NETD) [K]', 0.0, 10.0),
}


class SimWorldNode(Node):
    """Thin node around SimWorld and SimDevices; see the module docstring."""

    def __init__(self, **kwargs):
        """Declare parameters, build the world and the devices, start the stepping thread."""
        super().__init__('sim_world', **kwargs)
        flat = {}
        for name, default in flat_settings(SimSettings()).items():
            flat[name] = self._declare(name, default)
        self.settings = settings_from_flat(flat)
        self.real_time_factor = declare(
            self, 'real_time_factor', 1.0,
            'simulated seconds per wall second (0: as fast as possible)', 0.0, 1000.0)
        self.rgb_rate = declare(self, 'rgb_rate_hz', 5.0, 'RGB frame rate [Hz sim]', 0.0, 120.0)
        self.thermal_rate = declare(self, 'thermal_rate_hz', 8.7,
                                    'thermal frame rate [Hz sim]', 0.0, 120.0)
        self.canvas_rate = declare(self, 'canvas_rate_hz', 0.5,
                                   '/sim/canvas rate [Hz sim]', 0.0, 10.0)
        self.output_dir = declare(self, 'output_dir', '',
                                  'write canvas.png and dots.csv here at shutdown', None)
        rig_file = declare(self, 'rig_file', '',
                           "rig geometry YAML (empty: helio_optics' config/rig.yaml)", None)
        devices = DeviceSettings(
            dobot_port=declare(self, 'dobot_port', DeviceSettings.dobot_port,
                               'pty symlink of the emulated Dobot', None),
            servo_port=declare(self, 'servo_port', DeviceSettings.servo_port,
                               'pty symlink of the emulated Maestro', None),
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
                'Dobot j1..j4 at start [deg]', None)))
        self.world = SimWorld(self.settings, self._rig_parameters(rig_file))
        self.devices = SimDevices(self.world.clock, devices)
        self.world.attach_joint_source(self.devices.joint_positions)
        dobot_port, servo_port = self.devices.ports
        self.get_logger().info(
            f'emulated Dobot on {dobot_port} ({self.devices.dobot.device_name}), Maestro on '
            f'{servo_port} ({self.devices.servo.device_name}); real-time factor '
            f'{self.real_time_factor:g}; step {self.settings.step_s:g} s')

        self.clock_pub = self.create_publisher(Clock, '/clock', QoSProfile(depth=1))
        self.rgb_pub = self.create_publisher(Image, '/rgb/image_raw', qos_profile_sensor_data)
        self.rgb_info_pub = self.create_publisher(CameraInfo, '/rgb/camera_info',
                                                  qos_profile_sensor_data)
        self.thermal_pub = self.create_publisher(Image, '/thermal/image_raw',
                                                 qos_profile_sensor_data)
        self.thermal_info_pub = self.create_publisher(CameraInfo, '/thermal/camera_info',
                                                      qos_profile_sensor_data)
        self.canvas_pub = self.create_publisher(Image, '/sim/canvas', QoSProfile(depth=1))
        self._next = {'rgb': 0.0, 'thermal': 0.0, 'canvas': 0.0}
        self._pacer = Pacer(self.real_time_factor)
        self._stop = threading.Event()
        self.achieved_real_time_factor = 0.0
        self.step_errors = 0
        self._thread = threading.Thread(target=self._run, name='sim-world', daemon=True)
        self._thread.start()

    def _declare(self, name, default):
        description, minimum, maximum = PARAMETER_DOCS.get(name, (name, None, None))
        if isinstance(default, list):
            descriptor = ParameterDescriptor(
                description=description, type=ParameterType.PARAMETER_DOUBLE_ARRAY)
            value = self.declare_parameter(name, Parameter.Type.DOUBLE_ARRAY, descriptor).value
            return list(default) if value is None else [float(v) for v in value]
        if isinstance(default, bool):
            return declare(self, name, default, description)
        return declare(self, name, default, description, minimum, maximum)

    def _rig_parameters(self, rig_file):
        rig_file = rig_file or default_rig_file()
        if not rig_file:
            self.get_logger().warn('no helio_optics config/rig.yaml found: default rig geometry')
            return RigParameters()
        return load_rig_parameters(rig_file)

    # ------------------------------------------------------------------ loop
    def _run(self):
        """Step the world at the real-time factor and publish what is due."""
        while not self._stop.is_set():
            delay = self._pacer.delay(time.monotonic(), self.world.time)
            if delay > 0.0 and self._stop.wait(delay):
                break
            try:
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
        clock = Clock()
        clock.clock = stamp
        self.clock_pub.publish(clock)
        if self._due('thermal', self.thermal_rate):
            image = numpy_to_image(self.world.thermal_image(), '16UC1')
            image.header.stamp, image.header.frame_id = stamp, 'thermal'
            self.thermal_pub.publish(image)
            self.thermal_info_pub.publish(self._camera_info(self.world.thermal.camera, stamp,
                                                            'thermal'))
        if self._due('rgb', self.rgb_rate):
            if self.rgb_pub.get_subscription_count() > 0:
                image = numpy_to_image(self.world.rgb_image(), 'rgb8')
                image.header.stamp, image.header.frame_id = stamp, 'rgb'
                self.rgb_pub.publish(image)
            self.rgb_info_pub.publish(self._camera_info(self.world.rgb.camera, stamp, 'rgb'))
        if self._due('canvas', self.canvas_rate):
            image = numpy_to_image(self.world.canvas_image(), 'mono8')
            image.header.stamp, image.header.frame_id = stamp, 'world'
            self.canvas_pub.publish(image)

    @staticmethod
    def _camera_info(camera, stamp, frame_id):
        info = CameraInfo()
        info.header.stamp, info.header.frame_id = stamp, frame_id
        info.width, info.height = camera.width, camera.height
        info.distortion_model = 'plumb_bob'
        distortion = [float(v) for v in camera.distortion]
        info.d = (distortion + [0.0] * 5)[:5]
        info.k = [float(v) for v in camera.matrix.ravel()]
        info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        info.p = [float(camera.matrix[0, 0]), 0.0, float(camera.matrix[0, 2]), 0.0,
                  0.0, float(camera.matrix[1, 1]), float(camera.matrix[1, 2]), 0.0,
                  0.0, 0.0, 1.0, 0.0]
        return info

    def stop(self):
        """Stop stepping, write the outputs if asked, close the devices."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=10.0)
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
