"""Lens ray tracer (Eqs 1-6) against thin/thick-lens optics, Snell's law and energy balance."""

import math

from helio_optics.geometry import homogeneous, rotation_x, rotation_y, transform_points
from helio_optics.lens import area_samples, facet_sin_polar, LensParameters, LensSamples
from helio_optics.lens import outer_ring_samples, paraxial_focus_distance, ring_samples
from helio_optics.lens import trace, trace_bands, trace_batch
import numpy as np
import pytest


def single_ring(lens, radius, per_ring=16):
    """Rays from the sun's centre entering at one radius (for focus measurements)."""
    samples = ring_samples(lens, rings=1, per_ring=per_ring, sun_disk_points=1)
    r = np.full(len(samples), radius)
    return LensSamples(lens=lens, facet_sin=facet_sin_polar(lens, r), radius=r,
                       azimuth=samples.azimuth, weight=samples.weight,
                       disk_u=samples.disk_u, disk_v=samples.disk_v, ring=samples.ring)


def axis_crossing_depth(lens, radius):
    """Depth below O_l where rays entering at `radius` cross the lens axis (sun on axis)."""
    result = trace(lens, single_ring(lens, radius), [0.0, 0.0, -1.0],
                   plane_point=[0.0, 0.0, -0.05])
    p, d = result.points, result.directions
    along = -(p[:, 0] * d[:, 0] + p[:, 1] * d[:, 1]) / (d[:, 0] ** 2 + d[:, 1] ** 2)
    crossing = p + along[:, None] * d
    np.testing.assert_allclose(crossing[:, :2], 0.0, atol=1e-12)
    return -crossing[:, 2].mean()


def test_paraxial_focus_is_the_thin_lens_focal_length():
    # Plano-convex thin lens: f = R / (n - 1) (lensmaker's equation).
    for facets in ('spherical', 'corrected'):
        lens = LensParameters(facets=facets, thickness=0.0)
        thin = lens.sphere_radius / (lens.refractive_index - 1.0)
        assert axis_crossing_depth(lens, 1e-4) == pytest.approx(thin, rel=0.005)
        assert axis_crossing_depth(lens, 1e-4) == pytest.approx(0.080, rel=1e-5)


def test_thick_plate_shifts_the_focus_by_t_times_one_minus_one_over_n():
    lens = LensParameters(facets='spherical', thickness=0.004)
    expected = 0.080 + 0.004 * (1.0 - 1.0 / 1.4914)  # thick plano-convex, curved side first
    assert axis_crossing_depth(lens, 1e-4) == pytest.approx(expected, rel=1e-5)
    assert paraxial_focus_distance(lens) == pytest.approx(expected, rel=1e-12)


def test_spherical_facets_have_spherical_aberration_and_corrected_ones_do_not():
    spherical = LensParameters(facets='spherical')
    corrected = LensParameters(facets='corrected')
    rim = spherical.aperture_radius
    # Marginal rays of a fast spherical lens focus well short of the paraxial focus.
    assert axis_crossing_depth(spherical, rim) < 0.9 * paraxial_focus_distance(spherical)
    for radius in (0.3 * rim, 0.7 * rim, rim):
        assert axis_crossing_depth(corrected, radius) == pytest.approx(
            paraxial_focus_distance(corrected), rel=1e-9)


def test_refraction_obeys_the_scalar_snell_law_at_both_faces():
    lens = LensParameters(facets='spherical', thickness=0.0)
    n = lens.refractive_index
    for radius in np.linspace(0.002, lens.aperture_radius, 6):
        phi = math.asin(radius / lens.sphere_radius)  # facet tilt = incidence angle
        inside = phi - math.asin(math.sin(phi) / n)  # ray angle from the axis in the glass
        expected = math.asin(n * math.sin(inside))  # leaving the flat face
        result = trace(lens, single_ring(lens, radius, 8), [0, 0, -1.0],
                       plane_point=[0, 0, -0.05])
        angle = np.arccos(-result.directions[:, 2])
        np.testing.assert_allclose(angle, expected, atol=1e-12)
        # Bent towards the axis, in the plane of incidence.
        radial = result.directions[:, 0] * np.cos(single_ring(lens, radius, 8).azimuth) + \
            result.directions[:, 1] * np.sin(single_ring(lens, radius, 8).azimuth)
        assert np.all(radial < 0)
    # At the centre the facet is flat: a tilted ray crosses a plate and keeps its direction.
    sun = np.array([math.sin(0.4), 0.0, -math.cos(0.4)])
    straight = trace(lens, single_ring(lens, 0.0, 4), sun, plane_point=[0, 0, -0.07])
    np.testing.assert_allclose(straight.directions, np.tile(sun, (4, 1)), atol=1e-12)


def test_total_internal_reflection_is_counted_and_carries_no_power():
    lens = LensParameters(facets='spherical', thickness=0.0)
    samples = area_samples(lens, 4000)
    # Sun 70 deg off the axis: rays on the far side meet steep facets and leave the plate
    # beyond the critical angle.
    sun = [math.sin(math.radians(70.0)), 0.0, -math.cos(math.radians(70.0))]
    result = trace(lens, samples, sun, plane_point=[0, 0, -0.05])
    assert result.tir_count > 0
    lost = result.power == 0.0
    assert np.count_nonzero(lost) >= result.tir_count
    assert result.ground_power < result.incident_power * lens.transmission
    # On axis no ray is lost.
    on_axis = trace(lens, samples, [0, 0, -1], plane_point=[0, 0, -0.05])
    assert on_axis.tir_count == 0 and on_axis.hit.all()


@pytest.mark.parametrize('sampling', ['area', 'rings'])
def test_energy_is_conserved_without_tir(sampling):
    lens = LensParameters()
    samples = area_samples(lens, 5000) if sampling == 'area' else ring_samples(lens, 10, 60, 4)
    beta = math.radians(20.0)
    sun = [math.sin(beta), 0.0, -math.cos(beta)]  # 20 deg off the lens axis
    ground = homogeneous(rotation_x(math.radians(10.0)), [0.0, 0.0, -0.08])
    q_s = 850.0
    result = trace(lens, samples, sun, plane_point=ground[:3, 3],
                   plane_normal=ground[:3, 2], irradiance=q_s)
    assert result.tir_count == 0
    # Eq 13 with the aperture area pi a^2, independent of the sample weights.
    through_aperture = q_s * math.pi * (0.058 / 2) ** 2 * math.cos(beta)
    assert result.ground_power == pytest.approx(through_aperture * 0.92, rel=0.01)
    assert result.hit.all()


def test_trace_in_any_frame_equals_the_lens_frame_trace_moved():
    lens = LensParameters()
    samples = ring_samples(lens, 3, 24, 4)
    T_world_lens = homogeneous(rotation_y(0.3) @ rotation_x(-0.2), [0.1, -0.05, 0.09])
    sun_world = np.array([0.3, 0.2, -1.0])
    world = trace(lens, samples, sun_world, T_frame_lens=T_world_lens)
    R = T_world_lens[:3, :3]
    local_plane_point = R.T @ (np.zeros(3) - T_world_lens[:3, 3])
    local = trace(lens, samples, R.T @ sun_world, plane_point=local_plane_point,
                  plane_normal=R.T @ [0, 0, 1])
    np.testing.assert_allclose(world.points, transform_points(T_world_lens, local.points),
                               atol=1e-12)
    np.testing.assert_allclose(world.points[:, 2], 0.0, atol=1e-12)


def test_sun_behind_the_lens_focuses_nothing_and_bad_parameters_raise():
    lens = LensParameters()
    result = trace(lens, area_samples(lens, 100), [0, 0, 1.0], plane_point=[0, 0, -0.08])
    assert not result.hit.any() and result.ground_power == 0.0
    with pytest.raises(ValueError, match='aperture'):
        LensParameters(aperture_diameter=0.1)
    with pytest.raises(ValueError, match='facets'):
        LensParameters(facets='aspheric')
    with pytest.raises(ValueError, match='another lens'):
        trace(LensParameters(focal_length=0.1), area_samples(lens, 10), [0, 0, -1])


def test_from_sphere_round_trips_the_paper_parameters():
    lens = LensParameters.from_sphere(0.0393, math.radians(40.0))
    assert lens.sphere_radius == pytest.approx(0.0393)
    assert lens.bounding_polar_angle == pytest.approx(math.radians(40.0))


def test_batch_trace_equals_one_pose_at_a_time():
    lens = LensParameters()
    samples = ring_samples(lens, 2, 16, 2)
    poses = np.stack([homogeneous(rotation_y(0.2 * k) @ rotation_x(-0.1 * k), [0.01 * k, 0, 0.09])
                      for k in range(4)])
    sun = np.array([0.2, -0.1, -1.0])
    batch = trace_batch(lens, samples, sun, poses)
    for k in range(4):
        single = trace(lens, samples, sun, T_frame_lens=poses[k])
        np.testing.assert_array_equal(batch.hit[k], single.hit)
        np.testing.assert_allclose(batch.points[k][single.hit], single.points[single.hit],
                                   atol=1e-14)
    with pytest.raises(ValueError, match='radius_fraction'):
        outer_ring_samples(lens, radius_fraction=1.5)


def test_band_trace_equals_one_index_at_a_time():
    lens = LensParameters(focal_length=0.081, aperture_diameter=0.038, thickness=0.002)
    samples = area_samples(lens, 3000, seed=5)
    indices = [1.47, 1.4914, 1.52]
    T = homogeneous(rotation_x(0.3) @ rotation_y(-0.2), [0.01, -0.02, 0.08])
    s0 = [0.3, -0.1, -1.0]
    together = trace_bands(lens, samples, indices, s0, T, irradiance=800.0)
    for band, index in enumerate(indices):
        band_lens = LensParameters(focal_length=lens.sphere_radius / (index - 1.0),
                                   refractive_index=index, thickness=lens.thickness,
                                   aperture_diameter=lens.aperture_diameter)
        alone = trace(band_lens, LensSamples(
            lens=band_lens, facet_sin=samples.facet_sin, radius=samples.radius,
            azimuth=samples.azimuth, weight=samples.weight, disk_u=samples.disk_u,
            disk_v=samples.disk_v, ring=samples.ring), s0, T, irradiance=800.0)
        assert np.array_equal(together.hit[band], alone.hit)
        assert np.allclose(together.points[band][alone.hit], alone.points[alone.hit],
                           rtol=0.0, atol=1e-15)
        assert np.array_equal(together.power[band], alone.power)
        assert together.tir_count[band] == alone.tir_count
        assert together.incident_power == alone.incident_power
    behind = trace_bands(lens, samples, indices, [0.0, 0.0, 1.0], T)
    assert behind.points.shape == (3, 3000, 3) and not behind.hit.any()
