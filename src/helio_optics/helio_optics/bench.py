"""
Benchmarks of helio_optics: ``python -m helio_optics.bench [--json PATH] [--quick]``.

Prints the figures and writes them as flat JSON (units in the key names): rays traced per
second (two refractions + plane hit), one sun estimate per method (one spot and an
11-spot yaw sweep), a 35-point A_c(d_lp) sweep, the rig's FK and IK, and pysolar. Targets
of issue 3 (one core): >= 10 million rays/s, an estimate < 20 ms, the sweep < 100 ms.
"""

import argparse
import datetime
import math
import time

from helio_optics.bench_report import add_json_option, median_call_ms, report
from helio_optics.ephemeris import Site, sun_position
from helio_optics.focal_calibration import paper_sweep
from helio_optics.geometry import direction_from_angles, homogeneous, rotation_y, rotation_z
from helio_optics.lens import area_samples, LensParameters, trace
from helio_optics.rig_kinematics import Rig
from helio_optics.spot import spot_area_curve
from helio_optics.sun_estimation import SunEstimator
import numpy as np


def _sweep_poses(sun, yaws, distance=0.06, more_level_deg=14.0):
    elevation = math.asin(-sun[2])
    azimuth = math.atan2(-sun[1], -sun[0])
    polar = 0.5 * math.pi - elevation - math.radians(more_level_deg)
    axis = direction_from_angles(abs(polar), azimuth + (math.pi if polar < 0 else 0.0))
    rotation = rotation_z(math.atan2(axis[1], axis[0])) @ rotation_y(math.acos(axis[2]))
    centre = np.array([0.2, 0.0, 0.0]) - distance * sun
    return [homogeneous(rotation_z(yaw) @ rotation, centre) for yaw in yaws]


def run(quick=False):
    """Run every benchmark; return the flat dict of figures."""
    figures = {}
    lens = LensParameters()
    repeats = 3 if quick else 7

    samples = area_samples(lens, 1_000_000)
    sun = [0.1, 0.05, -1.0]
    trace(lens, samples, sun, plane_point=[0, 0, -0.08])  # warm up
    milliseconds = median_call_ms(
        lambda: trace(lens, samples, sun, plane_point=[0, 0, -0.08]), repeats)
    figures['trace_rays_per_s'] = len(samples) / (milliseconds * 1e-3)
    figures['trace_1e6_rays_ms_median'] = milliseconds

    estimator = SunEstimator(lens)
    rng = np.random.default_rng(0)
    suns = [-direction_from_angles(math.radians(rng.uniform(15.0, 55.0)),
                                   rng.uniform(0.0, 2.0 * math.pi)) for _ in range(20)]
    yaws = np.radians(np.arange(-25.0, 26.0, 5.0))
    for method in ('interaction_matrix', 'levenberg_marquardt'):
        single, sweep, errors = [], [], []
        for s in suns:
            one = [estimator.synthetic_observation(s, _sweep_poses(s, [0.0])[0])]
            many = [estimator.synthetic_observation(s, pose, noise=rng.normal(0, 5e-4, 2))
                    for pose in _sweep_poses(s, yaws)]
            single.append(median_call_ms(lambda: estimator.estimate(one, method), 1))
            start = time.perf_counter()
            result = estimator.estimate(many, method)
            sweep.append(time.perf_counter() - start)
            errors.append(math.degrees(math.acos(min(1.0, float(result.direction @ s)))))
        figures[f'estimate_{method}_1_spot_ms_median'] = float(np.median(single))
        figures[f'estimate_{method}_11_spot_sweep_ms_median'] = float(np.median(sweep)) * 1e3
        figures[f'estimate_{method}_11_spot_0.5mm_noise_error_deg_median'] = \
            float(np.median(errors))
        figures[f'estimate_{method}_11_spot_0.5mm_noise_error_deg_max'] = float(np.max(errors))

    d_lp = paper_sweep()
    spot_area_curve(lens, d_lp)
    figures['spot_area_sweep_35_points_ms_median'] = median_call_ms(
        lambda: spot_area_curve(lens, d_lp), repeats)

    rig = Rig()
    x = np.array([0.1, 0.5, 0.3, -0.2, 0.4])
    pose = rig.forward(x)
    count = 300 if quick else 2000
    start = time.perf_counter()
    for _ in range(count):
        rig.forward(x)
    figures['rig_forward_us_per_call'] = (time.perf_counter() - start) / count * 1e6
    start = time.perf_counter()
    for _ in range(count):
        rig.inverse(pose.T_robot_lens[:3, 3], pose.yaw, pose.pitch)
    figures['rig_inverse_us_per_call'] = (time.perf_counter() - start) / count * 1e6

    site = Site(46.5197, 6.6323)
    when = datetime.datetime(2026, 6, 21, 12, 0, tzinfo=datetime.timezone.utc)
    figures['ephemeris_sun_position_ms_per_call'] = median_call_ms(
        lambda: sun_position(site, when), 20)
    return figures


def main(args=None):
    """Parse arguments, run, print and optionally write JSON."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    add_json_option(parser)
    parser.add_argument('--quick', action='store_true', help='fewer repetitions')
    options = parser.parse_args(args)
    return report(run(options.quick), options.json, machine=True)


if __name__ == '__main__':
    raise SystemExit(main())
