"""Wood heat solver against closed forms, its energy balance and the char process."""

import math

from helio_drivers.sim.wood import GridParameters, WoodPanel, WoodParameters
import numpy as np
import pytest

LOSSLESS = {'convection_top': 0.0, 'convection_back': 0.0, 'emissivity': 0.0,
            'moisture_content': 0.0, 'heat_of_pyrolysis': 0.0}


def disk_irradiance(panel, radius, flux, centre=(0.0, 0.0), samples=8):
    """Irradiance per patch column of a uniform disk source, by area-weighted coverage."""
    fractions = (np.arange(samples) + 0.5) / samples
    xs = panel.x_edges[:-1, None] + fractions[None] * np.diff(panel.x_edges)[:, None]
    ys = panel.y_edges[:-1, None] + fractions[None] * np.diff(panel.y_edges)[:, None]
    inside = ((xs[None, :, None, :] - centre[0]) ** 2
              + (ys[:, None, :, None] - centre[1]) ** 2) <= radius ** 2
    return flux * inside.mean(axis=(2, 3))


def test_semi_infinite_solid_under_uniform_flux_matches_closed_form():
    wood = WoodParameters(thickness=0.02, **LOSSLESS)
    grid = GridParameters(fine_half_width=1e-3, half_width=2e-3, recentre_margin=0.0)
    panel = WoodPanel(wood, grid, extent=(-0.01, 0.01, -0.01, 0.01))
    irradiance = 1.0e4
    absorbed = wood.absorptance_wood * irradiance
    uniform = np.full(panel.cell_areas.shape, irradiance)
    checks = {}
    for _ in range(400):
        panel.step(0.05, uniform)
        if round(panel.time, 6) in (5.0, 10.0, 20.0):
            rise = panel.surface_temperature_at(0.0, 0.0) - wood.ambient
            exact = 2.0 * absorbed * math.sqrt(
                panel.time / (math.pi * wood.thermal_effusivity_squared))
            checks[round(panel.time, 1)] = (float(rise), exact)
    print('semi-infinite surface rise (sim, closed form) [K]:', checks)
    assert len(checks) == 3
    for rise, exact in checks.values():
        assert rise == pytest.approx(exact, rel=0.02)


def disk_centre_rise(flux, radius, k_x, k_y, k_z, samples=20000):
    """
    Steady centre rise of a uniform disk source on an anisotropic half-space [K].

    Scaling x by sqrt(k_x), y by sqrt(k_y), z by sqrt(k_z) makes the conduction isotropic
    with unit conductivity and flux q / sqrt(k_z); the disk becomes an ellipse of semi-axes
    a / sqrt(k_x), a / sqrt(k_y), and the centre rise is (q / sqrt(k_z)) / (2 pi) times the
    integral of the ellipse radius over the angle (isotropic: q a / k).
    """
    phi = (np.arange(samples) + 0.5) * (2.0 * math.pi / samples)
    semi_x, semi_y = radius / math.sqrt(k_x), radius / math.sqrt(k_y)
    ellipse_radius = 1.0 / np.sqrt((np.cos(phi) / semi_x) ** 2 + (np.sin(phi) / semi_y) ** 2)
    integral = float(np.sum(ellipse_radius)) * (2.0 * math.pi / samples)
    return flux / math.sqrt(k_z) * integral / (2.0 * math.pi)


@pytest.mark.parametrize('along_grain', [0.12, 0.22], ids=['isotropic', 'plywood_grain'])
def test_steady_disk_source_centre_temperature_matches_closed_form(along_grain):
    # Semi-infinite solid, uniform flux q on a disk of radius a: centre rise q a / k when
    # isotropic; with the face grain along x, the closed form of disk_centre_rise.
    wood = WoodParameters(thickness=0.04, absorptance_wood=1.0, convection_top=0.0,
                          convection_back=1e6, emissivity=0.0, moisture_content=0.0,
                          conductivity=0.12, conductivity_along_grain=along_grain)
    grid = GridParameters(fine_cell=1.25e-4, fine_half_width=2e-3, half_width=0.04,
                          lateral_growth=1.3, top_layer=3e-5, depth_growth=1.3,
                          recentre_margin=0.0)
    panel = WoodPanel(wood, grid, extent=(-0.05, 0.05, -0.05, 0.05))
    radius, flux = 1e-3, 2e4
    irradiance = disk_irradiance(panel, radius, flux)
    assert np.sum(irradiance * panel.cell_areas) == pytest.approx(flux * math.pi * radius ** 2,
                                                                  rel=0.01)
    previous = 0.0
    for cycle in range(12):  # cycled time steps: ADI converges to the discrete steady state
        for dt in np.geomspace(0.02, 200.0, 12):
            panel.step(dt, irradiance)
        centre = float(panel.surface_temperature_at(0.0, 0.0)) - wood.ambient
        if abs(centre - previous) < 1e-4 * centre:
            break
        previous = centre
    exact = disk_centre_rise(flux, radius, wood.conductivity_along_grain, wood.conductivity,
                             wood.conductivity)
    if along_grain == wood.conductivity:
        assert exact == pytest.approx(flux * radius / wood.conductivity, rel=1e-6)
    print(f'steady disk centre rise (k along grain {along_grain}): sim {centre:.2f} K, '
          f'closed form {exact:.2f} K after {cycle + 1} cycles')
    assert centre == pytest.approx(exact, rel=0.05)


def test_heat_spreads_faster_along_the_grain_as_diffusion_predicts():
    # An initial Gaussian hot spot, lossless: each lateral variance grows by 2 a t per axis.
    wood = WoodParameters(**LOSSLESS)
    panel = WoodPanel(wood, extent=(-0.03, 0.03, -0.03, 0.03))
    x, y = np.meshgrid(panel.x_centres, panel.y_centres)
    sigma0 = 0.8e-3
    panel.theta[:] = 50.0 * np.exp(-(x ** 2 + y ** 2) / (2.0 * sigma0 ** 2))[None]
    duration = 4.0
    for _ in range(80):
        panel.step(duration / 80, np.zeros(panel.cell_areas.shape))
    weights = panel.theta.sum(axis=0) * panel.cell_areas
    variance_x = float(np.sum(weights * x ** 2) / np.sum(weights))
    variance_y = float(np.sum(weights * y ** 2) / np.sum(weights))
    expected_x = sigma0 ** 2 + 2.0 * wood.diffusivity_along_grain * duration
    expected_y = sigma0 ** 2 + 2.0 * wood.diffusivity * duration
    print(f'lateral variance after {duration} s [mm^2]: x {variance_x * 1e6:.4f} '
          f'(2 a t: {expected_x * 1e6:.4f}), y {variance_y * 1e6:.4f} ({expected_y * 1e6:.4f})')
    assert variance_x == pytest.approx(expected_x, rel=0.03)
    assert variance_y == pytest.approx(expected_y, rel=0.03)


def gaussian_irradiance(panel, centre, power, width):
    """Gaussian spot of total `power` [W] and 1/e^2 radius `width` [m] on the patch columns."""
    x, y = np.meshgrid(panel.x_centres, panel.y_centres)
    r2 = (x - centre[0]) ** 2 + (y - centre[1]) ** 2
    return 2.0 * power / (math.pi * width ** 2) * np.exp(-2.0 * r2 / width ** 2)


def test_energy_balance_over_a_run_with_losses_moves_and_charring():
    panel = WoodPanel(extent=(-0.03, 0.03, -0.03, 0.03))
    panel.reset_ledger()
    spots = [(0.0, 0.0), (0.002, 0.0), (0.009, 0.004)]  # the last one re-centres the patch
    for spot in spots:
        panel.follow(spot)
        for _ in range(60):
            panel.step(0.1, gaussian_irradiance(panel, spot, 0.8, 1.0e-3) + 800.0, 800.0)
        for _ in range(20):
            panel.step(0.1, np.full(panel.cell_areas.shape, 800.0), 800.0)
    ledger = panel.ledger
    stored = panel.stored_energy() - ledger.initial_stored
    print(f'absorbed {ledger.absorbed:.3f} J, stored {stored:.3f} J, lost top '
          f'{ledger.lost_top:.3f} J, back {ledger.lost_back:.3f} J, evaporated '
          f'{ledger.evaporated:.3f} J, pyrolysis {ledger.pyrolysed:.3f} J, '
          f'regrid {ledger.regrid:.3f} J')
    assert panel.recentres >= 1
    assert ledger.lost_top > 0.05 * ledger.absorbed and ledger.lost_back > 0.0
    assert ledger.evaporated > 0.01 * ledger.absorbed and ledger.pyrolysed > 0.0
    assert abs(ledger.residual(panel.stored_energy())) < 0.01 * ledger.absorbed
    assert panel.char.max() > 0.5  # the run was hot enough to char


def test_lossless_heat_content_equals_absorbed_power_times_time():
    wood = WoodParameters(**LOSSLESS)
    panel = WoodPanel(wood, extent=(-0.03, 0.03, -0.03, 0.03))
    power, steps, dt = 0.2, 50, 0.1
    irradiance = gaussian_irradiance(panel, (0.0, 0.0), power, 1.5e-3)
    deposited = wood.absorptance_wood * np.sum(irradiance * panel.cell_areas)
    assert deposited == pytest.approx(wood.absorptance_wood * power, rel=0.01)
    for _ in range(steps):
        panel.step(dt, irradiance)
    assert panel.stored_energy() == pytest.approx(deposited * steps * dt, rel=1e-6)


def test_char_is_irreversible_raises_absorptance_and_needs_pyrolysis_temperature():
    wood = WoodParameters()
    panel = WoodPanel(wood, extent=(-0.03, 0.03, -0.03, 0.03))
    weak = gaussian_irradiance(panel, (0.0, 0.0), 0.02, 1.5e-3)
    for _ in range(100):
        panel.step(0.1, weak)
    assert panel.surface_temperature().max() < wood.pyrolysis_temperature
    assert panel.char.max() == 0.0
    strong = gaussian_irradiance(panel, (0.0, 0.0), 0.8, 1.0e-3)
    for _ in range(100):
        panel.step(0.1, strong)
    charred = panel.char.copy()
    assert charred.max() > 0.9
    assert panel.absorptance().max() > wood.absorptance_wood + 0.4
    for _ in range(100):
        panel.step(0.1, np.zeros_like(strong))
    assert panel.surface_temperature().max() < wood.pyrolysis_temperature
    assert np.all(panel.char >= charred)
    assert panel.char_at(0.0, 0.0) > 0.9 and panel.char_at(0.01, 0.01) == 0.0
    # The heat of pyrolysis taken is Delta_H per kg of the wood that turned, and only wood
    # that passed T_p turned.
    volumes = panel.z_widths[:, None, None] * panel.cell_areas[None]
    turned = wood.density * float(np.sum(volumes * (1.0 - panel.unpyrolysed)))
    assert turned > 0.0 and np.all(panel.unpyrolysed >= 0.0)
    assert panel.ledger.pyrolysed == pytest.approx(wood.heat_of_pyrolysis * turned, rel=1e-9)
    assert np.all(panel.unpyrolysed[:, 0, :] == 1.0)  # the patch edge never reached T_p


def test_bad_input_is_refused_and_leaves_the_state_unchanged():
    panel = WoodPanel(extent=(-0.03, 0.03, -0.03, 0.03))
    before = panel.theta.copy()
    with pytest.raises(ValueError, match='shape'):
        panel.step(0.1, np.zeros((3, 3)))
    with pytest.raises(ValueError, match='>= 0'):
        panel.step(0.1, -np.ones(panel.cell_areas.shape))
    with pytest.raises(ValueError, match='dt'):
        panel.step(0.0, np.zeros(panel.cell_areas.shape))
    with pytest.raises(ValueError, match='conductivity'):
        WoodParameters(conductivity=0.0)
    assert np.array_equal(panel.theta, before) and panel.time == 0.0
