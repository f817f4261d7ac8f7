"""
Node sun_estimator: estimate the sun's ray from light-spot observations (Sec. III-C, Eq 18).

Subscribes ``/spot`` (helio_msgs/SpotObservation) and ``/joint_states``; keeps the recent
valid spots, each with the lens pose from the joint states nearest its image stamp.
Service ``/estimate_sun`` (helio_msgs/EstimateSun) runs ``SunEstimator`` on them and, on
success, publishes ``/sun/estimate`` (helio_msgs/SunEstimate, reliable, transient local).
A timer republishes the estimate moved along with the sun by Eq 18 (pysolar at the site).
Parameters: see ``config/sun_estimator.yaml`` (all declared with descriptors).
"""

import bisect
import datetime
import math

from helio_msgs.msg import SpotObservation, SunEstimate
from helio_msgs.srv import EstimateSun
from helio_optics.ephemeris import corrected_angles, Site, sun_position
from helio_optics.geometry import direction_from_angles, transform_points
from helio_optics.lens import LensParameters
from helio_optics.node_parameters import declare
from helio_optics.node_runner import run_node
from helio_optics.rig_kinematics import default_rig_file, JOINT_NAMES, load_rig_parameters, Rig
from helio_optics.sun_estimation import METHODS, Observation, SunEstimator
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from sensor_msgs.msg import JointState


def stamp_to_datetime(stamp_ns):
    """UTC datetime of a ROS time in nanoseconds."""
    return datetime.datetime.fromtimestamp(stamp_ns * 1e-9, tz=datetime.timezone.utc)


class SunEstimatorNode(Node):
    """Thin node around helio_optics.sun_estimation and helio_optics.ephemeris."""

    def __init__(self, **kwargs):
        """Declare parameters, build the estimator and the rig, open topics and service."""
        super().__init__('sun_estimator', **kwargs)
        self._declare_parameters()
        p = self._parameter
        lens = LensParameters(
            focal_length=p('lens.focal_length'), refractive_index=p('lens.refractive_index'),
            thickness=p('lens.thickness'), aperture_diameter=p('lens.aperture_diameter'),
            transmission=p('lens.transmission'), facets=p('lens.facets'))
        rig_file = p('rig_config') or default_rig_file()
        if not rig_file:
            raise FileNotFoundError('no rig_config given and no helio_optics config/rig.yaml')
        self.rig = Rig(load_rig_parameters(rig_file))
        self.estimator = SunEstimator(lens, p('rim_points'), p('contour_fraction'))
        if p('method') not in METHODS:
            raise ValueError(f"parameter method must be one of {METHODS}, got {p('method')!r}")
        self.site = Site(p('site.latitude_deg'), p('site.longitude_deg'), p('site.elevation_m'),
                         p('site.temperature_c'), p('site.pressure_pa'))
        self._joint_stamps, self._joint_values = [], []
        self._observations = []  # (stamp_ns, Observation)
        self._estimate = None    # (SunEstimate message at the anchor, anchor SunPosition)
        self.estimate_publisher = self.create_publisher(
            SunEstimate, '/sun/estimate',
            QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.create_subscription(JointState, '/joint_states', self._on_joint_state, 50)
        self.create_subscription(SpotObservation, '/spot', self._on_spot, 20)
        self.create_service(EstimateSun, '/estimate_sun', self._on_estimate_sun)
        period = p('update_period')
        if period > 0.0:
            self.create_timer(period, self._on_timer)
        self.get_logger().info(
            f"sun_estimator ready: method {p('method')}, rig from {rig_file}, site "
            f'{self.site.latitude_deg:.4f}, {self.site.longitude_deg:.4f}')

    # -- parameters --------------------------------------------------------------------------
    def _declare_parameters(self):
        declare(self, 'method', 'levenberg_marquardt',
                "default solver: 'levenberg_marquardt' (joint, robust) or "
                "'interaction_matrix' (the paper's Eqs 11-12)")
        declare(self, 'lens.focal_length', 0.080, 'lens focal length f [m]', 0.01, 1.0)
        declare(self, 'lens.refractive_index', 1.4914, 'lens refractive index n [-]', 1.01, 3.0)
        declare(self, 'lens.thickness', 0.002, 'lens plate thickness [m]', 0.0, 0.02)
        declare(self, 'lens.aperture_diameter', 0.058, 'lens clear aperture diameter [m]',
                0.001, 1.0)
        declare(self, 'lens.transmission', 0.92, 'lens transmission kappa [-]', 0.01, 1.0)
        declare(self, 'lens.facets', 'corrected', "'corrected' or 'spherical' (paper Eq 3)")
        declare(self, 'rig_config', '',
                'rig geometry YAML (empty: helio_optics config/rig.yaml)')
        declare(self, 'rim_points', 64, 'rays traced on the contour ring of the model [-]',
                8, 4096)
        declare(self, 'contour_fraction', 1.0,
                'radius of the modelled contour ring over the aperture radius (1: rim) [-]',
                0.05, 1.0)
        declare(self, 'centre_sigma', 0.5e-3,
                'standard deviation of a spot centre on the ground [m]', 1e-6, 0.05)
        declare(self, 'max_observations', 60, 'spot observations kept for an estimate [-]',
                1, 10000)
        declare(self, 'max_observation_age', 300.0,
                'observations older than this are dropped [s]', 0.1, 1e6)
        declare(self, 'joint_state_tolerance', 0.1,
                'largest time between a spot image and the joint state used for it [s]',
                0.0, 10.0)
        declare(self, 'gain', 0.9, 'interaction-matrix gain lambda (Eq 11) [-]', 0.01, 2.0)
        declare(self, 'delta', 1e-5, 'interaction-matrix step delta (Eq 12) [rad]', 1e-9, 0.1)
        declare(self, 'tolerance', 1e-9, 'interaction-matrix stop on ||y_t - y_img|| [-]',
                1e-15, 1.0)
        declare(self, 'max_iterations', 60, 'iteration limit of either solver [-]', 1, 10000)
        declare(self, 'site.latitude_deg', 46.5197, 'site latitude, north positive [deg]',
                -90, 90)
        declare(self, 'site.longitude_deg', 6.6323, 'site longitude, east positive [deg]',
                -180, 360)
        declare(self, 'site.elevation_m', 400.0, 'site height above sea level [m]', -500, 9000)
        declare(self, 'site.temperature_c', 20.0, 'air temperature for refraction [degC]',
                -60, 60)
        declare(self, 'site.pressure_pa', 101325.0, 'air pressure for refraction [Pa]',
                3e4, 1.2e5)
        declare(self, 'update_period', 5.0,
                'period of the Eq 18 update of /sun/estimate (0: off) [s]', 0.0, 3600.0)

    def _parameter(self, name):
        return self.get_parameter(name).value

    # -- inputs ------------------------------------------------------------------------------
    def _on_joint_state(self, message):
        index = {name: i for i, name in enumerate(message.name)}
        if not all(name in index for name in JOINT_NAMES):
            return  # a partial message (e.g. only the wrist); wait for complete ones
        try:
            values = np.array([message.position[index[name]] for name in JOINT_NAMES], float)
        except IndexError:
            self.get_logger().warning('joint_states with fewer positions than names: skipped')
            return
        if not np.all(np.isfinite(values)):
            self.get_logger().warning('joint_states with NaN/inf positions: skipped')
            return
        stamp = Time.from_msg(message.header.stamp).nanoseconds
        if self._joint_stamps and stamp < self._joint_stamps[-1]:
            self._joint_stamps, self._joint_values = [], []  # time went back (sim restart)
        self._joint_stamps.append(stamp)
        self._joint_values.append(values)
        if len(self._joint_stamps) > 2000:
            del self._joint_stamps[:1000], self._joint_values[:1000]

    def _joints_at(self, stamp):
        if not self._joint_stamps:
            return None, 'no complete /joint_states received yet'
        i = bisect.bisect_left(self._joint_stamps, stamp)
        candidates = [j for j in (i - 1, i) if 0 <= j < len(self._joint_stamps)]
        best = min(candidates, key=lambda j: abs(self._joint_stamps[j] - stamp))
        gap = abs(self._joint_stamps[best] - stamp) * 1e-9
        if gap > self._parameter('joint_state_tolerance'):
            return None, f'nearest joint state is {gap:.3f} s from the image'
        return self._joint_values[best], ''

    def _on_spot(self, message):
        if not message.valid:
            self.get_logger().debug(f'invalid spot skipped: {message.reason}')
            return
        centre = np.array([message.center.x, message.center.y, message.center.z])
        if not np.all(np.isfinite(centre)):
            self.get_logger().warning('spot with a NaN/inf centre: skipped')
            return
        frame = message.header.frame_id or 'world'
        if frame == 'world':
            centre = transform_points(self.rig.parameters.T_robot_world, centre)
        elif frame != 'robot':
            self.get_logger().warning(f"spot in frame '{frame}' (want world or robot): skipped")
            return
        stamp = Time.from_msg(message.header.stamp).nanoseconds
        joints, reason = self._joints_at(stamp)
        if joints is None:
            self.get_logger().warning(f'spot skipped: {reason}')
            return
        T_world = self.rig.parameters.T_robot_world
        observation = Observation(centre, self.rig.forward(joints).T_robot_lens,
                                  T_world[:3, 3], T_world[:3, 2], self._parameter('centre_sigma'))
        self._observations.append((stamp, observation))
        del self._observations[:-self._parameter('max_observations')]

    # -- estimation --------------------------------------------------------------------------
    def _recent_observations(self, limit):
        now = self.get_clock().now().nanoseconds
        age = self._parameter('max_observation_age') * 1e9
        self._observations = [(s, o) for s, o in self._observations if now - s <= age]
        chosen = [o for _, o in self._observations]
        return chosen[-limit:] if limit else chosen

    def _on_estimate_sun(self, request, response):
        method = request.method or self._parameter('method')
        if method not in METHODS:
            response.success = False
            response.message = f'unknown method {method!r}; use one of {METHODS}'
            return response
        observations = self._recent_observations(int(request.max_observations))
        if not observations:
            response.success = False
            response.message = ('no valid spot observation with joint states in the last '
                                f"{self._parameter('max_observation_age'):g} s")
            return response
        options = {'max_iterations': self._parameter('max_iterations')}
        if method == 'interaction_matrix':
            options.update(gain=self._parameter('gain'), delta=self._parameter('delta'),
                           tolerance=self._parameter('tolerance'))
        try:
            result = self.estimator.estimate(observations, method=method, **options)
        except ValueError as error:
            response.success = False
            response.message = f'estimation failed: {error}'
            return response
        stamp = self.get_clock().now()
        message = self._message(result, stamp)
        response.estimate = message
        response.success = bool(result.converged)
        if not result.converged:
            response.message = f'{method} did not converge: {result.reason}'
            return response
        anchor = self._sun_now(stamp)
        if anchor is not None:
            message.anchor_stamp = stamp.to_msg()
            message.anchor_elevation = message.elevation = anchor.elevation
            message.anchor_azimuth = message.azimuth = anchor.azimuth
        self._estimate = (message, anchor)
        self.estimate_publisher.publish(message)
        sigma = np.degrees(np.sqrt(np.maximum(np.diag(result.covariance), 0.0)))
        response.message = (
            f'{method}: phi0 {math.degrees(result.phi0):.3f} deg, theta0 '
            f'{math.degrees(result.theta0):.3f} deg (sigma {sigma[0]:.3f}, {sigma[1]:.3f} deg) '
            f'from {result.observations} observations in {result.iterations} iterations'
            + (f'; {result.reason}' if result.reason else ''))
        self.get_logger().info(response.message)
        return response

    def _message(self, result, stamp):
        message = SunEstimate()
        message.header.stamp = stamp.to_msg()
        message.header.frame_id = 'robot'
        if result.converged:
            message.direction.x, message.direction.y, message.direction.z = (
                float(v) for v in result.direction)
            message.phi0, message.theta0 = float(result.phi0), float(result.theta0)
        message.covariance = [float(v) for v in np.asarray(result.covariance).ravel()]
        message.method = result.method
        message.iterations = int(result.iterations)
        message.residual = float(result.residual) if math.isfinite(result.residual) else 0.0
        message.converged = bool(result.converged)
        message.reason = result.reason
        message.observations = int(result.observations)
        return message

    def _sun_now(self, stamp):
        try:
            return sun_position(self.site, stamp_to_datetime(stamp.nanoseconds))
        except (ValueError, OverflowError) as error:
            self.get_logger().warning(f'ephemeris unavailable: {error}')
            return None

    def _on_timer(self):
        """Eq 18: move the published estimate along with the sun."""
        if self._estimate is None or self._estimate[1] is None:
            return
        anchor_message, anchor = self._estimate
        stamp = self.get_clock().now()
        now = self._sun_now(stamp)
        if now is None:
            return
        phi, theta = corrected_angles(anchor_message.phi0, anchor_message.theta0, anchor, now)
        message = SunEstimate()
        for field in SunEstimate.get_fields_and_field_types():
            setattr(message, field, getattr(anchor_message, field))
        message.header.stamp = stamp.to_msg()
        message.phi0, message.theta0 = float(phi), float(theta)
        direction = direction_from_angles(phi, theta)
        message.direction.x, message.direction.y, message.direction.z = (
            float(v) for v in direction)
        message.elevation, message.azimuth = now.elevation, now.azimuth
        self.estimate_publisher.publish(message)


def main(args=None):
    """Run the sun_estimator node."""
    run_node(SunEstimatorNode, args)


if __name__ == '__main__':
    main()
