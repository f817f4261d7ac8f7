"""Flux on the panel: power conservation, shadow, re-tracing only when something moved."""

import math

from helio_drivers.sim.flux import irradiance_on_cells, LensFlux
from helio_optics.geometry import homogeneous, rotation_y, unit
from helio_optics.lens import LensParameters, pmma_index
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
    assert again is first and flux.traces == 1
    moved = flux.field(lens_facing(s0, 0.082, (0.04, -0.02, 0.0)), s0)
    assert flux.traces == 2 and moved.centroid() == pytest.approx([0.04, -0.02], abs=1e-5)


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
