"""
Wood panel of the simulated world: transient heat conduction and charring (issue 6, item 3).

The panel lies in the ``world`` plane z = 0 (its surface), the wood below it. Heat flows
laterally and into the depth on a 3-D finite-volume grid that is fine around the light spot
and coarse far from it: a *patch* centred on the spot (lateral cells of ``fine_cell`` inside
``fine_half_width``, then growing geometrically to ``half_width``; layers thin at the
surface, growing with depth down to the panel thickness). When the spot leaves the fine
region the patch re-centres on it (the old field is interpolated onto the new grid, outside
it the far field is used; the energy this moves is booked as ``regrid``). Far from the spot
the panel is a 1-D column (same layers) under the unconcentrated sunlight.

Time stepping is the Douglas alternating-direction implicit scheme for backward Euler: per
step one tridiagonal solve along each axis (the Thomas algorithm, all lines of an axis
sharing its elimination coefficients, in one compiled loop nest: ``kernels.douglas_step``),
unconditionally stable; its fixed point is the exact discrete steady state.
Losses at the surface: convection h (T - T_a) and radiation eps sigma (T^4 - T_a^4), the
linear part implicit, the rest of the radiation explicit; at the back, convection through the
half bottom layer. Lateral patch sides are adiabatic (the far field has no lateral gradient).

Pyrolysis: an irreversible char fraction chi per surface pixel (the raster of the whole
panel at the fine cell size, aligned with the fine cells), first order,
d chi / dt = (1 - chi) A exp(-E / (R T)) where T > T_p, 0 below. Char raises the solar
absorptance: alpha = alpha_wood + (alpha_char - alpha_wood) chi. The char raster is the
painting. The same first-order reaction runs in every cell of the patch (the wood left to
pyrolyse per cell, 1 at the start) and takes an endothermic heat of pyrolysis per kg of wood
turned. It slows the heating a little; it does not set how long T_max stays at the camera's
cap after the retreat (Sec. IV-B3): that is lateral conduction, faster along the face grain
(world x, ``conductivity_along_grain``) than across it. No exothermic char oxidation or
flaming: the paper's lens is too weak for self-sustained burning (Sec. IV-B3).

Water and pyrolysis are heat sinks with a temperature recovery (an enthalpy method): per
step, heat above the sink's temperature turns the reservoir (water, unpyrolysed wood) at the
rate the process allows, never cooling a cell below that temperature.

Units: SI, temperatures in degC at the interface, K inside the radiation law.
"""

from dataclasses import dataclass
import math

from helio_drivers.sim.kernels import (bilinear_weights_on_axis, douglas_step, heat_sinks,
                                       surface_ledger, surface_loss, surface_rise,
                                       surface_source, thomas_factors)
import numpy as np

STEFAN_BOLTZMANN = 5.670374419e-8  # [W/(m^2 K^4)]
GAS_CONSTANT = 8.314462618         # [J/(mol K)]
KELVIN = 273.15


@dataclass(frozen=True)
class WoodParameters:
    """Material and surface values of the panel (sources in config/sim_world.yaml)."""

    density: float = 545.0              # plywood [kg/m^3]
    conductivity: float = 0.12          # across the grain: world y and depth [W/(m K)]
    conductivity_along_grain: float = 0.22  # along the face grain, world x [W/(m K)]
    specific_heat: float = 1215.0       # [J/(kg K)]
    thickness: float = 0.006            # panel thickness [m]
    absorptance_wood: float = 0.40      # solar absorptance of light wood [-]
    absorptance_char: float = 0.90      # solar absorptance of char [-]
    emissivity: float = 0.90            # thermal emissivity of the surface [-]
    convection_top: float = 10.0        # surface heat transfer coefficient [W/(m^2 K)]
    convection_back: float = 5.0        # back face heat transfer coefficient [W/(m^2 K)]
    ambient: float = 25.0               # air and initial panel temperature [degC]
    pyrolysis_temperature: float = 200.0    # T_p, no charring below [degC]
    char_preexponential: float = 1.0e9      # A of the char rate [1/s]
    char_activation_energy: float = 1.40e5  # E of the char rate [J/mol] (tuned)
    charred_fraction: float = 0.5       # chi above which a pixel counts as charred [-]
    moisture_content: float = 0.12      # water per dry wood mass (indoor wood 8-12 %) [-]
    latent_heat: float = 2.26e6         # of evaporating water [J/kg]
    boiling_temperature: float = 100.0  # where the water evaporates [degC]
    heat_of_pyrolysis: float = 3.0e5    # endothermic, per kg of wood pyrolysed [J/kg]

    def __post_init__(self):
        """Reject values that describe no wood."""
        for name in ('density', 'conductivity', 'conductivity_along_grain', 'specific_heat',
                     'thickness'):
            if not getattr(self, name) > 0.0:
                raise ValueError(f'{name} must be > 0, got {getattr(self, name)}')
        for name in ('absorptance_wood', 'absorptance_char', 'emissivity', 'charred_fraction'):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f'{name} must be in [0, 1], got {getattr(self, name)}')
        for name in ('convection_top', 'convection_back', 'char_preexponential',
                     'char_activation_energy', 'moisture_content', 'latent_heat',
                     'heat_of_pyrolysis'):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f'{name} must be >= 0, got {getattr(self, name)}')

    @property
    def volumetric_heat_capacity(self):
        """Return rho c [J/(m^3 K)]."""
        return self.density * self.specific_heat

    @property
    def diffusivity(self):
        """Return k / (rho c) [m^2/s]."""
        return self.conductivity / self.volumetric_heat_capacity

    @property
    def diffusivity_along_grain(self):
        """Return k_along_grain / (rho c) [m^2/s] (world x, the face veneer's grain)."""
        return self.conductivity_along_grain / self.volumetric_heat_capacity

    @property
    def thermal_effusivity_squared(self):
        """Return k rho c [W^2 s/(m^4 K^2)] (the semi-infinite solid's material group)."""
        return self.conductivity * self.volumetric_heat_capacity


@dataclass(frozen=True)
class GridParameters:
    """Shape of the moving patch grid [m]."""

    fine_cell: float = 2.0e-4           # lateral cell (and char pixel) size near the spot
    fine_half_width: float = 6.0e-3     # half side of the fine square
    half_width: float = 0.035           # half side of the whole patch
    lateral_growth: float = 1.25        # ratio of neighbouring coarse cells
    top_layer: float = 5.0e-5           # thickness of the surface layer
    depth_growth: float = 1.5           # ratio of neighbouring layers
    recentre_margin: float = 2.0e-3     # re-centre when the spot is this close to the fine edge

    def __post_init__(self):
        """Reject grids that cannot be built."""
        if not (self.fine_cell > 0.0 and self.top_layer > 0.0):
            raise ValueError('fine_cell and top_layer must be > 0')
        if not self.fine_half_width >= 2.0 * self.fine_cell:
            raise ValueError('fine_half_width must hold at least two fine cells')
        if not self.half_width >= self.fine_half_width:
            raise ValueError('half_width must be >= fine_half_width')
        if not (self.lateral_growth >= 1.0 and self.depth_growth >= 1.0):
            raise ValueError('growth ratios must be >= 1')
        if not 0.0 <= self.recentre_margin < self.fine_half_width:
            raise ValueError('recentre_margin must be in [0, fine_half_width)')


def lateral_edges(grid):
    """Cell edges of one lateral axis, relative to the patch centre: fine, then growing."""
    n_half = max(1, int(round(grid.fine_half_width / grid.fine_cell)))
    fine = np.arange(-n_half, n_half + 1) * grid.fine_cell
    outer = []
    position, width = fine[-1], grid.fine_cell
    while position < grid.half_width - 1e-12:
        width *= grid.lateral_growth
        position = min(position + width, grid.half_width)
        if grid.half_width - position < 0.3 * width:  # no sliver cell at the end
            position = grid.half_width
        outer.append(position)
    outer = np.array(outer)
    return np.concatenate([-outer[::-1], fine, outer])


def depth_edges(grid, thickness):
    """Layer boundaries from the surface (0) down to -thickness: thin on top, growing."""
    edges = [0.0]
    width = grid.top_layer
    while edges[-1] < thickness - 1e-12:
        bottom = min(edges[-1] + width, thickness)
        if thickness - bottom < 0.3 * width:
            bottom = thickness
        edges.append(bottom)
        width *= grid.depth_growth
    return -np.array(edges)


@dataclass
class EnergyLedger:
    """Energy that entered, left and moved through the patch since the ledger started [J]."""

    absorbed: float = 0.0       # solar power absorbed at the surface, integrated
    lost_top: float = 0.0       # convection and radiation from the surface
    lost_back: float = 0.0      # convection from the back face
    evaporated: float = 0.0     # latent heat carried away by the wood's evaporated water
    pyrolysed: float = 0.0      # heat taken by pyrolysis (reaction and volatiles)
    regrid: float = 0.0         # energy change caused by re-centring the patch
    initial_stored: float = 0.0  # heat content above ambient when the ledger started

    def residual(self, stored):
        """Return absorbed - lost + regrid - (stored - initial): zero if energy is conserved."""
        return (self.absorbed - self.lost_top - self.lost_back - self.evaporated
                - self.pyrolysed + self.regrid - (stored - self.initial_stored))


def _tridiagonal_operator(edges, diffusivity):
    """
    Banded form (3, n) of the 1-D conduction operator along one axis, adiabatic ends.

    Row i of the operator: a / w_i * [(u_{i+1} - u_i)/d_{i+1/2} - (u_i - u_{i-1})/d_{i-1/2}]
    with widths w and centre distances d [1/s]. Returns (lower, diagonal, upper) arrays.
    """
    widths = np.abs(np.diff(edges))
    centres = 0.5 * (edges[:-1] + edges[1:])
    coupling = diffusivity / np.abs(np.diff(centres))   # a / d_{i+1/2}  [m/s]
    n = len(widths)
    lower, diagonal, upper = np.zeros(n), np.zeros(n), np.zeros(n)
    upper[:-1] = coupling / widths[:-1]
    lower[1:] = coupling / widths[1:]
    diagonal[:-1] -= upper[:-1]
    diagonal[1:] -= lower[1:]
    return lower, diagonal, upper


def bilinear_weights(centres, coordinates):
    """
    Linear interpolation weights on a non-uniform axis of cell centres.

    Returns (index i0 = clip(searchsorted(centres, x) - 1, 0, n - 2), weight of i0 + 1,
    clipped to [0, 1]); coordinates between the outer edge and the outermost centre take
    the outermost value. A compiled loop (``kernels.bilinear_weights_on_axis``).
    """
    coordinates = np.asarray(coordinates, dtype=float)
    index = np.empty(coordinates.shape, np.intp)
    weight = np.empty(coordinates.shape)
    bilinear_weights_on_axis(np.ascontiguousarray(centres, dtype=float),
                             coordinates.reshape(-1), index.reshape(-1), weight.reshape(-1))
    return index, weight


def pyrolysis_rate(wood, temperature):
    """
    First-order pyrolysis rate of `wood` at `temperature` [degC] [1/s]: A exp(-E / (R T)).

    Zero at or below the pyrolysis temperature T_p (Sec. IV-B: no charring below T_p).
    """
    temperature = np.asarray(temperature, dtype=float)
    rate = wood.char_preexponential * np.exp(
        -wood.char_activation_energy / (GAS_CONSTANT * (temperature + KELVIN)))
    return np.where(temperature > wood.pyrolysis_temperature, rate, 0.0)


def _take_heat(theta, reservoir, active, threshold, heat_per_unit, convertible, rho_c,
               volumes):
    """
    Heat sink with temperature recovery (enthalpy method), in place; return the heat [J].

    In the `active` cells (a mask or indices of theta; theta above `threshold` [K]) the
    excess heat
    rho_c (theta - threshold) [J/m^3] turns up to `convertible` units (one value per active
    cell) of `reservoir` (per unit volume, each unit taking `heat_per_unit` [J/m^3]): a cell
    never cools below `threshold`.
    """
    if not heat_per_unit > 0.0:
        return 0.0
    excess = theta[active]
    if excess.size == 0:
        return 0.0
    excess = rho_c * (excess - threshold)                          # [J/m^3]
    used = np.minimum(excess, convertible * heat_per_unit)         # [J/m^3]
    theta[active] -= used / rho_c
    reservoir[active] = np.maximum(reservoir[active] - used / heat_per_unit, 0.0)
    return float(np.sum(used * np.broadcast_to(volumes, theta.shape)[active]))


class WoodPanel:
    """
    The panel: a moving 3-D patch around the spot, a far-field column and the char raster.

    ``extent`` = (x_min, x_max, y_min, y_max) of the panel surface in the world frame [m].
    Temperatures inside are kept as rises above ambient, theta = T - T_a [K].
    """

    def __init__(self, wood=None, grid=None, extent=(-0.05, 0.20, -0.05, 0.20),
                 centre=(0.0, 0.0)):
        """Build the patch at `centre` (snapped to the char raster), all at ambient."""
        self.wood = wood or WoodParameters()
        self.grid = grid or GridParameters()
        x_min, x_max, y_min, y_max = (float(v) for v in extent)
        if not (x_max > x_min and y_max > y_min):
            raise ValueError(f'panel extent must have x_max > x_min and y_max > y_min: {extent}')
        cell = self.grid.fine_cell
        self.raster_origin = np.array([x_min, y_min])
        self.raster_shape = (int(math.ceil((y_max - y_min) / cell)),
                             int(math.ceil((x_max - x_min) / cell)))
        self.extent = (x_min, x_min + self.raster_shape[1] * cell,
                       y_min, y_min + self.raster_shape[0] * cell)
        self.char = np.zeros(self.raster_shape, dtype=np.float64)  # chi per surface pixel

        self._lateral = lateral_edges(self.grid)
        self._n_fine_half = int(round(self.grid.fine_half_width / cell))
        self.z_edges = depth_edges(self.grid, self.wood.thickness)
        self.z_widths = -np.diff(self.z_edges)
        self.z_centres = 0.5 * (self.z_edges[:-1] + self.z_edges[1:])
        a = self.wood.diffusivity
        # The face veneer's grain runs along world x (conductivity_along_grain); across it
        # (world y) and into the depth the wood conducts with `conductivity`.
        self._ops_x = _tridiagonal_operator(self._lateral, self.wood.diffusivity_along_grain)
        self._ops_y = _tridiagonal_operator(self._lateral, a)
        self._sweep_dt = None
        self._sweeps = None
        self._depth_dt = None
        self._depth_elimination = None
        lower, diagonal, upper = _tridiagonal_operator(self.z_edges, a)
        rho_c = self.wood.volumetric_heat_capacity
        half_bottom = 0.5 * self.z_widths[-1]
        self._h_back = (0.0 if self.wood.convection_back == 0.0 else
                        1.0 / (1.0 / self.wood.convection_back
                               + half_bottom / self.wood.conductivity))
        diagonal = diagonal.copy()
        diagonal[-1] -= self._h_back / (rho_c * self.z_widths[-1])
        # The surface loss is added per column (radiation linearised at each step's T).
        self._ops_z = (lower, diagonal, upper)

        n_lateral = len(self._lateral) - 1
        self.theta = np.zeros((len(self.z_widths), n_lateral, n_lateral))  # (z, y, x)
        self.far_field = np.zeros(len(self.z_widths))                      # column theta
        water = self.wood.moisture_content * self.wood.density                # [kg/m^3]
        self.moisture = np.full(self.theta.shape, water)      # water left per cell [kg/m^3]
        self.far_moisture = np.full(len(self.z_widths), water)
        self.unpyrolysed = np.ones(self.theta.shape)    # wood left to pyrolyse per cell [-]
        self.time = 0.0
        self.ledger = EnergyLedger()
        self.recentres = 0
        self.coarse_overheat = False   # set if T_p was exceeded outside the fine region
        self._char_dirty = None        # raster box (r0, r1, c0, c1) where char changed
        self._centre = np.zeros(2)
        self._place(self._snap(centre))
        self._last_irradiance = np.zeros((n_lateral, n_lateral))
        self._last_absorbed = np.zeros((n_lateral, n_lateral))
        self._surface = self._surface_theta(self.theta[0], self._last_absorbed)

    # ------------------------------------------------------------------ geometry
    def _snap(self, point):
        """Nearest raster corner to `point`, kept so the fine region stays on the panel."""
        cell = self.grid.fine_cell
        corner = np.round((np.asarray(point, dtype=float)[:2] - self.raster_origin) / cell)
        corner[0] = np.clip(corner[0], self._n_fine_half, self.raster_shape[1] - self._n_fine_half)
        corner[1] = np.clip(corner[1], self._n_fine_half, self.raster_shape[0] - self._n_fine_half)
        return corner.astype(int)

    def _place(self, corner):
        """Set the patch centre to raster corner `corner` (column, row)."""
        self._corner = corner
        self._centre = self.raster_origin + corner * self.grid.fine_cell
        self.x_edges = self._centre[0] + self._lateral
        self.y_edges = self._centre[1] + self._lateral
        self.x_centres = 0.5 * (self.x_edges[:-1] + self.x_edges[1:])
        self.y_centres = 0.5 * (self.y_edges[:-1] + self.y_edges[1:])
        self.cell_areas = np.outer(np.diff(self.y_edges), np.diff(self.x_edges))
        self._volumes = (self.z_widths[:, None, None] * self.cell_areas[None]).reshape(-1)
        n_outer = (len(self._lateral) - 1) // 2 - self._n_fine_half
        self._fine = slice(n_outer, n_outer + 2 * self._n_fine_half)
        r0, c0 = corner[1] - self._n_fine_half, corner[0] - self._n_fine_half
        self._raster_fine = (slice(r0, r0 + 2 * self._n_fine_half),
                             slice(c0, c0 + 2 * self._n_fine_half))
        self._absorptance = self._column_absorptance()

    @property
    def centre(self):
        """Return the patch centre in the world frame, (x, y) [m]."""
        return self._centre.copy()

    @property
    def fine_bounds(self):
        """(x_min, x_max, y_min, y_max) of the fine region [m]."""
        f = self._fine
        return (self.x_edges[f.start], self.x_edges[f.stop],
                self.y_edges[f.start], self.y_edges[f.stop])

    def _column_absorptance(self):
        """Solar absorptance of each patch column from the char raster (area average)."""
        w = self.wood
        chi = self._raster_average(self.x_edges, self.y_edges)
        return w.absorptance_wood + (w.absorptance_char - w.absorptance_wood) * chi

    def _raster_average(self, x_edges, y_edges):
        """Mean char fraction over each cell of a grid (cells aligned with raster pixels)."""
        cell = self.grid.fine_cell
        cols = np.clip(np.round((x_edges - self.raster_origin[0]) / cell).astype(int),
                       0, self.raster_shape[1])
        rows = np.clip(np.round((y_edges - self.raster_origin[1]) / cell).astype(int),
                       0, self.raster_shape[0])
        window = self.char[rows[0]:rows[-1], cols[0]:cols[-1]]
        integral = np.zeros((window.shape[0] + 1, window.shape[1] + 1))
        integral[1:, 1:] = window.cumsum(0).cumsum(1)
        r, c = rows - rows[0], cols - cols[0]
        sums = (integral[r[1:]][:, c[1:]] - integral[r[:-1]][:, c[1:]]
                - integral[r[1:]][:, c[:-1]] + integral[r[:-1]][:, c[:-1]])
        counts = np.outer(np.diff(r), np.diff(c))
        # Cells off the panel (counts 0) are bare wood.
        return np.where(counts > 0, sums / np.maximum(counts, 1), 0.0)

    # ------------------------------------------------------------------ state
    def stored_energy(self):
        """Heat content of the patch above ambient [J]."""
        volumes = self.z_widths[:, None, None] * self.cell_areas[None]
        return float(self.wood.volumetric_heat_capacity * np.sum(volumes * self.theta))

    def reset_ledger(self):
        """Start a new energy ledger from the present state."""
        self.ledger = EnergyLedger(initial_stored=self.stored_energy())

    def absorptance(self):
        """Solar absorptance of each patch column (y, x) [-]."""
        return self._absorptance.copy()

    @property
    def placement(self):
        """Return the patch's raster corner (column, row): its grid moves when this changes."""
        return (int(self._corner[0]), int(self._corner[1]))

    def surface_temperature(self):
        """Surface temperature of each patch column (y, x) [degC], half-layer extrapolated."""
        return self.wood.ambient + self._surface

    def _surface_theta(self, top, absorbed):
        """Surface theta from the top-layer theta and the absorbed flux [K]."""
        top = np.ascontiguousarray(top, dtype=float)
        surface = np.empty_like(top)
        surface_rise(top.reshape(-1), np.ascontiguousarray(absorbed, dtype=float).reshape(-1),
                     *self._loss_terms(), 0.5 * self.z_widths[0], self.wood.conductivity,
                     surface.reshape(-1))
        return surface

    def _loss_terms(self):
        """Return the surface loss kernels' (T_ambient [K], h_top, emissivity x sigma)."""
        w = self.wood
        return w.ambient + KELVIN, w.convection_top, w.emissivity * STEFAN_BOLTZMANN

    def _loss_and_slope(self, top):
        """Return the surface loss [W/m^2] and its derivative [W/(m^2 K)] at theta `top`."""
        top = np.ascontiguousarray(top, dtype=float)
        loss, slope = np.empty_like(top), np.empty_like(top)
        surface_loss(top.reshape(-1), *self._loss_terms(), loss.reshape(-1), slope.reshape(-1))
        return loss, slope

    def _loss_linearisation(self, top):
        """
        Surface loss linearised at top-layer theta: loss ~= h theta + r (Newton step).

        Returns (h [W/(m^2 K)], r [W/m^2]); h is the implicit part, r the explicit one.
        """
        loss, h = self._loss_and_slope(top)
        loss -= h * top
        return h, loss

    def _depth_coefficients(self, dt):
        """
        Return the bottom-up elimination of (I - dt Az) without the surface loss, per dt.

        (upper, factor, inverse pivot, top pivot): eliminating from the bottom layer up, only
        the top row holds the per-column surface loss, so every other coefficient is a
        scalar shared by all columns.
        """
        if self._depth_dt != dt:
            lower, diagonal, upper = self._ops_z
            n = len(diagonal)
            below, main, above = -dt * lower, 1.0 - dt * diagonal, -dt * upper
            factor, inverse_pivot = np.zeros(n), np.zeros(n)
            inverse_pivot[n - 1] = 1.0 / main[n - 1]
            factor[n - 1] = below[n - 1] * inverse_pivot[n - 1]
            for k in range(n - 2, 0, -1):
                pivot = main[k] - above[k] * factor[k + 1]
                inverse_pivot[k] = 1.0 / pivot
                factor[k] = below[k] * inverse_pivot[k]
            top = main[0] - (above[0] * factor[1] if n > 1 else 0.0)
            self._depth_elimination = (above, factor, inverse_pivot, top)
            self._depth_dt = dt
        return self._depth_elimination

    def _solve_z(self, dt, rhs, h_top):
        """
        Solve (I - dt Az) x = rhs along the depth, surface loss h_top per column, in place.

        Thomas' algorithm run from the bottom up (scalar pivots below the top layer).
        Returns `rhs`, which now holds x.
        """
        above, factor, inverse_pivot, top = self._depth_coefficients(dt)
        n = len(factor)
        if n > 1:
            rhs[n - 1] *= inverse_pivot[n - 1]
        for k in range(n - 2, 0, -1):
            rhs[k] -= above[k] * rhs[k + 1]
            rhs[k] *= inverse_pivot[k]
        if n > 1:
            rhs[0] -= above[0] * rhs[1]
        rhs[0] /= top + dt * h_top / (self.wood.volumetric_heat_capacity * self.z_widths[0])
        for k in range(1, n):
            rhs[k] -= factor[k] * rhs[k - 1]
        return rhs

    def far_field_surface_temperature(self):
        """Surface temperature of the panel far from the patch [degC]."""
        return self.wood.ambient + float(self.far_field[0])

    def surface_temperature_at(self, x, y):
        """Surface temperature at world points (x, y) on the panel [degC], far field outside."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        surface = self._surface
        ix, wx = bilinear_weights(self.x_centres, x)
        iy, wy = bilinear_weights(self.y_centres, y)
        value = ((1 - wy) * ((1 - wx) * surface[iy, ix] + wx * surface[iy, ix + 1])
                 + wy * ((1 - wx) * surface[iy + 1, ix] + wx * surface[iy + 1, ix + 1]))
        inside = ((x >= self.x_edges[0]) & (x <= self.x_edges[-1])
                  & (y >= self.y_edges[0]) & (y <= self.y_edges[-1]))
        return self.wood.ambient + np.where(inside, value, self.far_field[0])

    def surface_rise(self):
        """Return the surface rise of the patch's columns (flat, K) and of the far field."""
        return np.ascontiguousarray(self._surface).reshape(-1), float(self.far_field[0])

    def surface_sampler(self, x, y):
        """
        Return a SurfaceSampler: sampler() -> the surface temperature at world points (x, y).

        The interpolation weights are found once: a call costs a gather. It is valid while
        the patch stays where it is (``placement`` unchanged); it gives what
        ``surface_temperature_at(x, y)`` gives.
        """
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        ix, wx = bilinear_weights(self.x_centres, x)
        iy, wy = bilinear_weights(self.y_centres, y)
        inside = ((x >= self.x_edges[0]) & (x <= self.x_edges[-1])
                  & (y >= self.y_edges[0]) & (y <= self.y_edges[-1]))
        return SurfaceSampler(self, iy * len(self.x_centres) + ix, wx, wy, inside)

    def char_at(self, x, y):
        """Char fraction of the raster pixel under world points (x, y) (0 off the panel)."""
        cell = self.grid.fine_cell
        col = np.floor((np.asarray(x, dtype=float) - self.raster_origin[0]) / cell).astype(int)
        row = np.floor((np.asarray(y, dtype=float) - self.raster_origin[1]) / cell).astype(int)
        inside = ((col >= 0) & (col < self.raster_shape[1])
                  & (row >= 0) & (row < self.raster_shape[0]))
        return np.where(inside, self.char[np.clip(row, 0, self.raster_shape[0] - 1),
                                          np.clip(col, 0, self.raster_shape[1] - 1)], 0.0)

    # ------------------------------------------------------------------ dynamics
    def follow(self, spot_xy):
        """Re-centre the patch on `spot_xy` if the spot came near the edge of the fine region."""
        if spot_xy is None or not np.all(np.isfinite(spot_xy)):
            return False
        limit = self.grid.fine_half_width - self.grid.recentre_margin
        if np.max(np.abs(np.asarray(spot_xy, dtype=float)[:2] - self._centre)) <= limit:
            return False
        corner = self._snap(spot_xy)
        if np.array_equal(corner, self._corner):
            return False
        self.recentre(corner)
        return True

    def recentre(self, corner):
        """Move the patch to raster corner `corner`, carrying the temperature field over."""
        before = self.stored_energy()
        old_x, old_y, old_theta = self.x_centres, self.y_centres, self.theta
        old_bounds = (self.x_edges[0], self.x_edges[-1], self.y_edges[0], self.y_edges[-1])
        self._place(np.asarray(corner, dtype=int))
        ix, wx = bilinear_weights(old_x, self.x_centres)
        iy, wy = bilinear_weights(old_y, self.y_centres)
        inside = (((self.x_centres >= old_bounds[0]) & (self.x_centres <= old_bounds[1]))[None]
                  & ((self.y_centres >= old_bounds[2])
                     & (self.y_centres <= old_bounds[3]))[:, None])
        wx, wy = wx[None, None, :], wy[None, :, None]
        yy, xx = iy[:, None], ix[None, :]

        def carry(old):
            """Interpolate a (z, y, x) field of the old patch onto the new one."""
            return ((1 - wy) * ((1 - wx) * old[:, yy, xx] + wx * old[:, yy, xx + 1])
                    + wy * ((1 - wx) * old[:, yy + 1, xx] + wx * old[:, yy + 1, xx + 1]))

        moved = carry(old_theta)
        self.theta = np.where(inside[None], moved, self.far_field[:, None, None])
        self.moisture = np.where(inside[None], carry(self.moisture),
                                 self.far_moisture[:, None, None])
        self.unpyrolysed = np.where(inside[None], carry(self.unpyrolysed), 1.0)
        self._last_absorbed = np.zeros_like(self.cell_areas)
        self._last_irradiance = np.zeros_like(self.cell_areas)
        self._surface = self._surface_theta(self.theta[0], self._last_absorbed)
        self.ledger.regrid += self.stored_energy() - before
        self.recentres += 1

    def _sweep_coefficients(self, dt):
        """
        Return the per-dt coefficients of ``kernels.douglas_step`` (kept while dt is).

        (dt Ay's and dt Az's bands, the Thomas factors of I - dt Ax and I - dt Ay, the
        bottom-up elimination of I - dt Az without the surface loss, its top pivot.)
        """
        if self._sweep_dt != dt:
            above, factor, inverse_pivot, top = self._depth_coefficients(dt)
            self._sweeps = (
                tuple(np.ascontiguousarray(dt * band) for band in self._ops_y),
                tuple(np.ascontiguousarray(dt * band) for band in self._ops_z),
                thomas_factors(*self._ops_x, dt), thomas_factors(*self._ops_y, dt),
                (above.copy(), factor.copy(), inverse_pivot.copy()), float(top))
            self._sweep_dt = dt
        return self._sweeps

    def step(self, dt, irradiance, far_irradiance=0.0):
        """
        Advance by `dt` [s] under solar `irradiance` on each patch column (y, x) [W/m^2].

        `far_irradiance` is the (unconcentrated) irradiance far from the patch [W/m^2].
        Douglas ADI: (I - dt Ax) u1 = u + dt (Ay + Az) u + dt f; (I - dt Ay) u2 = u1 - dt Ay u;
        (I - dt Az) u3 = u2 - dt Az u; f the explicit surface source. The sweeps are one
        compiled loop nest (``kernels.douglas_step``: the Thomas algorithm along each axis
        in double precision, the explicit terms recomputed where they are used).
        """
        if not dt > 0.0:
            raise ValueError(f'dt must be > 0 s, got {dt}')
        irradiance = np.ascontiguousarray(irradiance, dtype=float)
        if irradiance.shape != self.cell_areas.shape:
            raise ValueError(f'irradiance must have shape {self.cell_areas.shape}, '
                             f'got {irradiance.shape}')
        theta = self._flat('theta').reshape(self.theta.shape)
        dt_ay, dt_az, x_factors, y_factors, z_elimination, top = self._sweep_coefficients(dt)
        # the surface terms in one compiled pass (kernels.surface_source): absorbed flux,
        # the loss linearised at the top layer (h_top theta + remainder), the explicit
        # source and the implicit loss of the step
        absorbed, h_top, remainder, dt_source, top_loss, top_diagonal = (
            np.empty_like(self.cell_areas) for _ in range(6))
        if not surface_source(theta[0].reshape(-1), irradiance.reshape(-1),
                              self._flat('_absorptance'), *self._loss_terms(),
                              dt / (self.wood.volumetric_heat_capacity * self.z_widths[0]),
                              top, absorbed.reshape(-1), h_top.reshape(-1), remainder.reshape(-1),
                              dt_source.reshape(-1), top_loss.reshape(-1),
                              top_diagonal.reshape(-1)):
            raise ValueError('irradiance must be finite and >= 0')
        u3 = np.empty_like(theta)
        layer_max = douglas_step(theta, u3, dt_source, top_loss, dt_ay, dt_az, x_factors,
                                 y_factors, z_elimination, top_diagonal)

        absorbed_power, lost_top, lost_back = surface_ledger(
            absorbed.reshape(-1), h_top.reshape(-1), remainder.reshape(-1), u3[0].reshape(-1),
            float(self._h_back), u3[-1].reshape(-1), self._flat('cell_areas'))
        self.ledger.absorbed += dt * absorbed_power
        self.ledger.lost_top += dt * lost_top
        self.ledger.lost_back += dt * lost_back
        self.theta = u3
        evaporated, pyrolysed = self._heat_sinks(dt, layer_max)
        self.ledger.evaporated += evaporated
        self.ledger.pyrolysed += pyrolysed
        self._last_absorbed = absorbed
        self._last_irradiance = irradiance
        self._surface = self._surface_theta(self.theta[0], absorbed)
        self._step_far_field(dt, far_irradiance)
        self._update_char(dt)
        self.time += dt

    def _flat(self, name):
        """Return a flat view of the (z, y, x) field `name`, made contiguous first if needed."""
        field = getattr(self, name)
        if not field.flags.c_contiguous:
            field = np.ascontiguousarray(field)
            setattr(self, name, field)
        return field.reshape(-1)

    def _heat_sinks(self, dt, layer_max=None):
        """
        Evaporate water, then pyrolyse wood, in the cells hot enough (in place).

        Cell by cell in one compiled loop (``kernels.heat_sinks``: ``_take_heat``'s rule)
        over the layers down to the last whose highest rise (`layer_max`, from the step;
        None: all) passes the lower of the two temperatures. Returns the heat taken by
        each [J].
        """
        w = self.wood
        boiling = w.boiling_temperature - w.ambient
        threshold = w.pyrolysis_temperature - w.ambient
        evaporating = w.moisture_content > 0.0 and w.latent_heat > 0.0
        pyrolysing = w.heat_of_pyrolysis > 0.0
        if not (evaporating or pyrolysing):
            return 0.0, 0.0
        lowest = min(boiling if evaporating else math.inf,
                     threshold if pyrolysing else math.inf)
        layers = len(self.z_widths)
        if layer_max is not None:
            hot = np.flatnonzero(np.asarray(layer_max) > lowest)
            layers = int(hot[-1]) + 1 if hot.size else 0
        if layers == 0:
            return 0.0, 0.0
        return heat_sinks(self._flat('theta'), self._flat('moisture'),
                          self._flat('unpyrolysed'), self._volumes,
                          layers * self.cell_areas.size, dt,
                          w.volumetric_heat_capacity, boiling,
                          w.latent_heat if evaporating else 0.0, threshold,
                          w.heat_of_pyrolysis * w.density if pyrolysing else 0.0,
                          w.ambient + KELVIN, w.char_preexponential,
                          w.char_activation_energy, GAS_CONSTANT)

    def _step_far_field(self, dt, far_irradiance):
        """Backward-Euler step of the 1-D column far from the spot."""
        rho_c = self.wood.volumetric_heat_capacity
        h_top, remainder = self._loss_linearisation(self.far_field[:1])
        rhs = self.far_field.copy()
        rhs[0] += dt * (self.wood.absorptance_wood * far_irradiance
                        - float(remainder[0])) / (rho_c * self.z_widths[0])
        self.far_field = self._solve_z(dt, rhs, float(h_top[0]))
        if self.far_field.max() > self.wood.boiling_temperature - self.wood.ambient:
            self._evaporate(self.far_field, self.far_moisture, self.z_widths)

    def _evaporate(self, theta, moisture, volumes):
        """
        Turn heat above the boiling point into evaporation while water is left (in place).

        A wet cell cannot pass T_boil; its excess sensible heat evaporates water (latent heat
        L) until the cell is dry. Returns the latent heat taken [J] (cells of `volumes` [m^3]).
        """
        w = self.wood
        if w.moisture_content == 0.0:
            return 0.0
        boiling = w.boiling_temperature - w.ambient
        wet = (theta > boiling) & (moisture > 0.0)
        return _take_heat(theta, moisture, wet, boiling, w.latent_heat, moisture[wet],
                          w.volumetric_heat_capacity, volumes)

    def _update_char(self, dt):
        """Advance the char fraction where the surface passed T_p (fine region only)."""
        w = self.wood
        surface = self._surface + w.ambient
        overheated = surface > w.pyrolysis_temperature
        if not overheated.any():
            return
        fine = (self._fine, self._fine)
        hot = overheated[fine]
        if np.count_nonzero(hot) < np.count_nonzero(overheated):
            self.coarse_overheat = True      # T_p passed outside the fine region
        if not hot.any():
            return
        rate = pyrolysis_rate(w, surface[fine][hot])
        chi = self.char[self._raster_fine]
        chi[hot] = 1.0 - (1.0 - chi[hot]) * np.exp(-rate * dt)
        self._absorptance[fine] = (w.absorptance_wood
                                   + (w.absorptance_char - w.absorptance_wood) * chi)
        # the raster box of the pixels that changed
        rows = np.flatnonzero(hot.any(axis=1))
        cols = np.flatnonzero(hot.any(axis=0))
        row0, col0 = self._raster_fine[0].start, self._raster_fine[1].start
        box = (row0 + int(rows[0]), row0 + int(rows[-1]) + 1,
               col0 + int(cols[0]), col0 + int(cols[-1]) + 1)
        d = self._char_dirty
        self._char_dirty = box if d is None else (min(d[0], box[0]), max(d[1], box[1]),
                                                  min(d[2], box[2]), max(d[3], box[3]))

    def take_char_changes(self):
        """Return the raster box (r0, r1, c0, c1) where char changed since the last call."""
        box, self._char_dirty = self._char_dirty, None
        return box

    def charred_mask(self):
        """Boolean raster of pixels whose char fraction passed `charred_fraction`."""
        return self.char >= self.wood.charred_fraction

    def raster_pixel_centres(self):
        """World x of the raster's columns and y of its rows [m] (row 0 at y_min)."""
        cell = self.grid.fine_cell
        return (self.raster_origin[0] + (np.arange(self.raster_shape[1]) + 0.5) * cell,
                self.raster_origin[1] + (np.arange(self.raster_shape[0]) + 0.5) * cell)


class SurfaceSampler:
    """The surface temperature of a panel at fixed world points (``surface_sampler``)."""

    def __init__(self, panel, corner, wx, wy, inside):
        """Keep the points' lower-left patch column `corner` (flat), weights and mask."""
        self._panel = panel
        self._placement = panel.placement
        self.columns = len(panel.x_centres)
        self.corner, self.wx, self.wy, self.inside = corner, wx, wy, inside

    def surface(self):
        """Return the panel's surface rise (flat, K) and far-field rise now (checked valid)."""
        panel = self._panel
        if panel.placement != self._placement:
            raise RuntimeError('the patch moved: make a new surface_sampler')
        return panel.surface_rise()

    def __call__(self):
        """Return the surface temperature at the points now [degC]."""
        surface, far = self.surface()
        corner, columns, wx, wy = self.corner, self.columns, self.wx, self.wy
        low_x, low_y = 1 - wx, 1 - wy
        value = (low_y * (low_x * surface[corner] + wx * surface[corner + 1])
                 + wy * (low_x * surface[corner + columns]
                         + wx * surface[corner + columns + 1]))
        return self._panel.wood.ambient + np.where(self.inside, value, far)
