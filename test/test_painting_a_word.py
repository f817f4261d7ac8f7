"""
A sample word painted through /paint by the whole simulated graph (issue 13's main figure).

Every node runs as its own process (``sim_world``, both drivers on the emulated devices'
ptys, ``spot_detector``, ``thermal_monitor``, ``sun_estimator``, ``lens_planner``,
``painter``). The painter calibrates robot-world from the marker, estimates the sun with the
sweep (the world's sun is hidden from every controller node), plans ``sample:text`` (the
word "SUN") at a 3 mm pitch and burns it with Algorithm 1. The truth is the world's char map
(``sim/canvas``): every planned dot must be charred, on its target (mean placement error at
most 0.3 mm, the paper's mean errors being 0.99 mm of spacing and 0.61 mm laterally) and of
an even size (coefficient of variation of the diameters at most 10 %).
"""

import math

from conftest import graph_of_processes
from geometry_msgs.msg import Point
from helio_control.plan import Plan
import numpy as np
import pytest
from test_painter import dots_at, NODES, Painting

PICTURE = 'sample:text'
PITCH = 0.003                 # dot pitch [m]: 2 mm dots 1 mm apart, each measurable alone


@pytest.fixture(scope='module')
def painting(tmp_path_factory):
    """Run the whole graph for the module."""
    tmp_path = tmp_path_factory.mktemp('word')
    overrides = {'sim_world': {'real_time_factor': 0.0, 'flux_rays': 20000,
                               'canvas_rate': 1.0},
                 'lens_planner': {'calibration_dir': str(tmp_path / 'calibration')}}
    with graph_of_processes(tmp_path, NODES, overrides) as (_, graph):
        yield Painting(graph, tmp_path / 'runs')


def test_a_sample_word_is_painted_with_every_dot_charred_on_target_and_even(painting):
    result, journal = painting.paint('word', image_path=PICTURE, dot_radius=PITCH)
    assert result.success, result.message
    with open(painting.run_root / 'word' / 'plan.json') as stream:
        planned = Plan.from_json(stream.read()).dots
    assert len(planned) >= 40 and result.dots_planned == len(planned)
    assert result.dots_burnt == len(planned)
    assert [dot.outcome for dot in journal] == ['burnt'] * len(planned)
    targets = [Point(x=x, y=y, z=0.0) for x, y in planned]
    charred = dots_at(painting.charred_dots(), targets, radius=0.45 * PITCH)
    missing = [i for i, dot in enumerate(charred) if dot is None]
    assert not missing, f'planned dots without char: {missing}'
    assert len({(d.x, d.y) for d in charred}) == len(targets), 'two targets share a char blob'
    errors = np.array([math.hypot(d.x - t.x, d.y - t.y) for d, t in zip(charred, targets)])
    diameters = np.array([d.diameter for d in charred])
    spread = float(np.std(diameters) / np.mean(diameters))
    cycles = np.diff([dot.start for dot in journal] + [journal[-1].end])
    print(f'\n{result.message}\n{len(targets)} dots: placement error mean '
          f'{errors.mean() * 1e3:.3f} mm, max {errors.max() * 1e3:.3f} mm (first 10 dots '
          f'{errors[:10].mean() * 1e3:.3f}, last 10 {errors[-10:].mean() * 1e3:.3f}); '
          f'diameter {diameters.mean() * 1e3:.2f} mm, CV {spread * 100:.1f} %; '
          f'{cycles.mean():.1f} s per dot (sim)')
    assert errors.mean() <= 0.3e-3
    assert spread <= 0.10
