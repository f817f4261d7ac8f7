"""
Focal calibration (paper Sec. V-A): the best heating distance from a d_lp sweep of spot areas.

The robot aligns the lens with the sun and measures the spot area A_c on the ground for
d_lp = 6.4 .. 9.8 cm (0.1 cm steps); the paper finds the minimum at 8.2 cm. Near the
focus a spot of waist radius r_0 grows linearly with defocus, so the measured curve is fit
with A_c(d) = pi (r_0^2 + s^2 (d - d_0)^2) (robust least squares, scipy) and d_0 is the
best heating distance; the sample minimum is reported beside it. With a lens model the same
curve is predicted (``spot.spot_area_curve``) and the offset between measurement and model
is returned, the quantity the paper compares in Fig. 10c.

API
---
``paper_sweep()``: the paper's d_lp values [m].
``fit_focus_curve(d_lp, areas) -> FocusFit(d_0, waist_radius, slope, rms_relative)``.
``calibrate_focus(d_lp, areas, lens=None, sun_elevation=pi/2) -> FocusCalibration``
with ``best_d_lp`` (fit), ``sample_best_d_lp``, ``min_area``, ``fit``, and with a lens
``model_areas``, ``model_best_d_lp`` and ``offset`` (= best_d_lp - model_best_d_lp).
Bad input (lengths, fewer than 5 points, non-positive areas, a minimum at the sweep's end)
raises ValueError saying what is wrong.
"""

from dataclasses import dataclass
import math

from helio_optics.spot import spot_area_curve
import numpy as np
from scipy.optimize import least_squares


def paper_sweep():
    """Return the paper's sweep d_lp = 6.4 .. 9.8 cm by 0.1 cm [m] (35 values)."""
    return np.round(np.arange(64, 99) * 1e-3, 4)


@dataclass
class FocusFit:
    """A_c(d) = pi (r_0^2 + s^2 (d - d_0)^2) fit to a sweep."""

    d_0: float              # best heating distance [m]
    waist_radius: float     # r_0 [m]
    slope: float            # s, spot radius growth per metre of defocus [-]
    rms_relative: float     # rms of (fit - measured) / measured [-]

    def area(self, d_lp):
        """Fitted area [m^2] at d_lp [m]."""
        d_lp = np.asarray(d_lp, dtype=float)
        return math.pi * (self.waist_radius ** 2 + self.slope ** 2 * (d_lp - self.d_0) ** 2)


@dataclass
class FocusCalibration:
    """Result of calibrate_focus (see the module docstring)."""

    best_d_lp: float
    sample_best_d_lp: float
    min_area: float
    fit: FocusFit
    model_areas: np.ndarray = None
    model_best_d_lp: float = float('nan')
    offset: float = float('nan')


def _check_sweep(d_lp, areas):
    d_lp, areas = np.asarray(d_lp, dtype=float), np.asarray(areas, dtype=float)
    if d_lp.ndim != 1 or d_lp.shape != areas.shape:
        raise ValueError(f'd_lp and areas must be 1-D of one length, got {d_lp.shape} and '
                         f'{areas.shape}')
    if d_lp.size < 5:
        raise ValueError(f'a focus sweep needs at least 5 points, got {d_lp.size}')
    if not (np.all(np.isfinite(d_lp)) and np.all(np.isfinite(areas))):
        raise ValueError('the sweep holds NaN or infinite values')
    if np.any(areas <= 0.0) or np.any(d_lp <= 0.0):
        raise ValueError('spot areas and distances must be > 0')
    if np.unique(d_lp).size != d_lp.size:
        raise ValueError('the sweep repeats a distance')
    order = np.argsort(d_lp)
    return d_lp[order], areas[order]


def fit_focus_curve(d_lp, areas):
    """Fit A_c(d) = pi (r_0^2 + s^2 (d - d_0)^2) to the sweep (relative residuals, soft L1)."""
    d_lp, areas = _check_sweep(d_lp, areas)
    best = int(np.argmin(areas))
    if best in (0, d_lp.size - 1):
        raise ValueError(f'the smallest spot is at the end of the sweep (d_lp = {d_lp[best]} m):'
                         ' extend the sweep past the focus')
    r0 = math.sqrt(areas[best] / math.pi)
    far = int(np.argmax(np.abs(d_lp - d_lp[best])))
    slope = math.sqrt(max(areas[far] / math.pi - r0 ** 2, r0 ** 2)) / abs(d_lp[far] - d_lp[best])

    def residual(p):
        model = math.pi * (p[1] ** 2 + p[2] ** 2 * (d_lp - p[0]) ** 2)
        return (model - areas) / areas

    solution = least_squares(residual, [d_lp[best], r0, slope], loss='soft_l1', f_scale=0.1,
                             x_scale=[1e-3, r0, slope])
    d_0, waist, s = solution.x
    rms = float(np.sqrt(np.mean(residual(solution.x) ** 2)))
    return FocusFit(d_0=float(d_0), waist_radius=abs(float(waist)), slope=abs(float(s)),
                    rms_relative=rms)


def calibrate_focus(d_lp, areas, lens=None, sun_elevation=0.5 * math.pi):
    """Best heating distance from measured areas; with a lens, the model curve and offset."""
    d_lp, areas = _check_sweep(d_lp, areas)
    fit = fit_focus_curve(d_lp, areas)
    best = int(np.argmin(areas))
    result = FocusCalibration(best_d_lp=fit.d_0, sample_best_d_lp=float(d_lp[best]),
                              min_area=float(areas[best]), fit=fit)
    if lens is not None:
        model = spot_area_curve(lens, d_lp, sun_elevation)
        model_fit = fit_focus_curve(d_lp, model)
        result.model_areas = model
        result.model_best_d_lp = model_fit.d_0
        result.offset = fit.d_0 - model_fit.d_0
    return result
