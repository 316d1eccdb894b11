"""Fluid-droplet force laws lifted onto all droplets: drag coefficient with Reynolds and void-fraction corrections.

The coupling is the volume-averaged *model A* ("set I" of Zhou, Kuang, Chu & Yu, J. Fluid Mech. 661 (2010) 482),
as in :mod:`fulldem.fluid.solver`: the fluid feels -eps grad p, a droplet feels its buoyant weight (rho_p - rho_f) V g,
the pressure-gradient force -V grad p (dynamic pressure) and the drag beta (u - v), with Di Felice's voidage function

    beta = 3 pi mu d f(Re) eps^(1 - chi(Re)),  Re = rho eps |u - v| d / mu

(Di Felice, Int. J. Multiphase Flow 20 (1994) 153: F = C_D0 (rho/2)(pi d^2/4) eps^2 |u - v|(u - v) eps^-chi).
In a homogeneous suspension in the Stokes regime the droplets then settle at U/U_St = eps^(chi + 1) = (1 - phi)^4.7:
eps^2 from the mixture's pressure gradient and the return flow, eps^(chi - 1) from the drag -- the
Richardson-Zaki law (n = 4.65) that the hindered-settling test checks.
"""

from __future__ import annotations

import math

from numba import njit, prange

# The drag laws and hindrance corrections, their kernel codes and citations, are the shared registries of
# settler.physics (name -> code); drag_factor and hindrance_factor switch on those codes.
from settler.physics import drag_factor, hadamard_rybczynski_factor, hindrance_factor

from .mobility import SELF_CORRECTION_CAP


#: Void fractions below this are clipped in the hindrance factor (a packed bed is about 0.36).
EPS_FLOOR = 0.3


@njit(cache=True)
def drag_coefficient(diameter, slip, eps, density_fluid, viscosity, law, hindrance, viscosity_ratio):
    """Drag coefficient beta [kg/s] of one droplet (model A): F = beta (u - v).

    diameter [m], slip |u - v| [m/s], eps void fraction around the droplet [-], law a code of DRAG_LAWS
    (DRAG_STOKES, DRAG_SCHILLER_NAUMANN), hindrance a code of HINDRANCE (HINDRANCE_DI_FELICE applies Di Felice's
    eps^(-chi); a bool works too: True is HINDRANCE_DI_FELICE); viscosity_ratio mu_d/mu_f > 0 applies the
    Hadamard-Rybczynski fluid-drop factor, 0 leaves rigid spheres. settler.physics.terminal_velocity is the single
    droplet's balance of this drag (eps = 1) against its buoyant weight.
    """
    e = max(eps, EPS_FLOOR)
    reynolds = density_fluid * e * slip * diameter / viscosity
    beta = 3.0 * math.pi * viscosity * diameter * drag_factor(reynolds, law)
    beta *= hindrance_factor(e, reynolds, hindrance)
    if viscosity_ratio > 0.0:
        beta /= hadamard_rybczynski_factor(viscosity_ratio)
    return beta


@njit(cache=True, parallel=True)
def drag_coefficients(diameter, velocity, fluid_velocity, eps, count, density_fluid, viscosity, law, hindrance,
                      viscosity_ratio, spacing, sigma_cells, sigma_diameter, self_correction, mobility_ratios,
                      mobility_factors, oseen_logs, oseen_values, out):
    """beta for every droplet, with the self-induced-velocity correction when ``self_correction`` (see
    :mod:`fulldem.coupling`): beta / (1 - beta M_self), M_self = discrete_factor * oseen(Re_sigma) /
    (6 pi^1.5 mu sigma). The discrete factor is interpolated in the table (sigma/h, factor), the Oseen factor in
    the table (log10 Re_sigma, factor)."""
    for p in prange(count):
        sx = fluid_velocity[p, 0] - velocity[p, 0]
        sy = fluid_velocity[p, 1] - velocity[p, 1]
        sz = fluid_velocity[p, 2] - velocity[p, 2]
        slip = math.sqrt(sx * sx + sy * sy + sz * sz)
        beta = drag_coefficient(diameter[p], slip, eps[p], density_fluid, viscosity, law, hindrance,
                                viscosity_ratio)
        if self_correction:
            smoothing_width = max(sigma_cells * spacing, sigma_diameter * diameter[p])
            re_width = density_fluid * slip * smoothing_width / viscosity
            x = math.log10(max(re_width, 10.0 ** oseen_logs[0]))
            n = oseen_logs.shape[0]
            if x >= oseen_logs[n - 1]:
                oseen = oseen_values[n - 1] * 10.0 ** (oseen_logs[n - 1] - x)
            else:
                step = oseen_logs[1] - oseen_logs[0]
                i = min(int((x - oseen_logs[0]) / step), n - 2)
                t = (x - oseen_logs[i]) / step
                oseen = (1.0 - t) * oseen_values[i] + t * oseen_values[i + 1]
            ratio = smoothing_width / spacing
            m = mobility_ratios.shape[0]
            if ratio <= mobility_ratios[0]:
                discrete = mobility_factors[0]
            elif ratio >= mobility_ratios[m - 1]:
                discrete = mobility_factors[m - 1]
            else:
                j = 0
                while mobility_ratios[j + 1] < ratio:
                    j += 1
                u = (ratio - mobility_ratios[j]) / (mobility_ratios[j + 1] - mobility_ratios[j])
                discrete = (1.0 - u) * mobility_factors[j] + u * mobility_factors[j + 1]
            m_self = discrete * oseen / (6.0 * math.pi**1.5 * viscosity * smoothing_width)
            beta = beta / (1.0 - min(beta * m_self, SELF_CORRECTION_CAP))
        out[p] = beta
