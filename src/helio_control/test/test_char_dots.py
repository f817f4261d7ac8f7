"""
Charred dots measured per target in frames the simulated world renders (issue 29, items 3-4).

Then dots of 1.0-3.0 mm, drawn and burnt by the world, measured without the bias the
clipped channels gave (the camera read dots 12-25 % small). Last, the expected size a dot
is judged against (``dot_check``).

The world's char is set as discs of known size at known places (the camera renders char
wherever the char map has it), at 2 mm pitch (touching) and 3 mm pitch, a target left bare,
a dot far too small; the RGB frame is taken with the lens retreated 3 cm over each target
(its shadow and the defocused spot around the target). Each measure is judged by the
world's char map measured the same way per target (``measure_in_mask``): no ROS.
"""

from dataclasses import replace

from helio_control.dot_check import expected_dot
from helio_control.plan import load_plan_options, plan_dots
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import SimSettings, SimWorld
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
from helio_perception.char_dots import CharSettings, measure_in_image, measure_in_mask
from helio_perception.char_dots import measure_targets_in_mask
import numpy as np
import pytest

EXPECTED = 0.002          # the expected diameter [m]
# (x, y) [m] and the drawn diameter [m] (0: bare)
ROW_2MM = [((0.070 + 0.002 * i, 0.080), d) for i, d in
           enumerate((2.0e-3, 2.2e-3, 0.0, 1.8e-3, 2.0e-3))]
ROW_3MM = [((0.070 + 0.003 * i, 0.086), d) for i, d in
           enumerate((2.0e-3, 2.5e-3, 0.5e-3, 1.6e-3))]


@pytest.fixture(scope='module')
def world():
    """Return a world with the rows' char drawn into its char map."""
    world = SimWorld(replace(SimSettings(), flux_rays=8000),
                     load_rig_parameters(default_rig_file()))
    panel = world.panel
    xs, ys = panel.raster_pixel_centres()
    grid_x, grid_y = np.meshgrid(xs, ys)
    for (x, y), diameter in ROW_2MM + ROW_3MM:
        if diameter:
            panel.char[np.hypot(grid_x - x, grid_y - y) <= diameter / 2] = 1.0
    world.rgb.update_char(panel.char, (0, panel.char.shape[0], 0, panel.char.shape[1]))
    return world


def truth_of(world, target, neighbours):
    """Return the world's char map's measure of the dot at `target`."""
    panel = world.panel
    return measure_in_mask(panel.charred_mask(), panel.raster_origin, panel.grid.fine_cell,
                           target, EXPECTED, neighbours)


@pytest.mark.parametrize('row', [ROW_2MM, ROW_3MM], ids=['2mm', '3mm'])
def test_each_target_measured_in_a_frame_as_the_char_map_has_it(world, row):
    targets = [target for target, _ in row]
    for target, drawn in row:
        neighbours = [t for t in targets if t != target]
        world.set_joints(true_sun_focus_joints(world, target, 0.112))   # retreated 3 cm
        world.step()
        T_world_rgb, _ = world.camera_poses()
        seen = measure_in_image(world.rgb_image(), world.published_cameras['rgb'],
                                T_world_rgb, target, EXPECTED, neighbours)
        truth = truth_of(world, target, neighbours)
        print(f'{target}: drawn {drawn * 1e3:.2f} mm, char map {truth.diameter * 1e3:.2f} '
              f'mm, camera {seen.diameter * 1e3:.2f} mm ({seen.reason or "charred"})')
        assert seen.charred == truth.charred, (seen, truth)
        assert truth.charred == (drawn >= 0.5 * EXPECTED * 1.01)
        if truth.charred:
            # per target: the touching neighbours' char is theirs
            assert abs(truth.diameter - drawn) < 0.15e-3
            assert abs(seen.diameter - truth.diameter) < 0.10 * truth.diameter
            assert np.hypot(*(np.subtract(seen.centre, truth.centre))) < 0.3e-3
        elif not drawn:
            assert seen.diameter < 0.2 * EXPECTED and 'no char' in seen.reason


def look_from_the_retreated_lens(world, target, expected, neighbours=()):
    """Return the camera's measure of the dot at `target`, the lens retreated 3 cm over it."""
    world.set_joints(true_sun_focus_joints(world, target, 0.112))
    world.step()
    T_world_rgb, _ = world.camera_poses()
    return measure_in_image(world.rgb_image(), world.published_cameras['rgb'], T_world_rgb,
                            target, expected, neighbours)


SIZES = np.round(np.arange(1.0, 3.01, 0.25), 2) * 1e-3      # drawn diameters [m]


def test_dots_of_1_to_3_mm_measure_as_the_char_map_has_them():
    # each size at three places, off the camera's pixel grid at random (seeded); each dot
    # judged against its own size, as the painter judges a calibrated dot
    world = SimWorld(replace(SimSettings(), flux_rays=8000, seed=3),
                     load_rig_parameters(default_rig_file()))
    panel = world.panel
    grid_x, grid_y = np.meshgrid(*panel.raster_pixel_centres())
    rng = np.random.default_rng(11)
    dots = []
    for k, diameter in enumerate(np.repeat(SIZES, 3)):
        target = (0.05 + 0.008 * (k % 9) + rng.uniform(0.0, 0.5e-3),
                  0.06 + 0.008 * (k // 9) + rng.uniform(0.0, 0.7e-3))
        panel.char[np.hypot(grid_x - target[0], grid_y - target[1]) <= diameter / 2] = 1.0
        dots.append((target, diameter))
    world.rgb.update_char(panel.char, (0, panel.char.shape[0], 0, panel.char.shape[1]))
    ratios = {}
    for target, diameter in dots:
        seen = look_from_the_retreated_lens(world, target, diameter)
        truth = measure_in_mask(panel.charred_mask(), panel.raster_origin,
                                panel.grid.fine_cell, target, diameter)
        print(f'drawn {diameter * 1e3:.2f} mm: char map {truth.diameter * 1e3:.2f} mm, '
              f'camera {seen.diameter * 1e3:.2f} mm ({seen.reason or "charred"})')
        assert truth.charred
        ratios.setdefault(diameter, []).append(
            (seen.diameter / truth.diameter, seen.charred == truth.charred))
    for diameter, measured in ratios.items():
        ratio = np.array([r for r, _ in measured])
        agree = [a for _, a in measured]
        if diameter >= 1.5e-3:
            # unbiased: the mean of the three within 5 %; one dot within 15 % (the world
            # samples the panel at the pixels' centres, 0.28 x 0.67 mm there: no camera
            # integrates less)
            assert abs(np.mean(ratio) - 1.0) < 0.05, (diameter, ratio)
            assert np.all(np.abs(ratio - 1.0) < 0.15), (diameter, ratio)
            assert all(agree), (diameter, ratio)
        else:
            # the blur (0.3 x 0.47 mm) leaves no dark core: found at two places of three
            # at least, within 25 % (measured: +8 to +20 %; the third not found)
            assert sum(agree) >= 2 and np.sum(np.abs(ratio - 1.0) < 0.25) >= 2, \
                (diameter, ratio)


def test_dots_the_world_burns_measure_as_its_char_map_has_them():
    # dots burnt at the true sun's focus (no ROS) for 1.5-120 s: 0.8-2.7 mm in the char map
    world = SimWorld(replace(SimSettings(), flux_rays=8000),
                     load_rig_parameters(default_rig_file()))
    panel = world.panel
    measured = []
    for k, dwell in enumerate((1.5, 3.0, 5.0, 8.0, 15.0, 30.0, 60.0, 120.0)):
        target = (0.055 + 0.008 * k, 0.075)
        world.set_joints(true_sun_focus_joints(world, target, 0.082))
        world.run(dwell)
        seen = look_from_the_retreated_lens(world, target, EXPECTED)
        world.run(2.0)
        seen = look_from_the_retreated_lens(world, target, EXPECTED)
        truth = measure_in_mask(panel.charred_mask(), panel.raster_origin,
                                panel.grid.fine_cell, target, EXPECTED)
        print(f'{dwell:5.1f} s: char map {truth.diameter * 1e3:.2f} mm, camera '
              f'{seen.diameter * 1e3:.2f} mm ({seen.reason or "charred"})')
        # the verdict against the plan's 2 mm (charred from 1.0 mm) agrees with the char map
        assert seen.charred == truth.charred, (dwell, seen, truth)
        if truth.diameter >= 1.45e-3:
            measured.append(seen.diameter / truth.diameter)
    assert len(measured) >= 5
    assert abs(np.mean(measured) - 1.0) < 0.05, measured
    assert np.all(np.abs(np.array(measured) - 1.0) < 0.12), measured


def test_touching_dots_are_measured_per_target_not_per_region(world):
    panel = world.panel
    targets = [target for target, _ in ROW_2MM]
    measures = measure_targets_in_mask(panel.charred_mask(), panel.raster_origin,
                                       panel.grid.fine_cell, targets, EXPECTED)
    drawn = [d for _, d in ROW_2MM]
    assert [m.charred for m in measures] == [d > 0 for d in drawn]
    for measure, diameter in zip(measures, drawn):
        assert abs(measure.diameter - diameter) < 0.15e-3


def test_a_target_out_of_the_frame_is_not_charred_and_says_why(world):
    world.set_joints(true_sun_focus_joints(world, (0.07, 0.08), 0.112))
    world.step()
    T_world_rgb, _ = world.camera_poses()
    seen = measure_in_image(world.rgb_image(), world.published_cameras['rgb'], T_world_rgb,
                            (0.5, 0.5), EXPECTED)
    assert not seen.charred and 'out of the image' in seen.reason


def test_settings_that_cannot_measure_are_refused():
    with pytest.raises(ValueError):
        CharSettings(dark_ratio=0.0)


def test_a_dots_expected_size_follows_its_n_p_target_and_its_neighbours_are_the_plans():
    targets = np.array([[0.06 + 0.002 * i, 0.08] for i in range(6)] + [[0.06, 0.1]])
    plan = plan_dots(targets, replace(load_plan_options(), n_p_target=15), None, None)
    index = int(np.argmin(np.hypot(*(plan.dots - [0.064, 0.08]).T)))
    expected, neighbours = expected_dot(plan, index)
    # the world burns 1.40 mm at N_p 15 (test/test_painter.py): 2 mm x sqrt(15 / 30)
    assert expected == pytest.approx(0.002 * np.sqrt(0.5))
    assert sorted(np.round(neighbours[:, 0], 4)) == [0.062, 0.066]     # within 2.5 x 1.41 mm
