"""
Node sun_estimator: estimate the sun's ray from light-spot observations (Sec. III-C, Eq 18).

Subscribes ``spot`` (helio_msgs/SpotObservation) and ``joint_states`` (the drivers' partial
messages merged by ``JointStateBuffer``); keeps the recent valid spots (FULL quality only)
imaged while the lens was still (``still_only``: the joints unchanged around the image, as the
paper's observations are taken; a spot waits for the joint states after its image), each
with the lens pose from those joints and the pysolar sun position at its stamp. Service
``estimate_sun``
(helio_msgs/EstimateSun) moves every observation to one reference time (the middle of the
observations used) by Eq 18, runs ``SunEstimator`` and answers with the estimate at that
time; ``success`` only when it is trustworthy (a minimum that fits within the noise, not
ambiguous), else the reason. The frames of one still lens pose (a hold) are merged into one
observation before the fit (``centre_noise.merge_holds``): their errors against the model
are nearly all shared, so they are not independent evidence; the hold's sigma grows as the
chief ray (lens centre to spot) comes in flatter, and spots whose lens axis lies more than
``max_chief_ray_tilt_deg`` off the sweep's median chief ray (nearly the sun) are left out
(``centre_noise.CentreNoise``, measured on the simulated world's frames:
docs/measurements/2026-11-27-sweep-honesty.md).
The answer still counts and names frames (``observations``, stamps, outliers); the fit's
degrees of freedom count holds. A trustworthy estimate is published on ``sun/estimate``
(helio_msgs/SunEstimate, reliable, transient local) moved to the time of publication, and a
timer republishes it moved along with the sun by Eq 18. Names are relative (the node runs
under a namespace with its rig). Parameters: see ``config/sun_estimator.yaml`` (all declared
with descriptors; those read per estimate are dynamic, the others read-only).
"""

import collections
import copy
from dataclasses import dataclass
import datetime
import math
import time
import traceback

from helio_msgs.msg import SpotObservation, SunEstimate
from helio_msgs.srv import EstimateSun
from helio_optics.centre_noise import CentreNoise, frame_verdicts, merge_holds
from helio_optics.ephemeris import angle_offsets, corrected_angles, sun_position
from helio_optics.geometry import direction_from_angles, invert_transform, transform_points
from helio_optics.node_kit import topics
from helio_optics.node_kit.conversions import point_to_array, stamp_from_seconds
from helio_optics.node_kit.conversions import stamp_to_nanoseconds, stamp_to_seconds
from helio_optics.node_kit.deployment import declare_lens, declare_rig, declare_site
from helio_optics.node_kit.deployment import follow_world_calibration
from helio_optics.node_kit.joint_states import JointStateBuffer
from helio_optics.node_kit.parameters import declare
from helio_optics.node_kit.qos import LATCHED
from helio_optics.node_kit.runner import run_node
from helio_optics.sun_estimation import METHODS, Observation, SunEstimator, TrustSettings
import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState


def stamp_to_datetime(stamp_ns):
    """UTC datetime of a ROS time in nanoseconds."""
    return datetime.datetime.fromtimestamp(stamp_ns * 1e-9, tz=datetime.timezone.utc)


@dataclass
class _Buffered:
    """One spot observation with what the estimate needs besides it."""

    stamp: object            # builtin_interfaces/Time of the image
    seconds: float
    joints: np.ndarray       # reported, at the image (the lens pose is made at the fit, by
    #                          the rig model then: a rig calibration since applies to it)
    centre: np.ndarray       # world frame [m]
    sun: object              # pysolar SunPosition at the stamp (None: ephemeris failed)


@dataclass
class _Waiting:
    """A spot waiting for the joint states around its image."""

    stamp: object            # builtin_interfaces/Time of the image
    seconds: float
    centre: np.ndarray       # in the world frame [m]
    arrived: float           # node clock when it came [s]


class SunEstimatorNode(Node):
    """Thin node around helio_optics.sun_estimation and helio_optics.ephemeris."""

    def __init__(self, **kwargs):
        """Declare parameters, build the estimator and the rig, open topics and service."""
        super().__init__('sun_estimator', **kwargs)
        self._declare_parameters()
        p = self._parameter
        lens, lens_file = declare_lens(self)
        self.rig, rig_file = declare_rig(self)
        follow_world_calibration(self, self.rig)     # T_robot_world from the marker
        self.estimator = SunEstimator(lens, p('rim_points'), p('contour_fraction'))
        if p('method') not in METHODS:
            raise ValueError(f"parameter method must be one of {METHODS}, got {p('method')!r}")
        self._trust()  # a start-up value TrustSettings refuses stops the node, named
        self.site, site_file = declare_site(self)
        self.joints = JointStateBuffer()
        self._observations = []  # _Buffered, oldest first
        self._pending = []       # _Waiting, for the joint states after their images
        self._skipped = collections.Counter()   # spots left out since the start, by why
        self._estimate = None    # (SunEstimate message at the anchor, anchor SunPosition)
        self.estimate_publisher = self.create_publisher(
            SunEstimate, topics.SUN_ESTIMATE, LATCHED)
        self.create_subscription(JointState, topics.JOINT_STATES, self._on_joint_state, 50)
        self.create_subscription(SpotObservation, topics.SPOT, self._on_spot, 20)
        # A deep request queue: with the default 10, requests arriving while one estimate ran
        # were dropped unanswered (issue 35: 39 of 50 simultaneous requests never answered)
        self.create_service(EstimateSun, 'estimate_sun', self._on_estimate_sun,
                            qos_profile=QoSProfile(depth=p('request_queue_depth'),
                                                   reliability=ReliabilityPolicy.RELIABLE))
        self._last_answer = None         # (key, success, message, estimate) of the last fit
        self._fits = collections.deque()   # (monotonic end, duration) of recent fits [s]
        period = p('update_period')
        if period > 0.0:
            self.create_timer(period, self._on_timer)
        self.get_logger().info(
            f"sun_estimator ready: method {p('method')}, rig from {rig_file}, lens from "
            f'{lens_file}, site {self.site.latitude_deg:.4f}, {self.site.longitude_deg:.4f} '
            f'from {site_file}, FULL spots only')

    # -- parameters --------------------------------------------------------------------------
    def _declare_parameters(self):
        declare(self, 'method', 'levenberg_marquardt',
                "default solver: 'levenberg_marquardt' (joint, robust) or "
                "'interaction_matrix' (the paper's Eqs 11-12)", dynamic=True)
        declare(self, 'rim_points', 64, 'rays traced on the contour ring of the model [-]',
                8, 4096)
        declare(self, 'contour_fraction', 1.0,
                'radius of the modelled contour ring over the aperture radius (1: rim) [-]',
                0.05, 1.0)
        # The noise of a hold's spot centre (centre_noise.CentreNoise; measured on the
        # simulated world's rendered frames: docs/measurements/2026-11-27-sweep-honesty.md)
        noise = CentreNoise()
        declare(self, 'centre_sigma', noise.floor,
                "standard deviation of a hold's spot centre on the ground, per axis, under a "
                'sun straight above: the floor of the noise model (the frames of a still lens '
                'pose merged) [m]', 1e-6, 0.05, dynamic=True)
        declare(self, 'centre_sigma_per_cot', noise.per_cot,
                "the centre's standard deviation grows by this times the cotangent of the "
                "chief ray's (lens centre to spot) elevation above the ground [m]", 0.0, 0.05,
                dynamic=True)
        declare(self, 'frame_sigma', noise.frame,
                "one frame's own scatter about its hold's centre, per axis [m]", 0.0, 0.05,
                dynamic=True)
        declare(self, 'hold_frame_tolerance', noise.frame_tolerance,
                "a frame farther than this from the median of its hold's frames is left out "
                '[m]', 1e-6, 0.05, dynamic=True)
        declare(self, 'max_observations', 60, 'spot observations kept for an estimate [-]',
                1, 10000, dynamic=True)
        declare(self, 'max_observation_age', 300.0,
                'observations older than this are dropped [s]', 0.1, 1e6, dynamic=True)
        declare(self, 'joint_state_tolerance', 0.3,
                'largest time between a spot image and the joint state used for it, when '
                'still_only is off [s]', 0.0, 10.0, dynamic=True)
        declare(self, 'still_only', True,
                'use a spot only if the lens was still around its image: its joints unchanged '
                'from still_margin before to still_margin after (a moving lens pairs the image '
                'with joints stamped on another copy of the clock: the pose of another '
                'instant)', dynamic=True)
        declare(self, 'still_margin', 0.3,
                'time around a spot image over which the joints must not change; covers the '
                "skew between the camera's and the drivers' stamps [s]", 0.0, 10.0,
                dynamic=True)
        declare(self, 'still_hold', 1.0,
                'the joint samples that show the lens still may lie this far from the image; '
                "bridges the gaps a fast simulated clock leaves between the drivers' "
                'wall-clock joint states [s]', 0.0, 10.0, dynamic=True)
        declare(self, 'still_epsilon', 1e-6,
                'largest joint change that counts as still [rad]', 0.0, 0.1, dynamic=True)
        declare(self, 'still_wait', 3.0,
                'longest a spot waits for the joint states after it before it is judged on '
                'those that came (node clock) [s]', 0.0, 60.0, dynamic=True)
        declare(self, 'gain', 0.9, 'interaction-matrix gain lambda (Eq 11) [-]', 0.01, 2.0,
                dynamic=True)
        declare(self, 'delta', 1e-5, 'interaction-matrix step delta (Eq 12) [rad]', 1e-9, 0.1,
                dynamic=True)
        declare(self, 'tolerance', 1e-9, 'interaction-matrix stop on ||y_t - y_img|| [-]',
                1e-15, 1.0, dynamic=True)
        declare(self, 'max_iterations', 60, 'iteration limit of either solver [-]', 1, 10000,
                dynamic=True)
        declare(self, 'request_queue_depth', 100,
                'estimate_sun requests held while one is answered; more are lost [-]', 1, 10000)
        declare(self, 'busy_budget', 0.5,
                'estimate_sun refuses as busy a request that needs a new fit while the fits of '
                'the last busy_window took more than this fraction of it [-]', 0.05, 1.0,
                dynamic=True)
        declare(self, 'busy_window', 10.0, 'wall time over which busy_budget holds [s]',
                0.1, 3600.0, dynamic=True)
        declare(self, 'update_period', 5.0,
                'period of the Eq 18 update of sun/estimate (0: off) [s]', 0.0, 3600.0)
        # When an estimate is trusted (sun_estimation.TrustSettings).
        declare(self, 'fit_alpha', 1e-3,
                'significance of the chi-square test the fit must pass to count as converged '
                '[-]', 1e-12, 0.5, dynamic=True)
        declare(self, 'outlier_alpha', 1e-4,
                'significance at which one observation is left out as an outlier [-]',
                1e-15, 0.5, dynamic=True)
        declare(self, 'max_outlier_fraction', 0.25,
                'outliers must stay below this fraction of the plausible observations [-]',
                0.01, 1.0, dynamic=True)
        declare(self, 'step_tolerance', 0.01,
                'converged: the Newton step is below this many standard deviations [-]',
                1e-6, 1.0, dynamic=True)
        declare(self, 'ambiguity_chi2', 9.21,
                'another minimum within this chi-square of the estimate fits as well '
                '(9.21: the 99% region of two parameters) [-]', 0.01, 1000.0, dynamic=True)
        declare(self, 'ambiguity_separation_deg', 0.05,
                'minima closer than this are the same answer [deg]', 1e-4, 10.0, dynamic=True)
        declare(self, 'plane_tolerance', 2e-3,
                'a spot centre farther than this off the ground plane is left out [m]',
                1e-6, 1.0, dynamic=True)
        declare(self, 'min_chief_ray_elevation_deg', 3.0,
                'a spot whose chief ray (lens centre to spot) rises less above the ground is '
                'left out (a centre metres away) [deg]', 0.0, 80.0, dynamic=True)
        declare(self, 'max_chief_ray_tilt_deg', round(math.degrees(noise.max_tilt), 6),
                "a spot whose lens axis lies farther off the observations' median chief ray "
                "(lens centre to spot: nearly the sun) is left out: there the lens model's "
                'centre errs by far more than centre_sigma says, alike over a sweep (measured '
                'on the simulated world) [deg]', 1.0, 180.0,
                dynamic=True)

    def _parameter(self, name):
        return self.get_parameter(name).value

    def _noise(self):
        p = self._parameter
        return CentreNoise(floor=p('centre_sigma'), per_cot=p('centre_sigma_per_cot'),
                           frame=p('frame_sigma'), frame_tolerance=p('hold_frame_tolerance'),
                           max_tilt=math.radians(p('max_chief_ray_tilt_deg')))

    def _trust(self):
        p = self._parameter
        return TrustSettings(
            fit_alpha=p('fit_alpha'), outlier_alpha=p('outlier_alpha'),
            max_outlier_fraction=p('max_outlier_fraction'), step_tolerance=p('step_tolerance'),
            ambiguity_chi2=p('ambiguity_chi2'),
            ambiguity_separation=math.radians(p('ambiguity_separation_deg')),
            plane_tolerance=p('plane_tolerance'),
            min_chief_ray_elevation=math.radians(p('min_chief_ray_elevation_deg')),
            max_chief_ray_tilt=math.radians(p('max_chief_ray_tilt_deg')))

    # -- inputs ------------------------------------------------------------------------------
    def _on_joint_state(self, message):
        problem = self.joints.add_message(message)
        if problem:
            self.get_logger().warning(problem, throttle_duration_sec=5.0)
        if self._pending:
            self._take_pending()

    def _on_spot(self, message):
        if not message.valid:
            self.get_logger().debug(f'invalid spot skipped: {message.reason}')
            return
        if message.quality != SpotObservation.FULL:
            self.get_logger().debug(f'spot of quality {message.quality} (not FULL) skipped: '
                                    f'{message.quality_reason}')
            return
        centre = point_to_array(message.center)
        if not np.all(np.isfinite(centre)):
            self.get_logger().warning('spot with a NaN/inf centre: skipped')
            return
        frame = message.header.frame_id or 'world'
        if frame == 'robot':
            centre = transform_points(invert_transform(self.rig.parameters.T_robot_world),
                                      centre)
        elif frame != 'world':
            self.get_logger().warning(f"spot in frame '{frame}' (want world or robot): skipped")
            return
        self._pending.append(_Waiting(message.header.stamp, stamp_to_seconds(message.header.stamp),
                                      centre, self._now_seconds()))
        overflow = len(self._pending) - self._parameter('max_observations')
        if overflow > 0:
            self._skip('no joint states came after them', count=overflow)
            del self._pending[:overflow]
        self._take_pending()

    def _take_pending(self, complete=False):
        """
        Pair the waiting spots with the lens pose at their image stamps, or drop them.

        With ``still_only`` a spot waits until the joint states ``still_margin`` after its
        image have come, so a lens that started to move just after the image is seen. When
        an estimate is asked for (`complete`) the newest joints stand in for those; a spot
        newer than every joint sample keeps waiting, at most ``still_wait``.
        """
        p = self._parameter
        now, waiting = self._now_seconds(), []
        for spot in self._pending:
            expired = now - spot.arrived > p('still_wait')
            if p('still_only'):
                lookup = self.joints.still_at(spot.seconds, p('still_margin'), p('still_hold'),
                                              p('still_epsilon'), complete=complete or expired)
            else:
                lookup = self.joints.at(spot.seconds, p('joint_state_tolerance'))
            if lookup.waiting and not expired:
                waiting.append(spot)
            elif not lookup:
                self._skip(lookup.reason, moving=lookup.moving)
            else:
                self._observe(spot, lookup.positions)
        self._pending = waiting

    def _skip(self, reason, moving=False, count=1):
        if moving:                            # every move of a sweep: counted, not warned
            self._skipped['while the lens moved'] += count
            self.get_logger().debug(f'spot skipped: {reason}', throttle_duration_sec=2.0)
        else:                                 # two call sites: each its own throttle
            self._skipped['for their joints'] += count
            self.get_logger().warning(f'spot skipped: {reason}', throttle_duration_sec=2.0)

    def _observe(self, spot, joints):
        sun = self._sun_at(stamp_to_nanoseconds(spot.stamp))
        self._observations.append(_Buffered(spot.stamp, spot.seconds,
                                            np.array(joints, dtype=float), spot.centre, sun))
        self._observations.sort(key=lambda b: b.seconds)
        del self._observations[:-self._parameter('max_observations')]

    def _now_seconds(self):
        return self.get_clock().now().nanoseconds * 1e-9

    # -- estimation --------------------------------------------------------------------------
    def _recent_observations(self, limit, since=0.0):
        """Return the last `limit` (0: all) observations imaged at or after `since` [s]."""
        self._take_pending(complete=True)
        now = self._now_seconds()
        age = self._parameter('max_observation_age')
        self._observations = [b for b in self._observations if now - b.seconds <= age]
        recent = [b for b in self._observations if b.seconds >= since]
        return recent[-limit:] if limit else recent

    def _on_estimate_sun(self, request, response):
        method = request.method or self._parameter('method')
        if method not in METHODS:
            response.success = False
            response.message = f'unknown method {method!r}; use one of {METHODS}'
            return response
        since = stamp_to_seconds(request.since)
        buffered = self._recent_observations(int(request.max_observations), since)
        if not buffered:
            response.success = False
            response.message = ('no valid spot observation with joint states in the last '
                                f"{self._parameter('max_observation_age'):g} s"
                                + (f' imaged since {since:.3f} s' if since > 0.0 else '')
                                + self._skipped_note())
            return response
        try:
            trust, noise = self._trust(), self._noise()
        except ValueError as error:
            response.success = False
            response.message = f'trust parameters refused: {error}'
            return response
        response.rig_calibration = self.rig.calibration_id
        options = {'max_iterations': self._parameter('max_iterations')}
        if method == 'interaction_matrix':
            options.update(gain=self._parameter('gain'), delta=self._parameter('delta'),
                           tolerance=self._parameter('tolerance'))
        # A request that asks what the last one asked (the same observations and settings)
        # gets its answer without a new fit; one that needs a fit while fits have taken more
        # than their budget of wall time is refused as busy (issue 35: a flood of requests).
        key = (method, tuple(b.seconds for b in buffered), repr(trust), repr(noise),
               tuple(sorted(options.items())), self.rig.parameters)   # a calibration refits
        if self._last_answer is not None and self._last_answer[0] == key:
            _, response.success, response.message, estimate = self._last_answer
            response.estimate = copy.deepcopy(estimate)
            return response
        busy = self._busy()
        if busy:
            response.success = False
            response.message = busy
            self.get_logger().warning(busy, throttle_duration_sec=5.0)
            return response
        began = time.monotonic()
        try:
            self._fit(method, buffered, trust, noise, options, response)
        finally:
            ended = time.monotonic()
            self._fits.append((ended, ended - began))
        self._last_answer = (key, response.success, response.message,
                             copy.deepcopy(response.estimate))
        return response

    def _busy(self):
        """Return why a new fit must wait ('busy: ...'), or '' when the budget allows one."""
        window, budget = self._parameter('busy_window'), self._parameter('busy_budget')
        now = time.monotonic()
        while self._fits and self._fits[0][0] < now - window:
            self._fits.popleft()
        spent = sum(min(duration, ended - (now - window)) for ended, duration in self._fits)
        if spent <= budget * window:
            return ''
        return (f'busy: estimates took {spent:.1f} s of the last {window:g} s (busy_budget '
                f'{budget:g}); ask again in a few seconds')

    def _fit(self, method, buffered, trust, noise, options, response):
        """
        Fit the sun to the buffered observations; fill in `response` (Eqs 10-12, 18).

        The frames of each hold are merged first (``merge_holds``); the answer tells per
        frame what became of it (``frame_verdicts``).
        """
        # Eq 18: every observation moved to one reference time, the middle of the sweep.
        seconds = [b.seconds for b in buffered]
        reference = 0.5 * (min(seconds) + max(seconds))
        reference_stamp = stamp_from_seconds(reference)
        anchor = self._sun_at(stamp_to_nanoseconds(reference_stamp))
        corrected = anchor is not None and all(b.sun is not None for b in buffered)
        T_world = self.rig.parameters.T_robot_world    # the present calibrations
        try:
            observations = [Observation.seen_on_the_world_plane(
                self.rig, T_world, b.centre, b.joints, noise.sigma(),
                angle_offsets(anchor, b.sun) if corrected else (0.0, 0.0)) for b in buffered]
            holds = merge_holds(observations, noise)    # each sigma from its chief ray
            result = self.estimator.estimate([h.observation for h in holds], method=method,
                                             trust=trust, **options)
        except ValueError as error:
            self.get_logger().error(f'estimation failed on {len(buffered)} observations:\n'
                                    f'{traceback.format_exc()}')
            response.success = False
            response.message = f'estimation failed: {error}'
            return response
        frames = frame_verdicts(holds, result, noise)
        message = self._message(result, frames, buffered, reference_stamp, anchor, corrected)
        response.estimate = message
        response.success = result.trustworthy
        when = stamp_to_datetime(stamp_to_nanoseconds(reference_stamp)).isoformat()
        time_note = (f'at {when} (the middle of observations spanning '
                     f'{max(seconds) - min(seconds):.1f} s'
                     + (', each moved there by Eq 18)' if corrected else
                        "; NOT corrected for the sun's motion: no ephemeris)"))
        outliers = (f'; {len(frames.left_out)} left out: ' + '; '.join(
            f'observation at {buffered[i].seconds:.3f} s: {reason}'
            for i, reason in frames.left_out)) if frames.left_out else ''
        if not result.trustworthy:
            response.message = (f'{method}: estimate not trustworthy {time_note}: '
                                f'{result.reason or "not converged"}{outliers}'
                                f'{self._skipped_note()}')
            self.get_logger().warning(response.message)
            return response
        if anchor is not None:
            self._estimate = (message, anchor)
        moved = self._moved(message, anchor, self.get_clock().now()) if anchor else None
        self.estimate_publisher.publish(moved or message)
        spread = np.degrees(np.sqrt(np.maximum(np.diag(result.covariance), 0.0)))
        response.message = (
            f'{method}: phi0 {math.degrees(result.phi0):.3f} deg, theta0 '
            f'{math.degrees(result.theta0):.3f} deg (sigma {spread[0]:.3f}, {spread[1]:.3f} deg) '
            f'{time_note} from {len(frames.used)} observations ({result.observations} still '
            f'poses) in {result.iterations} iterations; fit chi-square {result.chi2:.3g} <= '
            f'{result.chi2_threshold:.3g} ({result.dof} degrees of freedom){outliers}'
            f'{self._skipped_note()}')
        self.get_logger().info(response.message)
        return response

    def _skipped_note(self):
        """Say how many spots were left out before any fit, and why ('' when none)."""
        if not self._skipped:
            return ''
        return '; spots left out since the start: ' + ', '.join(
            f'{count} {why}' for why, count in sorted(self._skipped.items()))

    def _message(self, result, frames, buffered, reference_stamp, anchor, corrected):
        """
        Build the SunEstimate at the reference time (header.stamp = anchor_stamp).

        Observations, their stamps, deviations and outliers are frames (`frames`:
        ``FrameVerdicts``); a hold's frames share its deviation; the fit's degrees of freedom
        count holds.
        """
        message = SunEstimate()
        message.header.stamp = reference_stamp
        message.header.frame_id = 'robot'
        if np.all(np.isfinite(result.direction)):
            message.direction.x, message.direction.y, message.direction.z = (
                float(v) for v in result.direction)
            message.phi0, message.theta0 = float(result.phi0), float(result.theta0)
        message.covariance = _finite(result.covariance)
        message.method = result.method
        message.iterations = int(result.iterations)
        message.residual = float(result.residual) if math.isfinite(result.residual) else 0.0
        message.converged = bool(result.converged)
        message.reason = result.reason
        message.observations = len(frames.used)
        message.anchor_stamp = reference_stamp
        if anchor is not None:
            message.anchor_elevation = message.elevation = anchor.elevation
            message.anchor_azimuth = message.azimuth = anchor.azimuth
        message.fit_chi2 = float(result.chi2) if math.isfinite(result.chi2) else 0.0
        message.fit_dof = int(result.dof)
        message.fit_threshold = float(result.chi2_threshold) \
            if math.isfinite(result.chi2_threshold) else 0.0
        message.observation_deviation = [float(v) for v in frames.deviations]
        message.observation_stamps = [buffered[i].stamp for i in frames.used]
        used = [buffered[i].seconds for i in frames.used]
        message.observation_span = float(max(used) - min(used)) if used else 0.0
        message.ephemeris_corrected = bool(corrected)
        message.outliers = len(frames.left_out)
        message.outlier_stamps = [buffered[i].stamp for i, _ in frames.left_out]
        message.outlier_reasons = [reason for _, reason in frames.left_out]
        message.ambiguous = bool(result.ambiguous)
        if result.alternatives:
            best = result.alternatives[0]
            message.alternative_direction.x, message.alternative_direction.y, \
                message.alternative_direction.z = (float(v) for v in best.direction)
            message.alternative_chi2 = float(best.chi2)
            message.alternative_separation = float(best.separation)
            message.alternative_covariance = _finite(best.covariance)
        return message

    def _sun_at(self, stamp_ns):
        try:
            return sun_position(self.site, stamp_to_datetime(stamp_ns))
        except (ValueError, OverflowError, TypeError) as error:
            self.get_logger().warning(f'ephemeris unavailable: {error}',
                                      throttle_duration_sec=10.0)
            return None

    def _moved(self, anchor_message, anchor, stamp):
        """Eq 18: the estimate moved from its anchor to `stamp` (rclpy Time)."""
        now = self._sun_at(stamp.nanoseconds)
        if now is None:
            return None
        phi, theta = corrected_angles(anchor_message.phi0, anchor_message.theta0, anchor, now)
        message = copy.deepcopy(anchor_message)   # its header is not the anchor's
        message.header.stamp = stamp.to_msg()
        message.phi0, message.theta0 = float(phi), float(theta)
        direction = direction_from_angles(phi, theta)
        message.direction.x, message.direction.y, message.direction.z = (
            float(v) for v in direction)
        message.elevation, message.azimuth = now.elevation, now.azimuth
        return message

    def _on_timer(self):
        """Eq 18: move the published estimate along with the sun."""
        if self._estimate is None:
            return
        message = self._moved(*self._estimate, self.get_clock().now())
        if message is not None:
            self.estimate_publisher.publish(message)


def _finite(matrix):
    """Return a 2x2 matrix as 4 floats, non-finite values as 0 (the message's 'unknown')."""
    values = np.asarray(matrix, dtype=float).ravel()
    return [float(v) if math.isfinite(v) else 0.0 for v in values]


def main(args=None):
    """Run the sun_estimator node."""
    run_node(SunEstimatorNode, args)


if __name__ == '__main__':
    main()
