"""Single-droplet settling laws: Stokes, Reynolds-dependent drag, fluid-drop and wall factors.

Each law is a scalar ``@njit(cache=True)`` function of floats in SI units, so the same code runs inside the
CFD-DEM kernels (:mod:`fulldem`) and the population balance (:mod:`popbal`). Vectorised twins for NumPy arrays
are made by :func:`settler.physics.vectorize` and carry the suffix ``_v``.

Sign convention: velocities are *settling* velocities, positive downwards when the droplet is denser than the
fluid.

Registries (:class:`settler.physics.registry.Registry`, name -> kernel code): :data:`DRAG_LAWS`, switched on by
:func:`drag_factor` and :func:`terminal_velocity`, and :data:`HINDRANCE`, switched on by :func:`hindrance_factor`.
"""

import math

from numba import njit

from .constants import STANDARD_GRAVITY
from .registry import Entry, Registry

#: Drag-law code: Stokes drag, f = 1.
DRAG_STOKES = 0
#: Drag-law code: Schiller-Naumann drag, f = 1 + 0.15 Re^0.687.
DRAG_SCHILLER_NAUMANN = 1
#: Single-droplet drag laws: name (case key drag.law) -> code of :func:`drag_factor`.
DRAG_LAWS = Registry(
    "drag law",
    Entry("stokes", DRAG_STOKES, "Creeping-flow drag of a rigid sphere, F = 3 pi mu d u (f = 1).",
          "Stokes 1851, Trans. Camb. Philos. Soc. 9, 8"),
    Entry("schiller_naumann", DRAG_SCHILLER_NAUMANN,
          "Finite-Re drag, f = C_D Re/24 = 1 + 0.15 Re^0.687 (Re <= 1000), C_D = 0.44 above.",
          "Schiller & Naumann 1933, Z. Ver. Dtsch. Ing. 77, 318"),
)

#: Hindrance code: no void-fraction correction.
HINDRANCE_NONE = 0
#: Hindrance code: Di Felice's voidage function (model A: beta x eps^(1 - chi)).
HINDRANCE_DI_FELICE = 1
#: Void-fraction corrections of the drag: name (case key fulldem.hindrance) -> code of :func:`hindrance_factor`.
#: HINDRANCE_DI_FELICE is 1 and HINDRANCE_NONE 0, so a bool "hindrance on" selects the same law.
HINDRANCE = Registry(
    "hindrance",
    Entry("di_felice", HINDRANCE_DI_FELICE,
          "Voidage function eps^-chi, chi = 3.7 - 0.65 exp(-(1.5 - log10 Re)^2 / 2); model A: beta x eps^(1 - chi).",
          "Di Felice 1994, Int. J. Multiphase Flow 20, 153"),
    Entry("none", HINDRANCE_NONE, "No void-fraction correction: single-droplet drag at every void fraction.",
          "none needed: the dilute limit eps -> 1 of any voidage function"),
)


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
    """Particle Reynolds number Re_p = rho_f abs(u) d / mu [-]."""
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
def drag_factor(reynolds, law):
    """Drag correction f = C_D Re / 24 of the drag law with code ``law`` (:data:`DRAG_LAWS`) [-].

    Drag force F = 3 pi mu d f(Re) u_rel. DRAG_STOKES gives 1; any other code Schiller-Naumann.
    """
    if law == DRAG_STOKES:
        return 1.0
    return schiller_naumann_factor(reynolds)


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
def terminal_velocity(diameter, density_droplet, density_fluid, viscosity, law, viscosity_ratio=0.0,
                      gravity=STANDARD_GRAVITY):
    """Terminal settling velocity of a single droplet with the drag law of code ``law`` (:data:`DRAG_LAWS`) [m/s].

    diameter [m], densities [kg/m^3], viscosity of the fluid [Pa s], viscosity_ratio lam = mu_droplet / mu_fluid:
    lam > 0 divides the drag by the Hadamard-Rybczynski factor (a clean fluid drop), exactly as
    :func:`fulldem.coupling.drag.drag_coefficient` applies it; 0 leaves a rigid sphere. The drop then settles where
    v f(Re(v)) = HR(lam) v_Stokes, i.e. at the law's velocity under gravity HR(lam) g: HR x the rigid velocity at
    Re -> 0, a little less at finite Re (f grows with v). Single droplet: void fraction 1, no hindrance.
    """
    speedup = hadamard_rybczynski_factor(viscosity_ratio) if viscosity_ratio > 0.0 else 1.0
    if law == DRAG_STOKES:
        return stokes_velocity(diameter, density_droplet, density_fluid, viscosity, gravity) * speedup
    return schiller_naumann_velocity(diameter, density_droplet, density_fluid, viscosity, gravity * speedup)


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


@njit(cache=True)
def hindrance_factor(void_fraction, reynolds, hindrance):
    """Factor on the drag coefficient beta of model A for the hindrance of code ``hindrance`` (:data:`HINDRANCE`) [-].

    HINDRANCE_DI_FELICE: eps^(1 - chi(Re)) -- Di Felice's eps^-chi on a drag written with the superficial slip
    eps abs(u - v) (Zhou et al. 2010, J. Fluid Mech. 661, 482, model A; see :mod:`fulldem.coupling.drag`); HINDRANCE_NONE: 1.
    Both give 1 at void_fraction = 1. reynolds: Re = rho eps abs(u - v) d / mu.
    """
    if hindrance == HINDRANCE_DI_FELICE:
        return void_fraction ** (1.0 - di_felice_exponent(reynolds))
    return 1.0
