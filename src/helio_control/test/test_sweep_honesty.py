"""
The sun estimate over sweeps under random suns, judged by the simulated world (issue 35).

Rendered webcam frames through the spot detector's own code, the observations as the
sun_estimator node builds them, the estimator with the node's noise model; the judge is the
world's TRUE sun, which nothing on the controller side reads. A small sample with a fixed
seed (the benchmark, ``python -m helio_control.sweep_honesty``, runs 200 and more).
"""

import datetime
import math

from helio_control.sweep_honesty import angle_deg, image_sweep, observations_of, run
from helio_control.sweep_honesty import SweepRunner
from helio_optics.centre_noise import CentreNoise
from helio_optics.sun_estimation import TrustSettings
import numpy as np
import pytest

SWEEPS = 10       # 5 tilted and 5 level-lens sweeps: about 20 s here


@pytest.fixture(scope='module')
def sample():
    """Return the rows of a fixed sample of sweeps (each with its Verdict per model)."""
    _, rows = run(SWEEPS, seed=35)
    return rows


def test_no_accepted_estimate_is_far_off_and_the_good_sweeps_are_accepted(sample):
    """Done when (issue 35): accepted <= 0.3 deg off; >= 95 % of those within 0.2 accepted."""
    after = [row['after'] for row in sample]
    for row in sample:
        verdict = row['after']
        assert not (verdict.accepted and verdict.error_deg > 0.3), (row, verdict.reason)
    good = [v for v in after if v.error_deg <= 0.2]
    assert len(good) >= SWEEPS // 2, 'the sample holds too few good sweeps to judge'
    accepted = sum(v.accepted for v in good)
    assert accepted >= 0.95 * len(good), [v.reason for v in good if not v.accepted]
    # every tilted sweep (the lens planner's) is usable and lands within 0.2 deg
    tilted = [row['after'] for row in sample if row['kind'] == 'tilted']
    assert all(v.accepted and v.error_deg <= 0.2 for v in tilted), [v.reason for v in tilted]


def test_the_chi_square_of_the_good_sweeps_averages_its_degrees_of_freedom(sample):
    """
    The measured noise makes the chi-square what its test assumes: about its dof.

    The sweeps within 0.2 deg of the true sun fit within their noise, so their pooled
    chi-square over pooled degrees of freedom is near 1 (the tilted sweeps give 1.0-1.1
    over 200 sweeps, the level ones 0.8); with the old 0.5 mm per frame it was a few
    hundredths: no fit could fail it.
    """
    def ratio(model):
        fitted = [row[model] for row in sample
                  if row[model].error_deg <= 0.2 and row[model].dof > 0]
        return sum(v.chi2 for v in fitted) / sum(v.dof for v in fitted)

    assert 0.6 < ratio('after') < 1.6
    assert ratio('before') < 0.1


def test_spots_of_a_moving_sun_taken_as_fixed_are_refused_not_averaged():
    """
    A wrong minimum: half a sweep imaged 150 s after the other, the sun taken as fixed.

    The sun moves about 0.75 deg between the first and the last frame; a fit that ignores it
    lands between the suns of the two halves, a quarter to half a degree from each (their
    spots 0.3-0.7 mm off it). With the old 0.5 mm per frame such a fit passed the chi-square
    test (47 for 46 degrees of freedom here, 0.33 and 0.43 deg off); with the measured noise
    it is refused. The same frames moved to one time by Eq 18 (the ephemeris at the site)
    give the true sun, accepted.
    """
    runner = SweepRunner()
    sweep = runner.sweep('tilted', np.random.default_rng(8))
    world, half = sweep.world, len(sweep.poses) // 2
    first = [f for f in sweep.frames if f.pose < half]
    world.clock.advance(150.0)
    later = image_sweep(world, runner.rig, world.rgb.camera, sweep.poses[half:],
                        sweep.T_robot_world)
    frames = first + later
    assert sum(f.valid for f in frames) >= 0.8 * len(frames)
    assert angle_deg(first[0].true_ray_robot, later[-1].true_ray_robot) > 0.6
    start = datetime.datetime.fromisoformat(sweep.sky.start_time)
    noise = CentreNoise()
    trust = TrustSettings(max_chief_ray_tilt=noise.max_tilt)
    fixed, _, _ = observations_of(frames, runner.rig, sweep.T_robot_world, None, start, noise)
    result = runner.estimator.estimate(fixed, trust=trust)
    # the fit is wrong for both halves: more than 0.2 deg from the sun of each
    assert min(angle_deg(result.direction, first[0].true_ray_robot),
               angle_deg(result.direction, later[-1].true_ray_robot)) > 0.2
    assert not result.trustworthy and 'chi-square' in result.reason, result.reason
    corrected, reference, _ = observations_of(frames, runner.rig, sweep.T_robot_world,
                                              sweep.sky.site(), start, noise)
    result = runner.estimator.estimate(corrected, trust=trust)
    assert result.trustworthy, result.reason
    assert angle_deg(result.direction, runner.truth_at(sweep, reference)) < 0.2
    assert math.isfinite(result.chi2) and result.chi2 <= result.chi2_threshold
