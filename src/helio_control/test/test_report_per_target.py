"""
The run report measures touching dots per target (issue 29).

At a 2 mm pitch the connected regions of the char map used to read as half the dots missing
and a diameter CV of 44 %.

A row of dots 2 mm apart, drawn 2.1 mm wide into the simulated world's char map (they
touch: one connected region each side of a target left bare), written as the world writes
its outputs (``canvas_mask.png``, ``dots.csv``); the summary's counts, diameters and CV
against the dots as drawn.
"""

from dataclasses import replace
import json

from helio_control.plan import load_plan_options, plan_dots
from helio_control.report import make_report
from helio_control.run_journal import JournalWriter
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
import numpy as np
import pytest

DRAWN = 2.1e-3     # [m]
BARE = 3           # the target left without char


def test_touching_dots_are_counted_and_sized_per_target(tmp_path):
    targets = np.array([[0.06 + 0.002 * i, 0.08] for i in range(8)])
    plan = plan_dots(targets, load_plan_options(), None, None)
    (tmp_path / 'plan.json').write_text(plan.to_json())
    world = SimWorld(replace(SimSettings(), flux_rays=2000),
                     load_rig_parameters(default_rig_file()))
    xs, ys = world.panel.raster_pixel_centres()
    grid_x, grid_y = np.meshgrid(xs, ys)
    bare = plan.dots[BARE]
    for target in plan.dots:
        if not np.allclose(target, bare):
            world.panel.char[np.hypot(grid_x - target[0], grid_y - target[1]) <= DRAWN / 2] = 1
    world.write_outputs(str(tmp_path))
    with JournalWriter(str(tmp_path / 'journal.jsonl')) as journal:
        journal.run({'points': targets.tolist()}, 0.0, 0.0, dot_calibration_s=3.0)
        for index, target in enumerate(plan.dots.tolist()):
            journal.dot(index=index, target=target, n_p_target=30, start=index,
                        end=index + 1.0, dwell=0.5, peak_n_p=30, t_max=180.9,
                        outcome='burnt',
                        verdict='charred' if index != BARE else 'not charred',
                        measured_diameter=1.8e-3 if index != BARE else 0.0)
        journal.result(success=False, dots_burnt=8, dots_skipped=0, duration=8.0,
                       wall_duration=1.0, message='')
    summary = make_report(str(tmp_path)).summary
    print(json.dumps(summary, indent=1))
    assert summary['measured_per'] == 'target'
    assert summary['charred_dots_seen'] == 2            # two connected regions of char
    assert summary['dots_without_char'] == 1            # one target bare, seven charred
    # each target's share of the touching char: 2.1 mm discs cut at the 2 mm pitch
    assert abs(summary['diameter_mean_m'] - DRAWN) < 0.1e-3
    assert summary['diameter_cv'] < 0.05
    assert summary['mean_placement_error_m'] < 0.1e-3
    assert summary['dots_verified_by_camera'] == 7 and summary['dots_camera_not_charred'] == 1
    assert summary['camera_diameter_mean_m'] == pytest.approx(1.8e-3)
    assert summary['dots_not_verified'] == 0
    # the goal took 8 s, 3 s of which the dot-size test row before the plan: the painting
    # the plan estimated took 5 s
    assert summary['dot_calibration_time_s'] == 3.0 and summary['painting_time_s'] == 5.0
    assert summary['estimate_error_ratio'] == pytest.approx(
        (plan.time_estimate['total_s'] - 5.0) / 5.0)
