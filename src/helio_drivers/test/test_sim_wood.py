"""Wood heat solver against closed forms, its energy balance and the char process."""

import math

from helio_drivers.sim.wood import bilinear_weights, GridParameters, WoodPanel, WoodParameters
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
    for bad in (np.nan, np.inf):     # one bad column among good ones
        irradiance = np.full(panel.cell_areas.shape, 900.0)
        irradiance[5, 7] = bad
        with pytest.raises(ValueError, match='finite'):
            panel.step(0.1, irradiance)
    with pytest.raises(ValueError, match='dt'):
        panel.step(0.0, np.zeros(panel.cell_areas.shape))
    with pytest.raises(ValueError, match='conductivity'):
        WoodParameters(conductivity=0.0)
    assert np.array_equal(panel.theta, before) and panel.time == 0.0


def reference_douglas_step(panel, dt, irradiance):
    """
    One step of the scheme the panel documents, written plainly (the reference).

    Douglas ADI for backward Euler in double precision with dense solves per axis (the
    operators rebuilt from the panel's edges), losses linearised at the top layer,
    evaporation then pyrolysis as whole-field masked sinks, then the char update. Returns
    (theta, moisture, unpyrolysed, char) without touching the panel.
    """
    w = panel.wood
    rho_c = w.volumetric_heat_capacity

    def operator(edges, diffusivity):
        widths = np.abs(np.diff(edges))
        coupling = diffusivity / np.abs(np.diff(0.5 * (edges[:-1] + edges[1:])))
        matrix = np.zeros((len(widths), len(widths)))
        for i, c in enumerate(coupling):
            matrix[i, i + 1] += c / widths[i]
            matrix[i, i] -= c / widths[i]
            matrix[i + 1, i] += c / widths[i + 1]
            matrix[i + 1, i + 1] -= c / widths[i + 1]
        return matrix

    ax = operator(panel.x_edges, w.diffusivity_along_grain)
    ay = operator(panel.y_edges, w.diffusivity)
    az = operator(panel.z_edges, w.diffusivity)
    dz = panel.z_widths
    h_back = 1.0 / (1.0 / w.convection_back + 0.5 * dz[-1] / w.conductivity)
    az[-1, -1] -= h_back / (rho_c * dz[-1])
    theta = panel.theta.copy()
    t = theta[0] + w.ambient + 273.15
    radiating = w.emissivity * 5.670374419e-8
    loss = w.convection_top * theta[0] + radiating * (t ** 4 - (w.ambient + 273.15) ** 4)
    h_top = w.convection_top + 4.0 * radiating * t ** 3
    absorbed = panel.absorptance() * irradiance
    source = np.zeros_like(theta)
    source[0] = (absorbed - (loss - h_top * theta[0])) / (rho_c * dz[0])
    ay_u = np.einsum('ij,zjx->zix', ay, theta)
    az_u = np.einsum('ij,jyx->iyx', az, theta)
    az_u[0] -= h_top * theta[0] / (rho_c * dz[0])
    eye = np.eye(len(panel.x_centres))
    u1 = np.einsum('ij,zyj->zyi', np.linalg.inv(eye - dt * ax),
                   theta + dt * (ay_u + az_u + source))
    u2 = np.einsum('ij,zjx->zix', np.linalg.inv(eye - dt * ay), u1 - dt * ay_u)
    rhs = u2 - dt * az_u
    u3 = np.empty_like(rhs)
    for row in range(rhs.shape[1]):
        for col in range(rhs.shape[2]):
            matrix = np.eye(len(dz)) - dt * az
            matrix[0, 0] += dt * h_top[row, col] / (rho_c * dz[0])
            u3[:, row, col] = np.linalg.solve(matrix, rhs[:, row, col])
    moisture, unpyrolysed = panel.moisture.copy(), panel.unpyrolysed.copy()
    boiling = w.boiling_temperature - w.ambient
    wet = (u3 > boiling) & (moisture > 0.0)
    used = np.minimum(rho_c * (u3[wet] - boiling), moisture[wet] * w.latent_heat)
    u3[wet] -= used / rho_c
    moisture[wet] = np.maximum(moisture[wet] - used / w.latent_heat, 0.0)
    threshold = w.pyrolysis_temperature - w.ambient
    hot = u3 > threshold
    rate = w.char_preexponential * np.exp(-w.char_activation_energy
                                          / (8.314462618 * (u3[hot] + w.ambient + 273.15)))
    heat = w.heat_of_pyrolysis * w.density
    used = np.minimum(rho_c * (u3[hot] - threshold),
                      unpyrolysed[hot] * -np.expm1(-rate * dt) * heat)
    u3[hot] -= used / rho_c
    unpyrolysed[hot] = np.maximum(unpyrolysed[hot] - used / heat, 0.0)
    t = u3[0] + w.ambient + 273.15
    loss = w.convection_top * u3[0] + radiating * (t ** 4 - (w.ambient + 273.15) ** 4)
    surface = u3[0] + (absorbed - loss) * 0.5 * dz[0] / w.conductivity + w.ambient
    char = panel.char.copy()
    fine = panel._fine
    rows, cols = panel._raster_fine
    chi = char[rows, cols]
    charring = surface[fine, fine] > w.pyrolysis_temperature
    rate = w.char_preexponential * np.exp(-w.char_activation_energy
                                          / (8.314462618 * (surface[fine, fine] + 273.15)))
    chi[charring] = 1.0 - (1.0 - chi[charring]) * np.exp(-rate[charring] * dt)
    return u3, moisture, unpyrolysed, char


def test_step_equals_the_plain_douglas_scheme_while_water_boils_and_wood_chars():
    panel = WoodPanel(extent=(-0.03, 0.03, -0.03, 0.03))
    strong = gaussian_irradiance(panel, (0.0, 0.0), 0.8, 1.0e-3) + 800.0
    checked = set()
    for step in range(80):
        if step in (3, 25, 79):   # heating up; water boiling off; wood charring
            theta, moisture, unpyrolysed, char = reference_douglas_step(panel, 0.1, strong)
            panel.step(0.1, strong)
            scale = float(np.abs(theta).max())
            assert np.abs(panel.theta - theta).max() < 1e-6 * scale
            assert np.allclose(panel.moisture, moisture, rtol=1e-6, atol=1e-9)
            assert np.allclose(panel.unpyrolysed, unpyrolysed, rtol=1e-6, atol=1e-9)
            assert np.allclose(panel.char, char, rtol=1e-6, atol=1e-9)
            checked.add(step)
        else:
            panel.step(0.1, strong)
    assert checked == {3, 25, 79}
    assert panel.char.max() > 0.5 and panel.unpyrolysed.min() < 1.0


def test_evaporated_heat_equals_the_latent_heat_of_the_water_lost():
    wood = WoodParameters(heat_of_pyrolysis=0.0)
    panel = WoodPanel(wood, extent=(-0.03, 0.03, -0.03, 0.03))
    assert panel.follow((0.009, 0.004))    # a re-centred patch's fields are carried over
    strong = gaussian_irradiance(panel, (0.009, 0.004), 0.8, 1.0e-3)
    for _ in range(60):
        panel.step(0.1, strong)
    volumes = panel.z_widths[:, None, None] * panel.cell_areas[None]
    water_lost = float(np.sum(volumes * (wood.moisture_content * wood.density
                                         - panel.moisture)))
    assert panel.moisture.min() == 0.0       # the spot dried out, so it could get hotter
    assert panel.surface_temperature().max() > wood.pyrolysis_temperature
    assert panel.ledger.evaporated == pytest.approx(wood.latent_heat * water_lost, rel=1e-9)


def test_bilinear_weights_equal_numpys_search_and_clip():
    # the compiled search against numpy's searchsorted on the patch's uneven centres,
    # coordinates inside, on centres, beyond both ends
    panel = WoodPanel(extent=(-0.03, 0.03, -0.03, 0.03))
    centres = panel.x_centres
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.uniform(centres[0] - 0.01, centres[-1] + 0.01, 5000),
                        centres, [panel.x_edges[0], panel.x_edges[-1]]])
    index, weight = bilinear_weights(centres, x)
    expected = np.clip(np.searchsorted(centres, x) - 1, 0, len(centres) - 2)
    span = centres[expected + 1] - centres[expected]
    assert np.array_equal(index, expected)
    assert np.array_equal(weight, np.clip((x - centres[expected]) / span, 0.0, 1.0))
