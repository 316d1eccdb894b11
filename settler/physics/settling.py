"""Single-droplet settling laws: Stokes, Reynolds-dependent drag, fluid-drop and wall factors.

Each law is a scalar ``@njit(cache=True)`` function of floats in SI units, so the same code runs inside the
CFD-DEM kernels (:mod:`fulldem`) and the population balance (:mod:`popbal`). Vectorised twins for NumPy arrays
are made by :func:`settler.physics.vectorize` and carry the suffix ``_v``.

Sign convention: velocities are *settling* velocities, positive downwards when the droplet is denser than the
fluid.
"""

import math

from numba import njit

from .constants import STANDARD_GRAVITY


@njit(cache=True)
def stokes_velocity(diameter, density_droplet, density_fluid, viscosity, gravity=STANDARD_GRAVITY):
    """Stokes terminal velocity of a rigid sphere, seed paper Eq. 1: v = (rho_p - rho_f) g d^2 / (18 mu).

    diameter [m], densities [kg/m^3], viscosity [Pa s], gravity [m/s^2] -> settling velocity [m/s].
    """
    return (density_droplet - density_fluid) * gravity * diameter * diameter / (18.0 * viscosity)


@njit(cache=True)
def relaxation_time(diameter, density_droplet, viscosity):
    """Stokes particle relaxation time tau_p = rho_p d^2 / (18 mu) [s]."""
    return density_droplet * diameter * diameter / (18.0 * viscosity)


@njit(cache=True)
def reynolds_number(diameter, speed, density_fluid, viscosity):
    """Particle Reynolds number Re_p = rho_f |u| d / mu [-]."""
    return density_fluid * abs(speed) * diameter / viscosity


@njit(cache=True)
def schiller_naumann_factor(reynolds):
    """Drag correction f = C_D Re / 24 of Schiller & Naumann (1933), Z. Ver. Dtsch. Ing. 77, 318.

    f = 1 + 0.15 Re^0.687 for Re <= 1000 and the Newton-regime constant C_D = 0.44 (f = 0.44 Re / 24) above,
    as in Fluent and CFDEM. Drag force F = 3 pi mu d f(Re) u_rel.
    """
    if reynolds <= 1000.0:
        return 1.0 + 0.15 * reynolds**0.687
    return 0.44 * reynolds / 24.0


@njit(cache=True)
def schiller_naumann_velocity(diameter, density_droplet, density_fluid, viscosity, gravity=STANDARD_GRAVITY):
    """Terminal velocity with Schiller-Naumann drag, solved from v f(Re(v)) = v_Stokes [m/s].

    v f(Re(v)) is strictly increasing in v, so a safeguarded Newton iteration on a bracket [0, v_Stokes] converges
    to round-off for any Reynolds number; the sign follows the density difference.
    """
    v_stokes = stokes_velocity(diameter, density_droplet, density_fluid, viscosity, gravity)
    target = abs(v_stokes)
    if target == 0.0:
        return 0.0
    scale = density_fluid * diameter / viscosity  # Re = scale * v
    low, high = 0.0, target
    v = target
    for _ in range(200):
        reynolds = scale * v
        f = schiller_naumann_factor(reynolds)
        residual = v * f - target
        if residual > 0.0:
            high = v
        else:
            low = v
        if reynolds <= 1000.0:
            slope = f + 0.15 * 0.687 * reynolds**0.687
        else:
            slope = 2.0 * f
        v_new = v - residual / slope
        if not (low < v_new < high):
            v_new = 0.5 * (low + high)
        if abs(v_new - v) <= 1e-15 * target:
            v = v_new
            break
        v = v_new
    return math.copysign(v, v_stokes)


@njit(cache=True)
def hadamard_rybczynski_factor(viscosity_ratio):
    """Speed-up of a clean fluid drop over a rigid sphere, U_HR/U_St = 3(1 + lam)/(2 + 3 lam) [-].

    viscosity_ratio lam = mu_droplet / mu_fluid. Hadamard (1911), Rybczynski (1911). Rigid limit lam -> inf gives 1.
    """
    return 3.0 * (1.0 + viscosity_ratio) / (2.0 + 3.0 * viscosity_ratio)


@njit(cache=True)
def haberman_sayre_factor(diameter_ratio):
    """Wall factor U/U_inf for a sphere on the axis of a circular tube, lam = d/D < 1 [-].

    Haberman & Sayre (1958), David Taylor Model Basin Report 1143:
    (1 - 2.1050 lam + 2.0865 lam^3 - 1.7068 lam^5 + 0.72603 lam^6) / (1 - 0.75857 lam^5).
    """
    lam = diameter_ratio
    lam3 = lam * lam * lam
    lam5 = lam3 * lam * lam
    return (1.0 - 2.1050 * lam + 2.0865 * lam3 - 1.7068 * lam5 + 0.72603 * lam5 * lam) / (1.0 - 0.75857 * lam5)


@njit(cache=True)
def square_duct_factor(diameter_ratio):
    """Wall factor U/U_inf for a sphere on the axis of a square duct of side L, first order in d/L [-].

    Happel & Brenner (1965), Low Reynolds number hydrodynamics: 1 / (1 + 1.903 d/L).
    """
    return 1.0 / (1.0 + 1.903 * diameter_ratio)


@njit(cache=True)
def richardson_zaki_factor(volume_fraction, exponent=4.65):
    """Hindered-settling factor U/U_St = (1 - phi)^n, Richardson & Zaki (1954), Trans. IChemE 32, 35 [-]."""
    return (1.0 - volume_fraction) ** exponent


@njit(cache=True)
def di_felice_exponent(reynolds):
    """Voidage exponent chi(Re) of Di Felice (1994), Int. J. Multiphase Flow 20, 153 [-].

    Drag in a suspension = single-particle drag x eps^(-chi), chi = 3.7 - 0.65 exp(-(1.5 - log10 Re)^2 / 2).
    """
    r = max(reynolds, 1e-12)
    t = 1.5 - math.log10(r)
    return 3.7 - 0.65 * math.exp(-0.5 * t * t)
