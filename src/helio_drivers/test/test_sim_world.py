"""The simulated world end to end: clouds, determinism, canvas output, hosted devices."""

import collections
import concurrent.futures
import copy
from dataclasses import replace
import math

import cv2
from helio_drivers.sim.cameras import CHAR_RGB, DevelopingFrame, light_window, NoisyReadOut
from helio_drivers.sim.truth import true_sun_focus_joints
from helio_drivers.sim.world import settings_from_flat, SimSettings, SimWorld
from helio_optics.ground_render import (decode_srgb8, GroundRenderer, GroundTexture,
                                        make_panel_texture, Webcam)
from helio_optics.rig_kinematics import default_rig_file, load_rig_parameters
import numpy as np
import pytest

RIG_YAML = default_rig_file()
FAST = SimSettings(flux_rays=8000, step=0.1)


def rig_parameters():
    """Return the rig of the workspace's config/rig.yaml."""
    return load_rig_parameters(RIG_YAML)


def test_a_cloud_drops_the_flux_to_its_attenuation_within_one_step():
    settings = replace(FAST, cloud_schedule=(1.05, 3.0, 0.3))
    world = SimWorld(settings, rig_parameters())
    world.set_joints(true_sun_focus_joints(world, [0.06, 0.06, 0.0], 0.082))
    powers = []
    for _ in range(12):
        world.step()
        powers.append(float(np.sum(world.panel._last_irradiance * world.panel.cell_areas)))
    # steps end at 0.1 .. 1.2 s: the one ending at 1.1 s is the first under the cloud
    assert powers[9] == pytest.approx(powers[8], rel=1e-9)
    assert powers[10] == pytest.approx(0.3 * powers[9], rel=1e-9)
    assert powers[11] == pytest.approx(powers[10], rel=1e-9)


def test_the_world_is_deterministic_for_a_seed():
    images = []
    for _ in range(2):
        world = SimWorld(FAST, rig_parameters())
        world.set_joints(true_sun_focus_joints(world, [0.05, 0.07, 0.0], 0.082))
        world.run(1.0)
        images.append((world.thermal_image(), world.rgb_image()))
    assert np.array_equal(images[0][0], images[1][0])
    assert np.array_equal(images[0][1], images[1][1])


def test_within_one_instant_the_joint_source_is_read_once_for_the_step_and_its_outputs():
    world = SimWorld(FAST, rig_parameters())
    start = true_sun_focus_joints(world, [0.07, 0.07, 0.0], 0.082)
    reads = []

    def drifting_joints():      # an arm that moves between any two reads
        reads.append(start + 0.002 * len(reads))
        return reads[-1]
    world.attach_joint_source(drifting_joints)
    with world.one_instant():
        world.step()
        poses = world.camera_poses()
        frame = world.stage_rgb_frame()
        world.thermal_image()
        assert len(reads) == 1 and np.array_equal(world.joint_positions(), reads[0])
    # the outputs are those of the joints read at the step, by the rig's own kinematics
    expected = world.rig.forward(reads[0])
    assert np.allclose(poses[0], world.T_world_robot @ expected.T_robot_rgb)
    assert np.allclose(poses[1], world.T_world_robot @ expected.T_robot_thermal)
    frame()
    # outside it, every read asks the source again
    world.camera_poses()
    world.camera_poses()
    assert len(reads) == 3 and np.array_equal(world.joint_positions(), reads[3])


def test_a_held_focus_chars_a_dot_written_to_the_canvas_outputs(tmp_path):
    world = SimWorld(FAST, rig_parameters())
    world.set_joints(true_sun_focus_joints(world, [0.07, 0.05, 0.0], 0.082))
    world.step()
    spot = world.flux_field.centroid()
    world.run(12.0)
    world.set_joints(true_sun_focus_joints(world, [0.07, 0.05, 0.0], 0.112))  # retreat 3 cm
    world.run(3.0)
    png, csv = world.write_outputs(str(tmp_path))
    mask = cv2.imread(str(tmp_path / 'canvas_mask.png'), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(mask, world.canvas_image())
    # the compiled canvas against the char raster flipped, scaled and rounded by numpy
    expected = np.flipud(np.rint(255.0 * (1.0 - world.panel.char))).astype(np.uint8)
    assert np.array_equal(world.canvas_image(), expected) and expected.min() < 128
    rows = np.loadtxt(csv, delimiter=',', comments='#', skiprows=2, ndmin=2)
    assert rows.shape == (1, 4)
    x, y, diameter, _ = rows[0]
    print(f'dot at ({x * 1e3:.2f}, {y * 1e3:.2f}) mm, light at ({spot[0] * 1e3:.2f}, '
          f'{spot[1] * 1e3:.2f}) mm, diameter {diameter * 1e3:.2f} mm')
    assert math.hypot(x - spot[0], y - spot[1]) < 0.3e-3
    assert 0.5e-3 < diameter < 4e-3
    # canvas.png is the panel as a person sees it: the same pixels (square, top view)
    picture = cv2.imread(png, cv2.IMREAD_COLOR)
    assert picture.shape[:2] == mask.shape
    grey = cv2.cvtColor(picture, cv2.COLOR_BGR2GRAY).astype(float)
    charred = mask == 0
    column, row = (np.array([x, world.panel.extent[3] - y]) / 2e-4
                   - [world.panel.extent[0] / 2e-4, 0]).astype(int)
    bare_wood = grey[row - 40:row + 40, column - 40:column + 40][
        ~charred[row - 40:row + 40, column - 40:column + 40]]
    assert charred.sum() > 10 and grey[charred].mean() < 0.5 * np.median(bare_wood)
    hue = cv2.cvtColor(picture, cv2.COLOR_BGR2HSV)[row - 40:row - 20, column, 0]
    assert np.all((hue > 5) & (hue < 30))      # the wood around it is wood-coloured
    # and the marker reads back where the world put it: 40 mm centred on the origin
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(
        cv2.aruco.DICT_4X4_50), cv2.aruco.DetectorParameters())
    corners, ids, _ = detector.detectMarkers(cv2.cvtColor(picture, cv2.COLOR_BGR2GRAY))
    assert ids is not None and list(ids.ravel()) == [0]
    x_min, _, _, y_max = world.panel.extent
    expected = (np.array([[-0.02, 0.02], [0.02, 0.02], [0.02, -0.02], [-0.02, -0.02]])
                - [x_min, y_max]) / [2e-4, -2e-4] - 0.5
    assert np.abs(corners[0][0] - expected).max() < 1.0


def test_flat_parameters_round_trip_and_unknown_names_are_refused():
    settings = settings_from_flat({'dni': 700.0, 'wood.density': 500.0,
                                   'lens.aperture_diameter': 0.05,
                                   'cloud_schedule': [1.0, 2.0, 0.5]})
    assert settings.dni == 700.0 and settings.wood.density == 500.0
    assert settings.lens.aperture_diameter == 0.05 and settings.cloud_schedule == (1.0, 2.0, 0.5)
    with pytest.raises(ValueError, match='unknown sim parameter'):
        settings_from_flat({'wood.colour': 1.0})
    with pytest.raises(ValueError, match='UTC offset'):
        SimWorld(replace(FAST, start_time='2026-06-21T10:00:00'), rig_parameters())


def straightforward_rgb(world, light, attenuation, rng=None):
    """
    Return the RGB frame of the world rendered whole from scratch (the truth).

    The panel's light built pixel by pixel of the char raster (wood and marker from the
    texture generator, char colour, sky + attenuation x direct sun, the light window),
    every image pixel's ray cast onto it (no homography), then the webcam's optics and
    read-out (with noise: the linearised read-out's, noise drawn by `rng`): nothing of the
    camera's kept state or partial renders.
    """
    s = world.settings.rgb
    wood = decode_srgb8(make_panel_texture(
        extent=world.panel.extent, metres_per_pixel=world.settings.grid.fine_cell,
        marker_side=world.settings.marker_side, marker_id=world.settings.marker_id,
        dictionary=world.settings.marker_dictionary, seed=world.settings.seed,
        print_reflectance=world.settings.marker_print_reflectance).image)
    chi = np.asarray(world.panel.char, dtype=np.float32)[:, :, None]   # rows from y_min
    albedo = np.flipud(wood) * (1.0 - chi) + decode_srgb8(np.array([CHAR_RGB], np.uint8)) * chi
    direct = np.ones(chi.shape[:2], np.float32)
    if light is not None:
        rows, cols, lit = light
        direct[rows, cols] = lit
    irradiance = (s.diffuse_fraction + attenuation * direct) / (1.0 + s.diffuse_fraction)
    texture = GroundTexture(image=np.flipud(s.exposure * albedo * irradiance[:, :, None]),
                            extent=world.panel.extent, linear=True)
    camera = s.camera()
    T_world_rgb, _ = world.camera_poses()
    renderer = GroundRenderer(camera, supersample=1)
    radiance = renderer.radiance(T_world_rgb, texture, background=0.0)
    webcam = Webcam(s.webcam(world.settings.seed + 7), camera)
    if rng is None:
        return webcam.sensor(webcam.optics(radiance))
    read_out = NoisyReadOut(webcam, (s.height, s.width, 3), world.settings.seed + 7)
    return read_out.expose(read_out.prepare(webcam.optics(radiance)), rng)


@pytest.mark.parametrize('noise', [False, True])
def test_kept_rgb_frames_of_a_painting_equal_a_straightforward_render(noise):
    """
    The RGB camera's kept and partly redone frames against a whole render from scratch.

    Along a dot heated until it chars, under a cloud, after a move that re-centres the heat
    patch and while the next dot heats: the same frames within the ray cast's and the
    homography's different rounding of the sample points (OpenCV 5 samples both at the
    float coordinates): at most a level apart. With
    noise, the same noise (the same draws) on the same light.
    """
    settings = SimSettings()
    if not noise:
        settings = replace(settings, rgb=replace(settings.rgb, read_noise=0.0,
                                                 full_well_electrons=0.0))
    world = SimWorld(settings, rig_parameters())
    dots = ([0.07, 0.07, 0.0], [0.076, 0.07, 0.0])
    world.set_joints(true_sun_focus_joints(world, dots[0], 0.082))
    checks = {1.0: 'spot', 14.0: 'char', 16.0: 'cloud', 17.0: 'moved', 20.0: 'next dot'}
    centres, seen = [], set()
    for k in range(1, 201):
        world.step()
        now = round(world.time, 6)
        if now == 15.0:
            world.set_cloud_schedule([now, now + 1.5, 0.3])
        if now == 16.5:
            centres.append(tuple(world.panel.centre))
            world.set_joints(true_sun_focus_joints(world, dots[1], 0.082))
        if k % 2:
            continue
        draws = copy.deepcopy(world._rng) if noise else None
        frame = world.rgb_image()
        if now in checks:
            seen.add(checks[now])
            attenuation = world.dni_now() / world.sun.dni
            expected = straightforward_rgb(world, world._light, attenuation, draws)
            difference = np.abs(frame.astype(int) - expected.astype(int))
            # measured: at most 1 level apart, under 1e-4 of a level on average
            assert difference.max() <= 2 and difference.mean() < 0.01, checks[now]
            if noise:      # and the noise is there
                assert np.abs(frame.astype(int) - straightforward_rgb(
                    world, world._light, attenuation, np.random.default_rng(5))).mean() > 0.5
            # the spot: the same saturated pixels
            saturated = np.all(frame == 255, axis=2)
            assert np.array_equal(saturated, np.all(expected == 255, axis=2)), checks[now]
            if checks[now] in ('spot', 'next dot'):
                assert np.count_nonzero(saturated) > 20
    assert seen == set(checks.values())
    assert world.panel.charred_mask().any()
    assert tuple(world.panel.centre) != centres[0]     # the move re-centred the patch
    assert world.rgb.renders['parts'] > 40             # the char was redone in parts


def test_rgb_frames_developed_on_a_thread_while_the_world_steps_equal_rendered_ones():
    """
    ``stage_rgb_frame`` then developing on another thread, as the node does, changes no frame.

    Two worlds of one seed along a dot heated until it chars, under a cloud, and a move to
    the next dot: one renders each frame at once (``rgb_image``); the other stages it and
    develops it on a worker thread, two frames in flight, while it takes its next steps
    and thermal frames (which draw from the same random generator). Every frame equal,
    bit for bit.
    """
    worlds = [SimWorld(SimSettings(), rig_parameters()) for _ in range(2)]
    dots = ([0.07, 0.07, 0.0], [0.076, 0.07, 0.0])
    for world in worlds:
        world.set_joints(true_sun_focus_joints(world, dots[0], 0.082))
    rendered, developed, pending = [], [], collections.deque()
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as worker:
        for k in range(1, 181):
            for world in worlds:
                world.step()
                now = round(world.time, 6)
                if now == 9.0:
                    world.set_cloud_schedule([now, now + 1.5, 0.3])
                if now == 15.0:
                    world.set_joints(true_sun_focus_joints(world, dots[1], 0.082))
                if k % 3 == 0:
                    world.thermal_image()
            if k % 2:
                continue
            rendered.append(worlds[0].rgb_image())
            if len(pending) == 2:
                developed.append(pending.popleft().result())
            pending.append(worker.submit(worlds[1].stage_rgb_frame()))
        developed.extend(job.result() for job in pending)
    assert worlds[1].panel.charred_mask().any()
    assert worlds[1].rgb.renders == worlds[0].rgb.renders
    assert worlds[0].rgb.renders['parts'] > 10 and worlds[0].rgb.renders['whole'] > 3
    assert len(developed) == len(rendered) == 90
    for k, (expected, frame) in enumerate(zip(rendered, developed)):
        assert np.array_equal(frame, expected), f'frame {k}'


def test_staged_rgb_frames_nobody_develops_are_developed_in_order_when_asked():
    twin = SimWorld(FAST, rig_parameters())
    world = SimWorld(FAST, rig_parameters())
    expected, staged = [], []
    for k in range(4):
        for each in (twin, world):
            each.set_joints(true_sun_focus_joints(each, [0.05 + 0.001 * (k // 2), 0.07, 0.0],
                                                  0.082))
            each.step()
        expected.append(twin.rgb_image())
        staged.append(world.stage_rgb_frame())     # left alone: no thread develops them
    assert not any(frame.done() for frame in staged)
    assert np.array_equal(staged[2](), expected[2])   # develops the first three, in order
    assert [frame.done() for frame in staged] == [True, True, True, False]
    for frame, image in zip(staged, expected):
        assert np.array_equal(frame(), image)
        assert np.array_equal(frame(), image)     # called again: the same image, not redone
    assert world.rgb.renders == twin.rgb.renders


def test_an_rgb_frame_that_fails_to_develop_raises_to_every_caller():
    frame = DevelopingFrame(lambda: 1 / 0)
    for _ in range(2):
        with pytest.raises(ZeroDivisionError):
            frame()


@pytest.mark.parametrize('target, d_lp', [((0.07, 0.07), 0.082), ((0.02, 0.1), 0.075),
                                          ((-0.035, 0.155), 0.082)],
                         ids=['focused', 'defocused', 'at_the_corner'])
def test_the_light_window_is_the_shadow_and_the_rays_blurred_over_the_whole_window(
        target, d_lp):
    """light_window bins and blurs the rays over their own box: as over the whole window."""
    world = SimWorld(FAST, rig_parameters())
    world.set_joints(true_sun_focus_joints(world, target, d_lp))
    world.step()
    field, panel = world.flux_field, world.panel
    cell, origin = panel.grid.fine_cell, panel.raster_origin
    rows, cols, lit = light_window(field, panel.raster_shape, origin, cell,
                                   world._light_window(field))
    # independently: every pixel centre's shadow test, numpy's histogram of all the rays
    # over the whole window, the same smoothing over the whole window
    x = origin[0] + (np.arange(cols.start, cols.stop) + 0.5) * cell
    y = origin[1] + (np.arange(rows.start, rows.stop) + 0.5) * cell
    shadow = field.in_shadow(x[None, :], y[:, None])
    x_edges = origin[0] + np.arange(cols.start, cols.stop + 1) * cell
    y_edges = origin[1] + np.arange(rows.start, rows.stop + 1) * cell
    keep = np.all(np.isfinite(field.points), axis=1)
    binned, _, _ = np.histogram2d(field.points[keep, 1], field.points[keep, 0],
                                  bins=(y_edges, x_edges), weights=field.power[keep])
    concentrated = cv2.GaussianBlur((binned / cell ** 2 / field.direct).astype(np.float32),
                                    (0, 0), 0.7)
    expected = np.where(shadow, 0.0, 1.0) + concentrated
    assert lit.dtype == np.float32 and lit.shape == expected.shape
    assert 0.1 < np.mean(shadow) < 0.9 and lit.max() > 10.0     # a shadow, and a spot
    assert np.allclose(lit, expected, rtol=1e-6, atol=1e-6)
