"""
The noise of a spot centre as the sun estimate sees it, and the holds it comes in (issue 35).

A sweep observes each lens pose for several frames while the lens is still (a hold). The
frames of a hold are NOT independent observations of the sun: what separates a detected
centre from the model's (``spot.SpotModel``: the lens rim's conic centre, Sec. III-B) is
almost all the same for every frame of the hold (the model's error for that geometry, the
camera pose, the lens' own errors); only the pixel noise changes from frame to frame.
Measured on the simulated world's rendered frames
(``docs/measurements/2026-11-27-sweep-honesty.md``, ``helio_control.sweep_honesty``): the
frames of a hold scatter by 0.007 mm rms about their mean, while that mean lies off the
model's centre for the true sun by 0.03 mm (across the sun's azimuth) to 0.16 mm (along
it; robust standard deviations). Counted as independent, four frames weigh one pose's
error four times; with the old 0.5 mm per frame the chi-square of the good sweeps was 0.05
of its degrees of freedom, the test could refuse nothing, and 12 of 200 sweeps were
accepted 0.3-1.0 deg off the true sun.

So the frames of a hold are merged into one observation (``merge_holds``: the mean of the
frames within ``frame_tolerance`` of their median centre) whose sigma (``CentreNoise.sigma``)
is the spread of that common error, per axis on the plane:

    sigma^2 = floor^2 + (per_cot * cot(elevation))^2 + frame^2 / frames

with ``elevation`` the chief ray's (the lens centre to the detected spot centre: nearly the
sun's ray through the lens centre, which a thin lens does not deviate) above the plane,
known from the observation itself: the light of a low sun comes in flat and stretches the
spot, and the model's error with it, along the ground. The defaults are a maximum-likelihood
fit to the residuals left at the fitted sun by 1171 holds of 306 sweeps (rendered frames,
seeds other than the benchmark's): a hold's sigma is 0.05 mm per axis with the chief ray
60 deg up, 0.14 mm at 30 deg. Over the good sweeps (within 0.2 deg of the true sun) the
chi-square is then 1.03 (tilted sweeps) and 0.77 (level-lens sweeps) of its degrees of
freedom, and 1.07 and 0.76 over the 200 sweeps of the benchmark (an independent seed); one
sigma for all (0.074 mm, its own best fit) gives 0.87 and 0.61; the chief ray's angle off
the lens axis or the spot's size predict the residuals less well (likelihood).

Beyond ``max_tilt`` (the sun's angle off the lens axis, judged by the sweep's median chief
ray) the model's error is no longer noise: the 95th percentile of a hold's error along the
sun is 0.3-0.5 mm within 15 deg, 0.7 mm at 15-20, 1.5 mm at 20-30 and 5 mm beyond, and it
is nearly the same for every hold of a sweep that yaws the lens about the vertical, so the
fit absorbs it into a wrong sun and no chi-square sees it (a level-lens sweep 0.63 deg off
fitted with chi-square 5.6 for 20 degrees of freedom; without the limit 6 of 100 level-lens
sweeps were accepted 0.3-0.95 deg off). The estimator leaves such observations out
(``TrustSettings.max_chief_ray_tilt``, set from ``max_tilt`` by the node).

API: ``CentreNoise(floor, per_cot, frame, frame_tolerance, max_tilt)`` with
``.sigma(elevation, frames=1)``, ``.elevation(observation)``, ``.tilt(observation)``,
``.of(observation, frames)`` (the observation with its sigma); ``Hold(observation, members,
left_out)``; ``merge_holds(observations, noise, position_tolerance, angle_tolerance)``;
``frame_verdicts(holds, result, noise)``: a fit on holds told per frame.
"""

from dataclasses import dataclass, replace
import math

import numpy as np


@dataclass(frozen=True)
class CentreNoise:
    """The standard deviation of a hold's spot centre on the plane, per axis [m]."""

    floor: float = 0.02e-3           # a hold's error under a sun straight above [m]
    per_cot: float = 0.08e-3         # grows by this times cot(chief-ray elevation) [m]
    frame: float = 0.01e-3           # one frame's own scatter within a hold [m]
    frame_tolerance: float = 0.3e-3  # a frame this far from its hold's median is left out [m]
    max_tilt: float = math.radians(15.0)  # the sigma holds up to this sun-to-axis angle [rad]

    def __post_init__(self):
        """Reject values outside their ranges, naming them."""
        for name in ('floor', 'per_cot', 'frame', 'frame_tolerance', 'max_tilt'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be a finite value >= 0, got {value}')
        if not self.floor + self.frame > 0.0:
            raise ValueError('floor and frame are both 0: a sigma of 0 under a sun straight '
                             'above')

    def sigma(self, elevation=0.5 * math.pi, frames=1):
        """Return sigma [m] of the mean centre of `frames` frames, chief ray `elevation` up."""
        cot = 0.0 if not 0.0 < elevation < 0.5 * math.pi else 1.0 / math.tan(elevation)
        return math.sqrt(self.floor ** 2 + (self.per_cot * cot) ** 2
                         + self.frame ** 2 / max(int(frames), 1))

    @staticmethod
    def _chief(observation):
        """Return the chief ray (lens centre to spot centre) as a unit vector, or None."""
        chief = observation.centre - observation.T_robot_lens[:3, 3]
        length = float(np.linalg.norm(chief))
        if not (math.isfinite(length) and length > 0.0):
            return None
        return chief / length

    @classmethod
    def elevation(cls, observation):
        """Return the chief ray's angle below the plane [rad] (NaN without a centre)."""
        chief = cls._chief(observation)
        if chief is None:
            return float('nan')
        return math.asin(max(-1.0, min(1.0, float(-chief @ observation.plane_normal))))

    @classmethod
    def tilt(cls, observation):
        """Return the angle [rad] between the lens axis and the chief ray to the spot centre."""
        chief = cls._chief(observation)
        if chief is None:
            return float('nan')
        return math.acos(max(-1.0, min(1.0, float(chief @ -observation.T_robot_lens[:3, 2]))))

    def of(self, observation, frames=1):
        """Return `observation` with the sigma of its chief ray and `frames`."""
        elevation = self.elevation(observation)
        return replace(observation, sigma=self.sigma(
            elevation if math.isfinite(elevation) else 0.5 * math.pi, frames))


@dataclass
class Hold:
    """One merged observation: the frames merged (indices into the input), those left out."""

    observation: object              # sun_estimation.Observation
    members: list                    # indices of the observations of the hold
    left_out: list                   # indices of its frames off the median


def _same_hold(a, b, position_tolerance, angle_tolerance):
    """Tell whether two observations share one lens pose and one plane."""
    if np.max(np.abs(a.T_robot_lens[:3, 3] - b.T_robot_lens[:3, 3])) > position_tolerance:
        return False
    if np.max(np.abs(a.T_robot_lens[:3, :3] - b.T_robot_lens[:3, :3])) > angle_tolerance:
        return False
    return bool(np.allclose(a.plane_point, b.plane_point, atol=position_tolerance)
                and np.allclose(a.plane_normal, b.plane_normal, atol=angle_tolerance))


def merge_holds(observations, noise, position_tolerance=1e-5, angle_tolerance=1e-5):
    """
    Merge consecutive observations of one lens pose and plane into Holds (see the docstring).

    `observations` are ``sun_estimation.Observation`` in time order. Observations whose lens
    positions agree within `position_tolerance` [m] and rotations within `angle_tolerance`
    [rad] form one hold (the joints of a still lens). The hold's centre is the mean of its
    frames within ``noise.frame_tolerance`` of their median centre (all of them when none
    is), moved onto the plane; its angle offset (Eq 18) the mean of theirs; its sigma
    ``noise.sigma`` of its chief ray and frame count. Non-finite centres stay apart,
    one hold each (the estimator screens them out with their reason).
    """
    groups = []
    for index, observation in enumerate(observations):
        finite = bool(np.all(np.isfinite(observation.centre)))
        if groups and finite and groups[-1][0] and _same_hold(
                observations[groups[-1][1][-1]], observation, position_tolerance,
                angle_tolerance):
            groups[-1][1].append(index)
        else:
            groups.append((finite, [index]))
    return [_merged(observations, members, noise, finite) for finite, members in groups]


def _merged(observations, members, noise, finite):
    """Return the Hold of `members` (indices of observations of one pose)."""
    first = observations[members[0]]
    if not finite:
        return Hold(first, list(members), [])
    centres = np.array([observations[i].centre for i in members])
    median = np.median(centres, axis=0)
    near = np.linalg.norm(centres - median, axis=1) <= noise.frame_tolerance
    used = [i for i, ok in zip(members, near) if ok] or list(members)
    centre = np.mean([observations[i].centre for i in used], axis=0)
    centre = centre - float((centre - first.plane_point) @ first.plane_normal) \
        * first.plane_normal
    offsets = np.mean([observations[i].angle_offset for i in used], axis=0)
    merged = noise.of(replace(first, centre=centre,
                              angle_offset=tuple(float(v) for v in offsets)), len(used))
    return Hold(merged, list(members), [i for i in members if i not in used])


@dataclass
class FrameVerdicts:
    """A fit on holds told per frame (the observations given to ``merge_holds``)."""

    used: list            # indices of the frames used, in the order of the holds used
    deviations: list      # per used frame, its hold's deviation [std dev]
    left_out: list        # (index, reason) of the frames left out, by index


def frame_verdicts(holds, result, noise):
    """
    Tell per frame what a fit on `holds` (``SunEstimateResult``) did with it.

    A frame of a hold used carries that hold's deviation; the frames of a hold left out
    carry its reason; a frame ``merge_holds`` set apart from its hold's median says so.
    """
    used, deviations, left_out = [], [], []
    for position, hold_index in enumerate(result.inliers):
        hold = holds[hold_index]
        deviation = float(result.deviations[position]) if position < len(result.deviations) \
            else float('nan')
        for index in hold.members:
            if index not in hold.left_out:
                used.append(index)
                deviations.append(deviation)
    for hold_index, reason in result.outliers:
        hold = holds[hold_index]
        left_out.extend((index, reason) for index in hold.members if index not in hold.left_out)
    for hold in holds:
        left_out.extend((index, f'its centre lies more than {noise.frame_tolerance * 1e3:.3g} '
                                'mm from the median of its hold (the other frames of the '
                                'still lens pose)') for index in hold.left_out)
    return FrameVerdicts(used, deviations, sorted(left_out))
