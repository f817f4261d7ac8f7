"""Flux on the panel: power conservation, shadow, re-tracing only when something moved."""

from dataclasses import replace
import math

from helio_drivers.sim.flux import (bin_on_edges, irradiance_on_cells, LensFlux,
                                    shadow_fractions)
from helio_drivers.sim.kernels import chosen_rays
from helio_optics.geometry import homogeneous, rotation_y, unit
from helio_optics.lens import LensParameters, pmma_index, trace
import numpy as np
import pytest

LENS = LensParameters(aperture_diameter=0.040, transmission=0.9)


def lens_facing(sun_ray, distance, target=(0.0, 0.0, 0.0)):
    """Pose T_world_lens of a lens whose axis points at the sun, `distance` up-sun of target."""
    s0 = unit(np.asarray(sun_ray, float))
    axis = -s0
    rotation = rotation_y(math.atan2(axis[0], axis[2]))  # sun rays in the x-z plane here
    return homogeneous(rotation, np.asarray(target) - distance * s0)


def test_pmma_index_matches_the_published_values():
    assert pmma_index(0.5876) == pytest.approx(1.4914, abs=2e-3)
    assert pmma_index(0.437) == pytest.approx(1.502, abs=2e-3)
    assert pmma_index(0.633) == pytest.approx(1.489, abs=2e-3)


@pytest.mark.parametrize('elevation_deg', [90.0, 50.0])
def test_power_on_a_large_panel_is_conserved(elevation_deg):
    # All the sunlight that falls on the panel area arrives, minus the lens loss (1 - kappa):
    # total = DNI (|s_z| area - A_l (1 - kappa)) for a lens facing the sun.
    e = math.radians(elevation_deg)
    s0 = np.array([math.cos(e), 0.0, -math.sin(e)])
    flux = LensFlux(LENS, rays=20000)
    field = flux.field(lens_facing(s0, 0.082), s0)
    assert field.total_power() == pytest.approx(LENS.aperture_area * LENS.transmission,
                                                rel=1e-3)
    edges = np.linspace(-0.12, 0.12, 241)
    dni = 850.0
    irradiance = irradiance_on_cells(field, edges, edges, dni, shadow_samples=4)
    total = float(np.sum(irradiance) * (edges[1] - edges[0]) ** 2)
    expected = dni * (math.sin(e) * 0.24 ** 2 - LENS.aperture_area * (1 - LENS.transmission))
    assert total == pytest.approx(expected, rel=2e-3)
    # The shadow: dark beside the focus, direct sun well outside the lens outline.
    assert field.in_shadow(0.004, 0.0) and not field.in_shadow(0.0, 0.06)


def test_focus_is_where_the_tracer_puts_it_and_retracing_follows_moves():
    s0 = np.array([0.0, 0.0, -1.0])
    flux = LensFlux(LENS, rays=5000)
    first = flux.field(lens_facing(s0, 0.082, (0.03, -0.02, 0.0)), s0)
    assert first.centroid() == pytest.approx([0.03, -0.02], abs=1e-5)
    again = flux.field(lens_facing(s0, 0.082, (0.03, -0.02 + 1e-6, 0.0)), s0)
    assert again is first and flux.traces == 1 and flux.fields == 1
    moved = flux.field(lens_facing(s0, 0.082, (0.04, -0.02, 0.0)), s0)   # moved, not turned
    assert flux.traces == 1 and flux.fields == 2
    assert moved.centroid() == pytest.approx([0.04, -0.02], abs=1e-5)
    tilted = lens_facing(s0, 0.082, (0.04, -0.02, 0.0)) @ homogeneous(rotation_y(0.01), [0] * 3)
    flux.field(tilted, s0)
    assert flux.traces == 2 and flux.fields == 3


@pytest.mark.parametrize('moving', [False, True])
def test_a_lens_that_moved_without_turning_gets_what_a_fresh_trace_gives(moving):
    # the rays carried along with the lens against a new LensFlux tracing at the new pose:
    # sideways and down (the spot defocuses), a sun off the lens axis, every band
    s0 = unit([0.3, -0.2, -1.0])
    lens = LensParameters(focal_length=0.081, aperture_diameter=0.038)
    start = lens_facing(unit([0.2, 0.0, -1.0]), 0.11, (0.05, 0.06, 0.0))
    moved = start.copy()
    moved[:3, 3] += [0.004, -0.0015, -0.021]
    flux = LensFlux(lens, rays=6000, beam_spread=0.004, moving_rays=1000)
    flux.field(start, s0)
    carried = flux.field(moved, s0, moving=moving)
    assert flux.traces == 1 and flux.field_is_sparse == moving
    fresh_flux = LensFlux(lens, rays=6000, beam_spread=0.004, moving_rays=1000)
    fresh = fresh_flux.field(moved, s0, moving=moving)
    assert len(carried.points) == len(fresh.points) > 1000
    assert np.allclose(carried.points, fresh.points, rtol=0.0, atol=1e-10)
    assert np.allclose(carried.power, fresh.power, rtol=1e-12, atol=0.0)
    assert carried.tir_fraction == pytest.approx(fresh.tir_fraction, abs=1e-12)
    assert np.allclose(carried.lens_centre, moved[:3, 3], rtol=0.0, atol=1e-15)


def test_a_moving_lens_turned_within_its_tolerance_keeps_its_map_within_its_noise():
    # carried along although turned by the moving tolerance (5 mrad, about two axes),
    # against a fresh trace of the same moving rays at the new pose (the sun off the lens
    # axis by 45 mrad): the spot's centre within 5 um (a 40th of a cell), the map on
    # 0.2 mm cells within 8 % (L1; 6 % measured, 1.5 % with the sun on the axis), under
    # half the difference between the moving lens's fewer rays and the full trace (its
    # sampling noise, 16 %)
    lens = LensParameters(focal_length=0.081, aperture_diameter=0.038, transmission=0.92)
    s0 = unit([0.3, -0.25, -1.0])
    start = lens_facing(unit([0.25, -0.2, -1.0]), 0.082, (0.07, 0.07, 0.0))
    edges = np.arange(-0.006, 0.00601, 0.0002)

    def binned(field):
        return bin_on_edges(field.points[:, 0], field.points[:, 1], field.power,
                            0.071 + edges, 0.0705 + edges)

    def flux():
        return LensFlux(lens, rays=20000, beam_spread=0.004, moving_rays=2500)

    for axis in (rotation_y(0.0049), np.array([[1.0, 0.0, 0.0],
                                              [0.0, math.cos(0.0049), -math.sin(0.0049)],
                                              [0.0, math.sin(0.0049), math.cos(0.0049)]])):
        moved = start @ homogeneous(axis, [0.0, 0.0, 0.0])
        moved[:3, 3] += [0.001, 0.0005, 0.0]
        carrying = flux()
        carrying.field(start, s0)
        carried = carrying.field(moved, s0, moving=True)
        assert carrying.traces == 1 and carrying.field_is_sparse
        fresh = flux().field(moved, s0, moving=True)
        full = flux().field(moved, s0)
        assert np.linalg.norm(carried.centroid() - fresh.centroid()) < 5e-6
        error = np.abs(binned(carried) - binned(fresh)).sum() / binned(fresh).sum()
        noise = np.abs(binned(fresh) - binned(full)).sum() / binned(full).sum()
        assert error < 0.08 and error < 0.5 * noise
    # beyond the tolerance the moving lens is traced anew
    turned = start @ homogeneous(rotation_y(0.006), [0.0, 0.0, 0.0])
    carrying.field(turned, s0, moving=True)
    assert carrying.traces == 2


def test_spot_is_smallest_near_the_focus_and_grows_away_from_it():
    s0 = np.array([0.0, 0.0, -1.0])
    flux = LensFlux(LENS, rays=8000)

    def spread(distance):
        field = flux.field(lens_facing(s0, distance), s0)
        return float(np.sqrt(np.average(np.sum(field.points ** 2, axis=1),
                                        weights=field.power)))

    near, focus, far = spread(0.070), spread(0.081), spread(0.092)
    assert focus < 0.5 * near and focus < 0.5 * far
    # Geometric blur away from focus ~ aperture radius x defocus / focus distance.
    assert far == pytest.approx(0.020 * 0.011 / 0.081 / math.sqrt(2), rel=0.5)


def test_bad_flux_parameters_are_refused():
    with pytest.raises(ValueError, match='rays'):
        LensFlux(LENS, rays=10)
    with pytest.raises(ValueError, match='weights'):
        LensFlux(LENS, rays=1000, bands=((0.5, 0.0),))


def test_lens_shadow_by_quadratic_form_equals_casting_each_point_to_the_lens():
    lens = LensFlux(LensParameters(focal_length=0.081, aperture_diameter=0.038), rays=500)
    s0 = np.array([0.3, -0.4, -0.866])
    T = np.eye(4)
    T[:3, :3] = np.array([[0.96, 0.0, -0.28], [0.0, 1.0, 0.0], [0.28, 0.0, 0.96]]).T
    T[:3, 3] = [0.06, 0.07, 0.08]
    field = lens.field(T, s0 / np.linalg.norm(s0))
    xs, ys = np.linspace(-0.02, 0.14, 161), np.linspace(-0.02, 0.14, 157)
    shadow = field.in_shadow(xs[None, :], ys[:, None])
    # cast every point along the sun ray to the lens plane, one by one
    towards_sun, normal = -field.sun_ray, field.lens_axis
    expected = np.zeros_like(shadow)
    for row, y in enumerate(ys):
        for col, x in enumerate(xs):
            point = np.array([x, y, 0.0])
            distance = (field.lens_centre - point) @ normal / (towards_sun @ normal)
            hit = point + distance * towards_sun
            expected[row, col] = (distance > 0.0 and np.linalg.norm(hit - field.lens_centre)
                                  <= field.aperture_radius)
    assert 500 < shadow.sum() and np.array_equal(shadow, expected)
    assert np.array_equal(field.in_shadow_grid(xs, ys), expected)


def test_binning_on_uneven_edges_equals_numpy_histogram2d():
    rng = np.random.default_rng(7)
    x_edges = np.concatenate([[-0.03, -0.012, -0.007], np.arange(-0.006, 0.0061, 0.0002),
                              [0.009, 0.02, 0.03]])
    y_edges = x_edges + 0.001
    x, y = rng.normal(0.0, 0.01, 50000), rng.normal(0.0, 0.012, 50000)
    x[:5], y[:5] = x_edges[[0, 3, 10, -1, -1]], y_edges[[0, 4, 20, -1, 3]]   # on edges
    weights = rng.random(50000)
    expected, _, _ = np.histogram2d(y, x, bins=(y_edges, x_edges), weights=weights)
    assert np.allclose(bin_on_edges(x, y, weights, x_edges, y_edges), expected,
                       rtol=1e-12, atol=1e-12)


def test_the_chosen_rays_are_numpys_boolean_index_of_the_trace():
    # the kernel against numpy's a[chosen] and the slopes' division, bit for bit: rays
    # missing in every band (and a band with none), a subset, a power scale
    rng = np.random.default_rng(3)
    bands, rays = 4, 3001
    points, directions = rng.normal(size=(bands, rays, 3)), rng.normal(size=(bands, rays, 3))
    power = rng.random((bands, rays))
    chosen = (rng.random((bands, rays)) < 0.8) & (np.arange(rays) % 3 == 0)[None, :]
    chosen[2] = False
    count = int(np.count_nonzero(chosen))
    out_points, out_slopes, out_power = np.empty((count, 2)), np.empty((count, 2)), \
        np.empty(count)
    chosen_rays(chosen, points, directions, power, 3.0, out_points, out_slopes, out_power)
    leaving = directions[chosen]
    assert np.array_equal(out_points, points[chosen][:, :2])
    assert np.array_equal(out_slopes, leaving[:, :2] / leaving[:, 2:3])
    assert np.array_equal(out_power, power[chosen] * 3.0)


def test_a_moving_lens_traces_fewer_rays_with_the_same_power_and_spot():
    lens = LensParameters(focal_length=0.081, aperture_diameter=0.038)
    flux = LensFlux(lens, rays=20000, beam_spread=0.004, moving_rays=2500)
    s0 = unit([0.2, 0.1, -1.0])
    T = homogeneous(np.eye(3), [0.0, 0.0, 0.08])
    full = flux.field(T, s0)
    T_moved = homogeneous(rotation_y(0.02), [0.0002, 0.0, 0.08])    # turned: re-traced
    sparse = flux.field(T_moved, s0, moving=True)
    assert flux.traces == 2
    assert flux.field_is_sparse and len(sparse.power) * 7 < len(full.power)
    assert sparse.total_power() == pytest.approx(full.total_power(), rel=0.01)
    full = LensFlux(lens, rays=20000, beam_spread=0.004).field(T_moved, s0)
    assert sparse.centroid() == pytest.approx(full.centroid(), abs=2e-5)
    spread = np.sqrt(np.average((full.points - full.centroid()) ** 2, axis=0,
                                weights=full.power))
    sparse_spread = np.sqrt(np.average((sparse.points - sparse.centroid()) ** 2, axis=0,
                                       weights=sparse.power))
    assert sparse_spread == pytest.approx(spread, rel=0.05)
    # held still, the next field is traced in full again
    held = flux.field(T_moved, s0)
    assert not flux.field_is_sparse and len(held.power) == len(full.power)


@pytest.mark.parametrize('tilt', [-0.2, 0.0, 0.2])
def test_shadow_fractions_sampled_along_the_edge_equal_sampling_every_cell(tilt):
    lens = LensFlux(LensParameters(focal_length=0.081, aperture_diameter=0.038), rays=500)
    s0 = unit([0.35, -0.2, -0.9])
    T = homogeneous(rotation_y(tilt), [0.071, 0.069, 0.08])
    field = lens.field(T, s0)
    lateral = np.concatenate([-np.cumsum(0.0002 * 1.25 ** np.arange(15))[::-1] - 0.006,
                              np.arange(-0.006, 0.00601, 0.0002),
                              np.cumsum(0.0002 * 1.25 ** np.arange(15)) + 0.006])
    x_edges, y_edges = 0.06 + lateral, 0.075 + lateral
    fractions = (np.arange(3) + 0.5) / 3
    xs = x_edges[:-1, None] + fractions[None] * np.diff(x_edges)[:, None]
    ys = y_edges[:-1, None] + fractions[None] * np.diff(y_edges)[:, None]
    every_cell = field.in_shadow(xs[None, :, None, :], ys[:, None, :, None]).mean(axis=(2, 3))
    fast = shadow_fractions(field, x_edges, y_edges, 3)
    assert 0.0 < every_cell.mean() < 1.0 and np.array_equal(fast, every_cell)


@pytest.mark.parametrize('moving', [False, True])
def test_all_bands_traced_at_once_equal_a_trace_per_band(moving):
    lens = LensParameters(focal_length=0.081, aperture_diameter=0.038)
    flux = LensFlux(lens, rays=4000, beam_spread=0.004, moving_rays=500)
    s0 = unit([0.2, 0.1, -1.0])
    T = homogeneous(rotation_y(0.1), [0.001, 0.0, 0.08])
    field = flux.field(T, s0, moving=moving)
    samples = flux._moving_samples if moving else flux._samples
    points, powers = [], []
    for index, weight in zip(flux._indices, flux._weights):
        band_lens = replace(lens, refractive_index=index,
                            focal_length=lens.sphere_radius / (index - 1.0))
        result = trace(band_lens, replace(samples, lens=band_lens), s0, T, irradiance=1.0)
        points.append(result.points[result.hit, :2])
        powers.append(weight * result.power[result.hit])
    assert np.allclose(field.points, np.concatenate(points), rtol=0.0, atol=1e-15)
    assert np.allclose(field.power, np.concatenate(powers), rtol=1e-15, atol=0.0)
    assert len(field.power) > 0.9 * len(samples) * len(flux._indices)
