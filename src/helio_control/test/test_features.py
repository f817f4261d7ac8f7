"""Feature modes against analytic truth: square outlines, medial lines, grey ramps, auto."""

import math

from helio_control.features import choose_mode
from helio_control.halftone import error_diffusion
from helio_control.plan import plan_picture, PlanOptions
import numpy as np
import pytest

PIXELS_PER_NODE = 10.0   # 400 px picture on a 40-dot (8 cm / 2 mm) canvas


def to_grid(x):
    """Picture coordinate (pixel edges at integers) -> grid coordinate (node centres)."""
    return np.asarray(x, dtype=float) / PIXELS_PER_NODE - 0.5


def options(mode):
    return PlanOptions(feature_mode=mode, ordering='nearest', v_axis='paper')


def distance_to_segments(points, segments):
    points = np.asarray(points, dtype=float)
    best = np.full(len(points), np.inf)
    for (ax, ay), (bx, by) in segments:
        a, b = np.array([ax, ay]), np.array([bx, by])
        t = np.clip(((points - a) @ (b - a)) / max((b - a) @ (b - a), 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=1))
    return best


def sample_segments(segments, step=0.05):
    samples = []
    for a, b in segments:
        count = max(2, int(math.dist(a, b) / step))
        samples.append(np.linspace(a, b, count))
    return np.vstack(samples)


@pytest.mark.parametrize('low, high', [(97, 283), (100, 300), (123, 241), (55, 346)])
def test_edges_of_a_filled_square_lie_within_half_a_pitch_of_its_outline(low, high):
    picture = np.full((400, 400), 255, np.uint8)
    picture[low:high, low:high] = 0
    plan = plan_picture(picture, options('edges'))
    a, b = to_grid(low), to_grid(high)    # the outline, in grid units
    outline = [((a, a), (b, a)), ((b, a), (b, b)), ((b, b), (a, b)), ((a, b), (a, a))]
    dots = plan.grid_uv.astype(float)
    assert np.max(distance_to_segments(dots, outline)) <= 0.5 + 1e-9
    # and the outline is drawn without gaps: every point of it has a dot within one pitch,
    # but at the corners, which thinning may round off
    gaps = np.min(np.linalg.norm(sample_segments(outline)[:, None] - dots[None], axis=2), 1)
    assert np.max(gaps) <= 2.0
    assert np.mean(gaps <= 1.0) >= 0.95


def ring_picture(centre, inner, outer, size=400, supersample=8):
    """Anti-aliased ring: each pixel's grey is the ring's area fraction (8 x 8 samples)."""
    offsets = (np.arange(supersample) + 0.5) / supersample
    y, x = np.mgrid[0:size, 0:size]
    ink = np.zeros((size, size))
    for dy in offsets:
        for dx in offsets:
            radius = np.hypot(x + dx - centre[0], y + dy - centre[1])
            ink += (radius >= inner) & (radius <= outer)
    return np.rint(255.0 * (1.0 - ink / supersample ** 2)).astype(np.uint8)


@pytest.mark.parametrize('centre, inner, outer', [
    ((200.0, 200.0), 120.0, 150.0), ((203.7, 196.2), 95.0, 131.0)])
def test_centerline_of_a_thick_ring_lies_within_half_a_pitch_of_its_medial_circle(
        centre, inner, outer):
    plan = plan_picture(ring_picture(centre, inner, outer), options('centerline'))
    dots = plan.grid_uv.astype(float)
    middle = np.array(to_grid(centre))
    medial = 0.5 * (inner + outer) / PIXELS_PER_NODE
    distance = np.abs(np.linalg.norm(dots - middle, axis=1) - medial)
    assert np.max(distance) <= 0.5 + 1e-9
    angles = np.linspace(0.0, 2.0 * math.pi, 720)
    circle = middle + medial * np.column_stack([np.cos(angles), np.sin(angles)])
    gaps = np.min(np.linalg.norm(circle[:, None] - dots[None], axis=2), axis=1)
    assert np.max(gaps) <= 1.0    # all the way round, no gap


def test_centerline_of_a_thick_bar_lies_within_half_a_pitch_of_its_medial_axis():
    x0, x1, y0, y1 = 63, 337, 171, 204    # bar 274 x 33 px (3.3 pitches thick)
    picture = np.full((400, 400), 255, np.uint8)
    picture[y0:y1, x0:x1] = 0
    plan = plan_picture(picture, options('centerline'))
    a, b, c, d = to_grid(x0), to_grid(x1), to_grid(y0), to_grid(y1)
    half = 0.5 * (d - c)
    middle = 0.5 * (c + d)
    # medial axis of a rectangle: the middle segment and four 45-degree branches to corners
    axis = [((a + half, middle), (b - half, middle)),
            ((a + half, middle), (a, c)), ((a + half, middle), (a, d)),
            ((b - half, middle), (b, c)), ((b - half, middle), (b, d))]
    dots = plan.grid_uv.astype(float)
    assert np.max(distance_to_segments(dots, axis)) <= 0.5 + 1e-9
    along = np.sort(dots[np.abs(dots[:, 1] - middle) <= 0.5][:, 0])
    assert along[0] <= a + half + 1 and along[-1] >= b - half - 1


def grey_ramp(darkness, band_px=80, height=400):
    columns = np.repeat(1.0 - np.asarray(darkness), band_px)
    return np.tile(columns, (height, 1))


def test_tones_follow_each_bands_darkness_within_3_points_and_monotonically():
    darkness = [0.1, 0.3, 0.5, 0.7, 0.9]
    plan = plan_picture(grey_ramp(darkness), options('tones'))
    counts = np.bincount(plan.grid_uv[:, 0] // 8, minlength=5)
    fractions = counts / (8 * 40)
    assert np.all(np.abs(fractions - darkness) <= 0.03)
    assert np.all(np.diff(fractions) > 0)


@pytest.mark.parametrize('kernel', ['floyd_steinberg', 'jarvis_judice_ninke'])
def test_error_diffusion_kernels_keep_band_darkness(kernel):
    levels = np.linspace(0.05, 0.95, 10)
    grid = np.repeat(levels, 6)[None, :].repeat(60, 0)
    dots = error_diffusion(grid, kernel)
    fractions = dots.reshape(60, 10, 6).mean(axis=(0, 2))
    assert np.all(np.abs(fractions - levels) <= 0.03)
    assert np.all(np.diff(fractions) > 0)


def test_atkinson_drops_a_quarter_of_the_error_so_the_ends_saturate():
    levels = np.array([0.1, 0.5, 0.9])
    dots = error_diffusion(np.repeat(levels, 10)[None, :].repeat(40, 0), 'atkinson')
    fractions = dots.reshape(40, 3, 10).mean(axis=(0, 2))
    assert fractions[0] < 0.05 and abs(fractions[1] - 0.5) <= 0.03 and fractions[2] > 0.95


def working(picture):
    return np.asarray(picture, dtype=np.float32) / 255.0


def test_auto_rule_picks_tones_for_a_photograph_like_picture():
    gradient = np.tile(np.linspace(0, 255, 320), (320, 1)).astype(np.uint8)
    assert choose_mode(working(gradient), 8)[0] == 'tones'


def test_auto_rule_picks_edges_for_wide_shapes_and_centerline_for_thin_strokes():
    wide = np.full((320, 320), 255, np.uint8)
    wide[80:240, 80:240] = 0      # 20 pitches wide at 8 px per pitch
    thin = np.full((320, 320), 255, np.uint8)
    thin[150:162, 40:280] = 0     # 1.5 pitches wide
    assert choose_mode(working(wide), 8)[0] == 'edges'
    assert choose_mode(working(thin), 8)[0] == 'centerline'
