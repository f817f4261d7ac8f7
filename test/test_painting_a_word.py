"""
A sample word painted through /paint by the whole simulated graph (issue 13's main figure).

Every node runs as its own process (``sim_world``, both drivers on the emulated devices'
ptys, ``spot_detector``, ``thermal_monitor``, ``sun_estimator``, ``lens_planner``,
``painter``). The painter calibrates robot-world from the marker, estimates the sun with the
sweep (the world's sun is hidden from every controller node), plans ``sample:text`` (the
word "SUN") at a 3 mm pitch and burns it with Algorithm 1 and the window cooling rule (no
wait; the next dot never in the last one's hot region). The truth is the world's char map
(``sim/canvas``): every planned dot must be charred, on its target (mean placement error at
most 0.3 mm, the paper's mean errors being 0.99 mm of spacing and 0.61 mm laterally) and of
an even size (coefficient of variation of the diameters at most 10 %).

The dots are burnt to N_p 20, not the paper's 30 (the demo's default): this test is about
placing 45 dots through every node and closing the loop on each, and N_p 30's dwell (16 s
of simulated time a dot, of which the last 10 s add pixels one by one) doubled its time for
nothing more: 884 s simulated for the paper rule's painting at N_p 30 against 477 s at
N_p 20 (1.61 mm dots, CV 1.3 %). N_p 30 is burnt by ``test_painter.py``'s rows, the rule
comparison and its cycle estimate. At N_p 15 (1.40 mm) the dots were no longer even (CV
11.4 %): the 3 s dwell is then a few thermal frames, and one frame more or less shows.

The word is painted once, with the window rule: with the paper's rule it took 60 % longer
(182 s against 116 s in a fresh run of the suite) for the same placement through the same
nodes. The paper's rule is painted by ``test_painter.py`` (the rule comparison) and by
``helio paint`` in ``test_operator_tools.py`` (the default rule).
"""

import math

from geometry_msgs.msg import Point
from helio_control.plan import Plan
import numpy as np
import pytest
from test_painter import dots_at, painting_graph

PICTURE = 'sample:text'
PITCH = 0.003                 # dot pitch [m]: 1.6 mm dots 1.4 mm apart, each measurable alone
N_P_TARGET = 20               # N_p per dot (see above)


@pytest.fixture(scope='module')
def painting(tmp_path_factory):
    """Run the whole graph for the module."""
    with painting_graph(tmp_path_factory.mktemp('word')) as session:
        yield session


# The word's dots lie 9-27 mm above offset_y. Below y = 0.07 m, at this sun, the wrist branch
# some poses take shows the thermal camera the panel so slanted that N_p (a pixel count) can
# stay under the target (test_painter_safety.py): with the word at offset 0.05 one dot at
# y 0.059 reached N_p 15 of 20 in 90 s and failed, 1 run of 5 (2026-11-27; issue 29 is about
# N_p's dependence on the thermal camera's view). The painting lies above it.
def test_a_sample_word_is_painted_with_every_dot_charred_on_target_and_even(painting):
    # the window rule's plan keeps each next dot out of the last one's hot region (7.5 mm),
    # where the shortest tour steps closer 43 times in 44
    cooling, offset_y = 'window', 0.092
    name = f'word_{cooling}'
    result, journal = painting.paint(name, image_path=PICTURE, dot_radius=PITCH,
                                     cooling=cooling, offset_y=offset_y,
                                     n_p_target=N_P_TARGET)
    assert result.success, result.message
    # a clear sky read as a cloud costs a reheated dot, not a dot: printed, not asserted
    # (1 of 45 heatings in some runs, the window rule's, on a loaded machine)
    with open(painting.run_root / name / 'plan.json') as stream:
        plan = Plan.from_json(stream.read())
    planned = plan.dots
    assert plan.parameters['close_steps'] == 0
    assert len(planned) >= 40 and result.dots_planned == len(planned)
    assert result.dots_burnt == len(planned)
    assert [dot.outcome for dot in journal] == ['burnt'] * len(planned)
    assert all(dot.n_p_target == N_P_TARGET for dot in journal)
    targets = [Point(x=x, y=y, z=0.0) for x, y in planned]
    charred = dots_at(painting.charred_dots(), targets, radius=0.45 * PITCH)
    missing = [i for i, dot in enumerate(charred) if dot is None]
    assert not missing, f'planned dots without char: {missing}'
    assert len({(d.x, d.y) for d in charred}) == len(targets), 'two targets share a char blob'
    errors = np.array([math.hypot(d.x - t.x, d.y - t.y) for d, t in zip(charred, targets)])
    diameters = np.array([d.diameter for d in charred])
    spread = float(np.std(diameters) / np.mean(diameters))
    cycles = np.diff([dot.start for dot in journal] + [journal[-1].end])
    print(f'\n{result.message} (cloud wait {result.cloud_wait:.1f} s)\n{cooling} rule, '
          f'{len(targets)} dots: placement error mean '
          f'{errors.mean() * 1e3:.3f} mm, max {errors.max() * 1e3:.3f} mm (first 10 dots '
          f'{errors[:10].mean() * 1e3:.3f}, last 10 {errors[-10:].mean() * 1e3:.3f}); '
          f'diameter {diameters.mean() * 1e3:.2f} mm, CV {spread * 100:.1f} %; '
          f'{cycles.mean():.1f} s per dot (sim)')
    assert errors.mean() <= 0.3e-3
    assert spread <= 0.10
