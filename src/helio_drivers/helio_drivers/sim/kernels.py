"""
Compiled loops of the simulated world (issue 16): the heat step's sweeps and the cameras'.

numba compiles these once per machine (``cache=True``: the machine code is kept beside this
file, or in numba's user cache when that is not writable) and runs them on the calling
thread, no thread pool (as every helio process: ``single_threaded_numerics``). Each is a
loop the numpy form of which made several passes over the whole array with a temporary
per pass; compiled, one loop nest reads and writes each cell once or twice, in the cache.

Why numba (README, "Dependencies"): the world's hot loops are recurrences (the Thomas
algorithm along each axis) and fused per-pixel arithmetic that numpy cannot express without
temporaries; numba compiles the plain loops from Python with no C build step in colcon, and
the pip wheel (with llvmlite) installs on every machine the project supports.
"""

import math

import numba
import numpy as np


def thomas_factors(lower, diagonal, upper, dt):
    """
    Return the top-down elimination of (I - dt A) for a tridiagonal A (1-D arrays).

    (sub, super_eliminated, inverse_pivot): row i of I - dt A is
    sub[i] x[i-1] + (1 - dt diagonal[i]) x[i] - dt upper[i] x[i+1]; the Thomas algorithm's
    forward sweep is d'[i] = (r[i] - sub[i] d'[i-1]) inverse_pivot[i], its back sweep
    x[i] = d'[i] - super_eliminated[i] x[i+1]. The coefficients are shared by every line
    of the patch (the operator is the same on each), so they are worked out once per dt.
    """
    n = len(diagonal)
    sub = -dt * np.asarray(lower, dtype=float)
    main = 1.0 - dt * np.asarray(diagonal, dtype=float)
    sup = -dt * np.asarray(upper, dtype=float)
    eliminated = np.zeros(n)
    inverse_pivot = np.zeros(n)
    inverse_pivot[0] = 1.0 / main[0]
    eliminated[0] = sup[0] * inverse_pivot[0]
    for i in range(1, n):
        inverse_pivot[i] = 1.0 / (main[i] - sub[i] * eliminated[i - 1])
        eliminated[i] = sup[i] * inverse_pivot[i]
    eliminated[-1] = 0.0
    return sub, eliminated, inverse_pivot


@numba.njit(cache=True, nogil=True, error_model='numpy', inline='always')
def _scaled_row(out, coefficient, row):
    """Set the row `out` = `coefficient` x `row` (1-D, one contiguous pass)."""
    for i in range(out.shape[0]):
        out[i] = coefficient * row[i]


@numba.njit(cache=True, nogil=True, error_model='numpy', inline='always')
def _add_scaled_row(out, coefficient, row):
    """Add `coefficient` x `row` to the row `out` (1-D, one contiguous pass)."""
    for i in range(out.shape[0]):
        out[i] += coefficient * row[i]


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _layer_explicit_terms(theta, k, dt_ay_ops, dt_az_ops, top_loss, dt_ay, dt_az):
    """
    Fill dt_ay = dt Ay theta and dt_az = dt Az theta (Az with the surface loss) of layer k.

    `dt_ay`, `dt_az` (y, x): the layer's. Each is the three-point stencil of its axis,
    applied row by row (y: the rows j - 1, j, j + 1 of layer k; z: row j of the layers
    k - 1, k, k + 1). The stencil has no neighbour beyond the lateral ends (adiabatic) and
    the bottom layer; the top layer adds the surface loss. The helpers inline: the same
    loops and speed as writing each row's loop out.
    """
    nz, ny, nx = theta.shape
    ay_lower, ay_diagonal, ay_upper = dt_ay_ops
    az_lower, az_diagonal, az_upper = dt_az_ops
    for j in range(ny):
        _scaled_row(dt_ay[j], ay_diagonal[j], theta[k, j])
        if j > 0:
            _add_scaled_row(dt_ay[j], ay_lower[j], theta[k, j - 1])
        if j < ny - 1:
            _add_scaled_row(dt_ay[j], ay_upper[j], theta[k, j + 1])
        _scaled_row(dt_az[j], az_diagonal[k], theta[k, j])
        if k > 0:
            _add_scaled_row(dt_az[j], az_lower[k], theta[k - 1, j])
        else:
            for i in range(nx):
                dt_az[j, i] -= top_loss[j, i] * theta[0, j, i]
        if k < nz - 1:
            _add_scaled_row(dt_az[j], az_upper[k], theta[k + 1, j])


@numba.njit(cache=True, nogil=True, error_model='numpy')
def douglas_step(theta, out, dt_source, top_loss, dt_ay_ops, dt_az_ops, x_factors,
                 y_factors, z_elimination, top_pivot):
    """
    One Douglas ADI step for backward Euler of the patch (wood.py), into `out`.

    Returns the highest new rise of each layer (z,).

    theta (z, y, x) the rises now, out the same shape (overwritten with the new ones),
    dt_source (y, x) dt times the surface source of the top layer, top_loss (y, x) dt h_top
    / (rho c dz0), dt_ay_ops and dt_az_ops the (lower, diagonal, upper) of dt Ay and dt Az
    (Az without the surface loss), x_factors and y_factors the ``thomas_factors`` of
    (I - dt Ax) and (I - dt Ay), z_elimination the bottom-up (above, factor,
    inverse_pivot) of (I - dt Az) without the loss, and top_pivot (y, x) the top row's
    pivot with the loss. The scheme (Douglas and Gunn):
    (I - dt Ax) u1 = u + dt (Ay + Az) u + dt f; (I - dt Ay) u2 = u1 - dt Ay u;
    (I - dt Az) u3 = u2 - dt Az u; every solve the Thomas algorithm in double precision.

    Everything but the z solve stays within a layer: a layer's explicit terms, its x and
    y sweeps and its share of the z sweep's right-hand side are done one layer at a time,
    in the core's cache (a 10 x 90 x 90 patch's whole-volume arrays, 0.65 MB each, do not
    fit in it together); the same operations in the same order as whole-volume passes.
    """
    nz, ny, nx = theta.shape
    x_sub, x_eliminated, x_inverse = x_factors
    y_sub, y_eliminated, y_inverse = y_factors
    above, factor, z_inverse = z_elimination
    dt_ay = np.empty((ny, nx))      # the layer's dt Ay u and dt Az u
    dt_az = np.empty((ny, nx))
    for k in range(nz):
        _layer_explicit_terms(theta, k, dt_ay_ops, dt_az_ops, top_loss, dt_ay, dt_az)
        # right-hand side of the x sweep: u + dt Ay u + dt Az u + dt f
        for j in range(ny):
            for i in range(nx):
                out[k, j, i] = theta[k, j, i] + dt_ay[j, i] + dt_az[j, i]
        if k == 0:
            for j in range(ny):
                for i in range(nx):
                    out[0, j, i] += dt_source[j, i]
        # x sweep (lines along the contiguous axis: the lines of a layer advance together)
        for j in range(ny):
            out[k, j, 0] *= x_inverse[0]
        for i in range(1, nx):
            sub, inverse = x_sub[i], x_inverse[i]
            for j in range(ny):
                out[k, j, i] = (out[k, j, i] - sub * out[k, j, i - 1]) * inverse
        for r in range(nx - 1):
            i = nx - 2 - r
            eliminated = x_eliminated[i]
            for j in range(ny):
                out[k, j, i] -= eliminated * out[k, j, i + 1]
        # y sweep of u1 - dt Ay u
        inverse = y_inverse[0]
        for i in range(nx):
            out[k, 0, i] = (out[k, 0, i] - dt_ay[0, i]) * inverse
        for j in range(1, ny):
            sub, inverse = y_sub[j], y_inverse[j]
            for i in range(nx):
                out[k, j, i] = (out[k, j, i] - dt_ay[j, i] - sub * out[k, j - 1, i]) * inverse
        for r in range(ny - 1):
            j = ny - 2 - r
            eliminated = y_eliminated[j]
            for i in range(nx):
                out[k, j, i] -= eliminated * out[k, j + 1, i]
        # the z sweep's right-hand side: u2 - dt Az u
        for j in range(ny):
            for i in range(nx):
                out[k, j, i] -= dt_az[j, i]
    # z sweep, eliminated from the bottom layer up (only the top row's pivot differs from
    # column to column: the surface loss)
    layer_max = np.empty(nz)
    if nz == 1:
        for j in range(ny):
            for i in range(nx):
                out[0, j, i] /= top_pivot[j, i]
        layer_max[0] = out.max()
        return layer_max
    inverse = z_inverse[nz - 1]
    for j in range(ny):
        for i in range(nx):
            out[nz - 1, j, i] *= inverse
    for r in range(nz - 2):
        k = nz - 2 - r
        a, inverse = above[k], z_inverse[k]
        for j in range(ny):
            for i in range(nx):
                out[k, j, i] = (out[k, j, i] - a * out[k + 1, j, i]) * inverse
    a = above[0]
    for j in range(ny):
        for i in range(nx):
            out[0, j, i] = (out[0, j, i] - a * out[1, j, i]) / top_pivot[j, i]
    layer_max[0] = out[0].max()
    for k in range(1, nz):
        f = factor[k]
        highest = -np.inf
        for j in range(ny):
            for i in range(nx):
                value = out[k, j, i] - f * out[k - 1, j, i]
                out[k, j, i] = value
                highest = max(highest, value)
        layer_max[k] = highest
    return layer_max


@numba.njit(cache=True, nogil=True, error_model='numpy')
def tone_table_read_out(light, scale, uniform_scale, last, level_table, gain_table, level,
                        gain, index):
    """
    Fill `level` and `gain` (h, w, 3) float32 from tables indexed by light (NoisyReadOut).

    `light` (h, w, channels >= 3): the first three channels are read (a warp's padding
    channel is skipped, not copied away). Per element, in single precision as numpy's
    passes did it: index = light x scale[r, c] (the pixel's: the vignetting; or x
    `uniform_scale` when `scale` is empty), clipped to [0, last] (NaN to 0), + 0.5,
    truncated; then level = level_table[index], gain = gain_table[index]. Row by row: the
    indices into the int32 scratch `index` (3 w: it stays in the cache), then the
    look-ups. Any strides: `level` and `gain` may be views of a kept frame's stage.
    """
    uniform = scale.shape[0] == 0
    top = np.float32(last)
    height, width = level.shape[0], level.shape[1]
    for r in range(height):
        row = light[r]
        for c in range(width):
            factor = uniform_scale if uniform else scale[r, c]
            index[3 * c] = _table_index(row[c, 0] * factor, top)
            index[3 * c + 1] = _table_index(row[c, 1] * factor, top)
            index[3 * c + 2] = _table_index(row[c, 2] * factor, top)
        level_row, gain_row = level[r], gain[r]
        for c in range(width):
            for k in range(3):
                level_row[c, k] = level_table[index[3 * c + k]]
                gain_row[c, k] = gain_table[index[3 * c + k]]


@numba.njit(cache=True, nogil=True, error_model='numpy', inline='always')
def _table_index(value, top):
    """Return int32(`value` clipped to [0, `top`] (NaN to 0) + 0.5), float32 throughout."""
    value = value if value > np.float32(0.0) else np.float32(0.0)      # NaN too
    value = value if value < top else top
    return np.int32(value + np.float32(0.5))


@numba.njit(cache=True, nogil=True, error_model='numpy')
def noisy_read_out(level, gain, noise, out):
    """
    Fill `out` uint8: round(level + gain x noise), saturated to 0..255 (flat arrays).

    OpenCV's multiply-then-add of the same float32 values (rounding half to even, as
    ``cvRound``) in one vectorised pass: no look-up per element (a gather per element
    costs seven times this pass), the tables were read once when the light changed.
    """
    low, high = np.float32(0.0), np.float32(255.0)
    for p in range(level.shape[0]):
        value = level[p] + gain[p] * np.float32(noise[p])
        out[p] = np.uint8(np.rint(min(max(value, low), high)))


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _first_at_or_above(sorted_values, value, right):
    """Binary search: numpy's searchsorted of one value (side 'right' when `right`)."""
    low, high = 0, len(sorted_values)
    while low < high:
        middle = (low + high) // 2
        if sorted_values[middle] < value or (right and sorted_values[middle] == value):
            low = middle + 1
        else:
            high = middle
    return low


@numba.njit(cache=True, nogil=True, error_model='numpy')
def bilinear_weights_on_axis(centres, coordinates, index, weight):
    """
    Fill index (i0) and weight (of i0 + 1) of linear interpolation on a non-uniform axis.

    What ``wood.bilinear_weights`` documents: i0 = clip(searchsorted(centres, x) - 1, 0,
    n - 2), weight = clip((x - c[i0]) / (c[i0 + 1] - c[i0]), 0, 1); a NaN coordinate
    sorts last (numpy's order) and keeps a NaN weight.
    """
    n = len(centres)
    for p in range(len(coordinates)):
        x = coordinates[p]
        if x != x:
            i = n - 2
        else:
            i = min(max(_first_at_or_above(centres, x, False) - 1, 0), n - 2)
        index[p] = i
        w = (x - centres[i]) / (centres[i + 1] - centres[i])
        if w < 0.0:
            w = 0.0
        elif w > 1.0:
            w = 1.0
        weight[p] = w


@numba.njit(cache=True, nogil=True, error_model='numpy')
def bin_points(x, y, weights, x_edges, y_edges, x_even, y_even, out):
    """
    Add `weights` of points (x, y) to the cells (y, x) of increasing edges in `out`.

    ``np.histogram2d(y, x, bins=(y_edges, x_edges), weights=weights)``'s rule: a cell holds
    its low edge, the last cell its high edge too; points outside (or NaN) are left out.
    `x_even` and `y_even` = (first, last) edge indices of a run of cells of equal width
    (the patch's fine region, where the spot is): a point there finds its cell by
    arithmetic (times the cells per metre: a division per point cost a third of the
    loop), checked against the edges; elsewhere by binary search.
    """
    nx, ny = len(x_edges) - 1, len(y_edges) - 1
    x_per_metre = _cells_per_metre(x_edges, x_even[0], x_even[1])
    y_per_metre = _cells_per_metre(y_edges, y_even[0], y_even[1])
    for p in range(len(x)):
        column = _cell_of(x_edges, nx, x_even[0], x_even[1], x_per_metre, x[p])
        row = _cell_of(y_edges, ny, y_even[0], y_even[1], y_per_metre, y[p])
        if column >= 0 and row >= 0:
            out[row, column] += weights[p]


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _cells_per_metre(edges, first, last):
    """Return the cells per unit length of the even run of edges [first, last] (0: none)."""
    if last <= first:
        return 0.0
    return (last - first) / (edges[last] - edges[first])


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _cell_of(edges, cells, first, last, per_metre, value):
    """
    Return the cell of `value` (histogram rule, see ``bin_points``), -1 outside.

    In the even run [first, last] the cell is guessed from `per_metre` and then moved
    until the edges hold the value: the edges decide, whatever the guess's rounding.
    """
    if not (value >= edges[0] and value <= edges[cells]):
        return -1
    if value == edges[cells]:
        return cells - 1
    if last > first and value >= edges[first] and value < edges[last]:
        cell = min(max(first + int((value - edges[first]) * per_metre), first), last - 1)
        while value < edges[cell]:
            cell -= 1
        while value >= edges[cell + 1]:
            cell += 1
        return cell
    return _first_at_or_above(edges, value, True) - 1


@numba.njit(cache=True, nogil=True, error_model='numpy', inline='always')
def _loss_and_slope_at(rise, ambient_kelvin, ambient4, convection, radiating):
    """
    Return the surface loss [W/m^2] and its slope [W/(m^2 K)] at a top-layer rise [K].

    loss = h (T - T_a) + eps sigma (T^4 - T_a^4), slope = h + 4 eps sigma T^3 (T in K,
    at least 0); `ambient4` = T_a^4.
    """
    t = max(rise + ambient_kelvin, 0.0)
    squared = t * t
    return (convection * rise + radiating * (squared * squared - ambient4),
            4.0 * radiating * (squared * t) + convection)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def surface_loss(top, ambient_kelvin, convection, radiating, loss, slope):
    """
    Fill the surface loss [W/m^2] and its slope [W/(m^2 K)] at top-layer rises `top` [K].

    Per element of the flat arrays (``WoodPanel._loss_and_slope``; ``_loss_and_slope_at``).
    """
    ambient4 = ambient_kelvin ** 4
    for p in range(top.shape[0]):
        loss[p], slope[p] = _loss_and_slope_at(top[p], ambient_kelvin, ambient4, convection,
                                               radiating)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def surface_source(top, irradiance, absorptance, ambient_kelvin, convection, radiating,
                   factor, top_pivot, absorbed, h_top, remainder, dt_source, top_loss,
                   top_diagonal):
    """
    Fill a heat step's surface terms from top-layer rises `top` and `irradiance` (flat).

    What ``WoodPanel.step`` computed in numpy passes, element for element the same
    arithmetic: absorbed = absorptance x irradiance; the loss linearised at `top`
    (h_top = its slope, remainder = loss - h_top x top); dt_source = (absorbed -
    remainder) x `factor` (dt / (rho c dz0)); top_loss = h_top x `factor`; top_diagonal =
    top_loss + `top_pivot`. Returns False (the outputs unfinished) when an irradiance is
    negative or not finite.
    """
    ambient4 = ambient_kelvin ** 4
    for p in range(top.shape[0]):
        q = irradiance[p]
        if not (q >= 0.0 and q < np.inf):   # NaN fails both
            return False
        taken = absorptance[p] * q
        loss, slope = _loss_and_slope_at(top[p], ambient_kelvin, ambient4, convection,
                                         radiating)
        rest = loss - slope * top[p]
        absorbed[p], h_top[p], remainder[p] = taken, slope, rest
        dt_source[p] = (taken - rest) * factor
        top_loss[p] = slope * factor
        top_diagonal[p] = top_loss[p] + top_pivot
    return True


@numba.njit(cache=True, nogil=True, error_model='numpy')
def surface_ledger(absorbed, h_top, remainder, top, h_back, bottom, areas):
    """
    Return a heat step's (absorbed, lost at the top, lost at the back) power [W] (flat).

    Sums over the columns of absorbed x area, (h_top x top + remainder) x area (the
    linearised loss at the new top rises) and h_back x bottom x area.
    """
    absorbed_power = lost_top = lost_back = 0.0
    for p in range(areas.shape[0]):
        area = areas[p]
        absorbed_power += absorbed[p] * area
        lost_top += (h_top[p] * top[p] + remainder[p]) * area
        lost_back += h_back * bottom[p] * area
    return absorbed_power, lost_top, lost_back


@numba.njit(cache=True, nogil=True, error_model='numpy')
def surface_rise(top, absorbed, ambient_kelvin, convection, radiating, half_depth,
                 conductivity, out):
    """
    Fill the surface rise [K]: top + (absorbed - loss(top)) x `half_depth` / conductivity.

    The half-layer extrapolation of ``WoodPanel._surface_theta`` (flat arrays).
    """
    ambient4 = ambient_kelvin ** 4
    for p in range(top.shape[0]):
        loss, _ = _loss_and_slope_at(top[p], ambient_kelvin, ambient4, convection, radiating)
        out[p] = top[p] + (absorbed[p] - loss) * half_depth / conductivity


@numba.njit(cache=True, nogil=True, error_model='numpy')
def heat_sinks(theta, moisture, unpyrolysed, volumes, cells, dt, rho_c, boiling,
               latent_heat, threshold, heat_per_wood, ambient_kelvin, preexponential,
               activation, gas_constant):
    """
    Evaporate water, then pyrolyse wood, cell by cell in flat cells [0, cells), in place.

    A cell above `boiling` [K rise] with water left turns its excess heat
    rho_c (theta - boiling) into evaporation up to the water it holds (latent_heat [J/kg],
    0: no evaporation); then a cell above `threshold` (T_p) turns its excess into
    pyrolysis, up to the wood the first-order rate A exp(-E / (R T)) converts in dt
    (heat_per_wood [J/m^3] per unit, 0: none). Neither cools a cell below its
    temperature. Returns the heat each took [J] (``wood._take_heat``'s rule per cell).
    """
    evaporated = 0.0
    pyrolysed = 0.0
    evaporating = latent_heat > 0.0
    pyrolysing = heat_per_wood > 0.0
    for p in range(cells):
        rise = theta[p]
        if evaporating and rise > boiling and moisture[p] > 0.0:
            used = min(rho_c * (rise - boiling), moisture[p] * latent_heat)
            rise -= used / rho_c
            theta[p] = rise
            moisture[p] = max(moisture[p] - used / latent_heat, 0.0)
            evaporated += used * volumes[p]
        if pyrolysing and rise > threshold:
            rate = preexponential * math.exp(-activation / (gas_constant
                                                            * (rise + ambient_kelvin)))
            convertible = unpyrolysed[p] * -math.expm1(-rate * dt)
            used = min(rho_c * (rise - threshold), convertible * heat_per_wood)
            theta[p] = rise - used / rho_c
            unpyrolysed[p] = max(unpyrolysed[p] - used / heat_per_wood, 0.0)
            pyrolysed += used * volumes[p]
    return evaporated, pyrolysed


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _bilinear_rise(surface, k, columns, wx, wy):
    """Return the bilinear mix of `surface` at k, k + 1, k + columns, k + columns + 1."""
    low_x, low_y = 1 - wx, 1 - wy
    return (low_y * (low_x * surface[k] + wx * surface[k + 1])
            + wy * (low_x * surface[k + columns] + wx * surface[k + columns + 1]))


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _counts(value, noise, sigma, floor, cap, gain, offset):
    """
    Return the read-out of `value` [degC] as uint16 centikelvin.

    value (1 + gain) + offset (the camera's radiometric error), + sigma noise, clipped to
    [floor, cap].
    """
    value = min(max(value * (1.0 + gain) + offset + sigma * noise, floor), cap)
    return np.uint16(min(max(np.rint((value + 273.15) * 100.0), 0.0), 65535.0))


@numba.njit(cache=True, nogil=True, error_model='numpy')
def thermal_counts(seen_position, corner, columns, wx, wy, inside, surface, far, ambient,
                   noise, sigma, floor, cap, gain, offset, out):
    """
    Fill `out` (H, W) uint16 centikelvin: the thermal read-out of the surface, in one pass.

    Pixel (r, c) sees sampler point seen_position[r, c] (-1: no panel, ambient); a point
    inside the patch is the bilinear mix of `surface` (flat rises) at `corner`, `corner` +
    1, + `columns`, + `columns` + 1 with weights wx, wy, outside it the `far` rise. Then
    + sigma noise[r, c], clipped to [floor, cap] degC, rint((T + 273.15) 100), clipped to
    0..65535: what ``ThermalCamera.temperatures`` and ``celsius_to_centikelvin`` do in
    their passes, element for element in the same double-precision arithmetic.
    """
    height, width = seen_position.shape
    for r in range(height):
        for c in range(width):
            q = seen_position[r, c]
            value = ambient
            if q >= 0:
                if inside[q]:
                    rise = _bilinear_rise(surface, corner[q], columns, wx[q], wy[q])
                else:
                    rise = far
                value = ambient + rise
            out[r, c] = _counts(value, noise[r, c], sigma, floor, cap, gain, offset)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def shadow_grid(xs, ys, form, out):
    """
    Fill `out` (len(ys), len(xs)) bool: the panel points (xs[i], ys[j]) in the lens shadow.

    `form` = (aa, 2ab, bb, 2ac, 2bc, cc, r^2, d0, n0, n1, denominator): the offset from the
    lens centre where the sunward ray from (x, y) meets the lens plane has the squared
    length aa x^2 + 2ab x y + bb y^2 + 2ac x + 2bc y + cc and the ray's length to it is
    (d0 - n0 x - n1 y) / denominator (``FluxField.in_shadow``, the same arithmetic in the
    same order).
    """
    aa, ab2, bb, ac2, bc2, cc, r2, d0, n0, n1, denominator = form
    for j in range(ys.shape[0]):
        y = ys[j]
        for i in range(xs.shape[0]):
            x = xs[i]
            radial2 = aa * x * x + ab2 * x * y + bb * y * y + ac2 * x + bc2 * y + cc
            distance = (d0 - n0 * x - n1 * y) / denominator
            out[j, i] = distance > 0.0 and radial2 <= r2


@numba.njit(cache=True, nogil=True, error_model='numpy')
def points_summary(points, power):
    """
    Return (sum power, sum power x, sum power y, x min, y min, x max, y max) of (N, 2).

    One pass over the rays (numpy's reductions along the first axis of (N, 2) made one
    strided pass each).
    """
    total = sx = sy = 0.0
    x_min = y_min = np.inf
    x_max = y_max = -np.inf
    for p in range(points.shape[0]):
        x, y, w = points[p, 0], points[p, 1], power[p]
        total += w
        sx += w * x
        sy += w * y
        x_min = min(x_min, x)
        x_max = max(x_max, x)
        y_min = min(y_min, y)
        y_max = max(y_max, y)
    return total, sx, sy, x_min, y_min, x_max, y_max


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _cell_shadow_share(x_edges, y_edges, row, col, form, samples):
    """
    Return the share of cell (row, col)'s samples^2 points in the lens shadow.

    The points are at the fractions (k + 0.5) / samples of each cell side; the test is
    ``shadow_grid``'s (the same arithmetic).
    """
    aa, ab2, bb, ac2, bc2, cc, r2, d0, n0, n1, denominator = form
    x0, width = x_edges[col], x_edges[col + 1] - x_edges[col]
    y0, height = y_edges[row], y_edges[row + 1] - y_edges[row]
    count = 0
    for a in range(samples):
        y = y0 + ((a + 0.5) / samples) * height
        for b in range(samples):
            x = x0 + ((b + 0.5) / samples) * width
            radial2 = aa * x * x + ab2 * x * y + bb * y * y + ac2 * x + bc2 * y + cc
            distance = (d0 - n0 * x - n1 * y) / denominator
            if distance > 0.0 and radial2 <= r2:
                count += 1
    return count / (samples * samples)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def shadow_shares(x_edges, y_edges, form, samples, out):
    """
    Fill `out` (ny, nx): each cell's share of the lens shadow (``flux.shadow_fractions``).

    The shadow is convex and far larger than a cell: a cell whose four corners are in it
    is in it (1), one whose corners are out and whose eight neighbours' corners are out too
    is out of it (0); the cells along its edge and their neighbours get the share of their
    samples^2 points in it (``_cell_shadow_share``). The corners are tested as
    ``shadow_grid`` tests points. One compiled pass where numpy's passes over the corner
    grid took 0.13 ms a step.
    """
    ny, nx = out.shape
    corners = np.zeros((ny + 1, nx + 1), np.bool_)
    shadow_grid(x_edges, y_edges, form, corners)
    edge = np.zeros((ny, nx), np.bool_)
    for r in range(ny):
        for c in range(nx):
            count = (int(corners[r, c]) + int(corners[r, c + 1]) + int(corners[r + 1, c])
                     + int(corners[r + 1, c + 1]))
            edge[r, c] = 0 < count < 4
            out[r, c] = 1.0 if count == 4 else 0.0
    # the edge cells and their eight neighbours, marked from the edge cells (a separate
    # loop: marking inside the one above made it 12 % slower)
    near = np.zeros((ny, nx), np.bool_)
    for r in range(ny):
        for c in range(nx):
            if edge[r, c]:
                for dr in range(max(r - 1, 0), min(r + 2, ny)):
                    for dc in range(max(c - 1, 0), min(c + 2, nx)):
                        near[dr, dc] = True
    for r in range(ny):
        for c in range(nx):
            if near[r, c]:
                out[r, c] = _cell_shadow_share(x_edges, y_edges, r, c, form, samples)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def chosen_rays(chosen, points, directions, power, power_scale, out_points, out_slopes,
                out_power):
    """
    Fill the rays of `chosen` (B, N) bool, band after band (flux._TracedRays's sets).

    Of `points` and `directions` (B, N, 3) and `power` (B, N), in the order of numpy's
    ``a[chosen]``: `out_points` (n, 2) the hit point's x and y, `out_slopes` (n, 2) the
    leaving direction's d_x / d_z and d_y / d_z, `out_power` (n,) the power times
    `power_scale`. One pass: numpy's boolean index of the (B, N, 3) arrays and the slopes'
    strided division took 4.6 ms of a 120 000-ray trace's 12 ms.
    """
    n = 0
    for band in range(chosen.shape[0]):
        for ray in range(chosen.shape[1]):
            if chosen[band, ray]:
                out_points[n, 0] = points[band, ray, 0]
                out_points[n, 1] = points[band, ray, 1]
                z = directions[band, ray, 2]
                out_slopes[n, 0] = directions[band, ray, 0] / z
                out_slopes[n, 1] = directions[band, ray, 1] / z
                out_power[n] = power[band, ray] * power_scale
                n += 1


@numba.njit(cache=True, nogil=True, error_model='numpy')
def carried_points(points, slopes, shift_x, shift_y, shift_z, out):
    """Fill `out` (N, 2): points + (shift_x, shift_y) - shift_z slopes (flux._TracedRays)."""
    for p in range(points.shape[0]):
        out[p, 0] = points[p, 0] + shift_x - shift_z * slopes[p, 0]
        out[p, 1] = points[p, 1] + shift_y - shift_z * slopes[p, 1]


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _count_below(centres, value, hint):
    """
    Return how many `centres` (sorted) are below `value`: numpy's searchsorted (left).

    Walked from `hint`, the count for a point nearby (a pixel's neighbour along its image
    row lands a cell or two away): a step or two instead of a binary search's eight.
    A walk longer than a few cells gives way to the binary search.
    """
    n = len(centres)
    k = min(max(hint, 0), n)
    for _ in range(4):
        if k < n and centres[k] < value:
            k += 1
        elif k > 0 and not centres[k - 1] < value:
            k -= 1
        else:
            return k
    return _first_at_or_above(centres, value, False)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _axis_weight(centres, value, hint):
    """
    Return (i0, weight of i0 + 1, count below) as ``bilinear_weights_on_axis`` finds them.

    `hint`: the count below of a point nearby (``_count_below``); the third value is
    this point's, the hint for the next.
    """
    n = len(centres)
    below = _count_below(centres, value, hint)
    i = min(max(below - 1, 0), n - 2)
    w = (value - centres[i]) / (centres[i + 1] - centres[i])
    return i, min(max(w, 0.0), 1.0), below


@numba.njit(cache=True, nogil=True, error_model='numpy')
def thermal_counts_at(x, y, x_centres, y_centres, bounds, surface, far, ambient, noise,
                      sigma, floor, cap, gain, offset, out):
    """
    Fill `out` (H, W) uint16 as ``thermal_counts`` does, from each pixel's ground point.

    x, y (H, W) where each pixel's ray meets the panel (NaN: never): the interpolation
    weights are found per pixel on the patch's centres, walking from the last pixel's
    (``_count_below``; a camera that moves gets a new view every frame: no sampler worth
    keeping), `bounds` = (x_min, x_max, y_min, y_max) of the patch. The same arithmetic as
    the sampler and ``thermal_counts``.
    """
    height, width = x.shape
    columns = len(x_centres)
    hint_x, hint_y = len(x_centres) // 2, len(y_centres) // 2
    for r in range(height):
        for c in range(width):
            px, py = x[r, c], y[r, c]
            value = ambient
            if px == px:
                if (px >= bounds[0] and px <= bounds[1] and py >= bounds[2]
                        and py <= bounds[3]):
                    ix, wx, hint_x = _axis_weight(x_centres, px, hint_x)
                    iy, wy, hint_y = _axis_weight(y_centres, py, hint_y)
                    rise = _bilinear_rise(surface, iy * columns + ix, columns, wx, wy)
                else:
                    rise = far
                value = ambient + rise
            out[r, c] = _counts(value, noise[r, c], sigma, floor, cap, gain, offset)


@numba.njit(cache=True, nogil=True, error_model='numpy')
def bin_on_raster(points, power, x0, y0, pixel_size, c0, r0, out):
    """
    Add the rays' `power` to the raster pixels (rows from y_min) of window `out` (h, w).

    Pixel (row, col) of the panel raster whose corner is (x0, y0) holds the rays with
    floor((x - x0) / pixel_size) = col and the same for y; `out` starts at (r0, c0).
    Rays outside the window (or NaN) are left out.
    """
    height, width = out.shape
    for p in range(points.shape[0]):
        column = np.floor((points[p, 0] - x0) / pixel_size)
        row = np.floor((points[p, 1] - y0) / pixel_size)
        if column == column and row == row:
            column = int(column) - c0
            row = int(row) - r0
            if column >= 0 and column < width and row >= 0 and row < height:
                out[row, column] += power[p]


@numba.njit(cache=True, nogil=True, error_model='numpy')
def _window_light(r, c, uniform, window, window_box, direct):
    """Return the light per unit of raster pixel (r, c): `relit_texture`'s rule."""
    w0, w1, v0, v1 = window_box
    if r >= w0 and r < w1 and c >= v0 and c < v1:
        return window[r - w0, c - v0] * direct + (uniform - direct)
    return uniform


@numba.njit(cache=True, nogil=True, error_model='numpy')
def relit_texture(albedo, lit, box, uniform, window, window_box, direct, previous,
                  previous_box, previous_direct, changed_only):
    """
    Set `lit` = `albedo` x the light per unit, over raster `box` (r0, r1, c0, c1).

    The textures (H, W, channels) run in rows from y_max: raster row r is texture row
    H - 1 - r. The light is `uniform` (the daylight) outside raster `window_box` (same
    form), and window[r - w0, c - v0] x `direct` + (`uniform` - `direct`) inside it
    (`window`: the direct sun relative to the clear sun, rows from y_min; float32 scalars:
    ``RgbCamera._set_window``'s light in one pass, without a per-channel copy).
    `changed_only`: `lit` holds the albedo under the `previous` window (its box and
    direct sun, the same daylight): only the pixels whose light differs are written (a
    moving lens's window shifts by a few pixels between frames).
    """
    height, channels = albedo.shape[0], albedo.shape[2]
    r0, r1, c0, c1 = box
    for r in range(r0, r1):
        t = height - 1 - r
        for c in range(c0, c1):
            light = _window_light(r, c, uniform, window, window_box, direct)
            if changed_only and light == _window_light(r, c, uniform, previous,
                                                       previous_box, previous_direct):
                continue
            for k in range(channels):
                lit[t, c, k] = albedo[t, c, k] * light


@numba.njit(cache=True, nogil=True, error_model='numpy')
def char_canvas(char, out):
    """
    Fill `out` uint8 (rows from y_max) with rint(255 (1 - chi)) of `char` (rows from y_min).

    ``SimWorld.canvas_image``'s flip, scale, rounding and cast in one pass (a 1000 x 1000
    raster: four whole-raster numpy passes took ~5 ms).
    """
    rows, cols = char.shape
    for r in range(rows):
        source = rows - 1 - r
        for c in range(cols):
            out[r, c] = np.uint8(np.rint(255.0 * (1.0 - char[source, c])))
