"""The fittable [popbal] keys with their bounds, and the standard errors and correlations of a least-squares fit
from its Jacobian: shared by the one-level fit (:mod:`analysis.calibrate`) and the hierarchy's levels."""

from __future__ import annotations

import numpy as np

#: Fittable [popbal] keys, and those a closure set measures before its fit and the bands draw (the collision radii,
#: outer_dispersion): name -> (lower bound, upper bound, unit). Bounds [chosen]: physical (>= 0, a fraction <= 1) and
#: wide enough that an estimate on a bound says the data push beyond what the form allows; the channel must fit in
#: the 0.2 m boxes (R_c < 0.113 m = 1.5 inlet radii of the simple and cubic cases). The core's exponent may be
#: negative; near 0 its relative standard error, which the gate takes, and its relative step say little (a caveat
#: for a fit that puts it there).
PARAMETERS: dict[str, tuple[float, float, str]] = {
    "collision_efficiency": (1e-3, 100.0, "-"),
    "channel_coefficient": (1e-3, 3.0, "-"),
    "channel_feed_fraction": (0.0, 1.0, "-"),
    "channel_radius_factor": (0.05, 1.45, "-"),
    "shear_coefficient": (0.0, 100.0, "-"),
    "feed_layer_thickness": (1e-3, 0.05, "m"),
    "feed_layer_coefficient": (1e-5, 10.0, "-"),
    "axis_velocity_ratio": (0.2, 5.0, "-"),
    "plume_reynolds_scale": (1e-2, 100.0, "-"),
    "return_flow_ratio": (0.0, 100.0, "-"),
    "roof_layer_coefficient": (1e-4, 10.0, "-"),
    "roof_thickness": (1e-3, 0.05, "m"),
    "bottom_layer_factor": (0.05, 20.0, "-"),
    "plume_core_radius": (2e-3, 0.05, "m"),
    "bottom_turning_share": (1e-3, 0.95, "-"),
    "plume_core_exponent": (-1.0, 1.5, "-"),
    "channel_collision_radius": (1e-3, 0.1, "m"),
    "spread_channel_collision_radius": (1e-3, 0.1, "m"),
    "outer_dispersion": (0.0, 1e-2, "m^2/s"),
}


def parameter_uncertainty(jacobian, residual, x, parameters):
    """Standard errors [parameter units], correlation matrix, singular values of J diag(x) and the direction of the
    smallest one, from the Jacobian J (m, p) of residuals r (m,) at the estimates x (p,).

    cov = s^2 (J^T J)^+ with s^2 = r.r / (m - p) (the pseudo-inverse, so a rank-deficient J gives huge, not
    missing, errors; a parameter the residuals do not move at all gets an infinite standard error).
    """
    jacobian = np.asarray(jacobian, dtype=float)
    m, p = jacobian.shape
    s2 = float(residual @ residual) / max(m - p, 1)
    _, singular, vt = np.linalg.svd(jacobian, full_matrices=False)
    tiny = singular.max() * 1e-12 if singular.size and singular.max() > 0 else 0.0
    inverse = (vt.T / np.where(singular > tiny, singular**2, np.inf)) @ vt
    variance = s2 * np.diag(inverse)
    dead = np.all(jacobian == 0.0, axis=0)
    standard_errors = np.where(dead, np.inf, np.sqrt(np.maximum(variance, 0.0)))
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.sqrt(np.diag(inverse))
        correlation = inverse / np.outer(scale, scale)
    correlation[np.ix_(dead, dead)] = np.nan
    _, rel_singular, rel_vt = np.linalg.svd(jacobian * np.asarray(x, dtype=float)[None, :], full_matrices=False)
    weakest = dict(zip(parameters, rel_vt[-1] * np.sign(rel_vt[-1][np.argmax(np.abs(rel_vt[-1]))])))
    return standard_errors, correlation, rel_singular, weakest
