"""Contact laws between droplets (and between a droplet and a wall), written pointwise.

A contact law is a scalar ``@njit`` function of one contact's overlap and normal velocity; the loops over pairs
live in :mod:`fulldem.dem`. Laws are chosen by name from :data:`CONTACT_LAWS` and passed to the kernels as the
integer code :data:`ContactLaw.code`, so one compiled kernel serves every law (:func:`normal_force` dispatches).

Sign conventions (one meaning per symbol, SI units):

* overlap ``delta`` [m] = (d_i + d_j)/2 - |x_j - x_i| > 0 while the droplets touch;
* normal velocity ``v_n`` [m/s] = (v_j - v_i) . n with n = (x_j - x_i)/|x_j - x_i|: positive while they separate
  (so d(delta)/dt = -v_n);
* normal force ``F_n`` [N] positive when repulsive; droplet i receives -F_n n, droplet j receives +F_n n.

Stiffness from an overlap target
--------------------------------
Droplets are soft only so that contacts can be integrated; the stiffness is a numerical choice, not a material
property. It is picked so that a contact carrying ``load_factor`` buoyant droplet weights W = (rho_p - rho_f) g pi
d^3 / 6 is compressed by ``max_overlap_ratio * d`` (:func:`stiffness_for_overlap`). Per pair it scales as
k_ij = k_ref (d_small / d_ref)^2, with d_small the smaller diameter of the pair: the load a contact has to carry
grows with the droplet weight (proportional to d^3) while the allowed overlap grows with d, so k must grow as
d^3 / d = d^2 to keep the same overlap *ratio* for every size. The contact time t_c = pi sqrt(m_eff / k) then grows
as sqrt(d): the smallest droplets set the time step (:func:`stable_step`). A contact between a large droplet
resting on a much smaller one is stiffened only by the small one's size and can overlap more than the target; the
loads in the settler (plumes of fed droplets, absorbing bottom) do not build such piles.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

from numba import njit


#: Integer code of the linear spring-dashpot law (see :func:`hooke_normal_force`).
HOOKE = 0


@njit(cache=True)
def damping_ratio(restitution):
    """Damping ratio zeta of a linear spring-dashpot with restitution coefficient e in (0, 1] [-].

    zeta = -ln e / sqrt(pi^2 + ln^2 e); e = 1 gives 0 (elastic). The inverse is :func:`restitution_coefficient`.
    """
    log_e = math.log(restitution)
    return -log_e / math.sqrt(math.pi * math.pi + log_e * log_e)


@njit(cache=True)
def restitution_coefficient(zeta):
    """Restitution coefficient of a linear spring-dashpot with damping ratio 0 <= zeta < 1 [-].

    e = exp(-pi zeta / sqrt(1 - zeta^2)), the ratio of separation to approach speed when the contact ends at
    zero overlap (the force is not clipped, see :func:`hooke_normal_force`).
    """
    return math.exp(-math.pi * zeta / math.sqrt(1.0 - zeta * zeta))


@njit(cache=True)
def effective_mass(mass_i, mass_j):
    """Reduced mass m_i m_j / (m_i + m_j) of a pair [kg]; against a wall use the droplet's mass itself."""
    return mass_i * mass_j / (mass_i + mass_j)


@njit(cache=True)
def damping_coefficient(stiffness, mass_effective, zeta):
    """Dashpot coefficient gamma = 2 zeta sqrt(k m_eff) [N s/m] (stiffness [N/m], mass [kg], zeta [-])."""
    return 2.0 * zeta * math.sqrt(stiffness * mass_effective)


@njit(cache=True)
def pair_stiffness(stiffness_ref, diameter_ref, diameter_small):
    """Stiffness of a contact whose smaller droplet has ``diameter_small``: k_ref (d_small / d_ref)^2 [N/m]."""
    ratio = diameter_small / diameter_ref
    return stiffness_ref * ratio * ratio


@njit(cache=True)
def hooke_normal_force(overlap, normal_velocity, stiffness, damping):
    """Linear spring-dashpot normal force, frictionless: F_n = k delta - gamma v_n [N].

    Cundall & Strack, Geotechnique 29 (1979) 47. ``overlap`` delta [m] > 0, ``normal_velocity`` v_n [m/s]
    (positive when separating), ``stiffness`` k [N/m], ``damping`` gamma [N s/m]. The force is not clipped at zero
    (it is slightly attractive just before separation), as in LIGGGHTS/LAMMPS ``hooke``: that is what makes the
    restitution coefficient exactly :func:`restitution_coefficient` of the damping ratio.
    """
    return stiffness * overlap - damping * normal_velocity


@njit(cache=True)
def normal_force(law, overlap, normal_velocity, stiffness, damping):
    """The normal force of contact law ``law`` (an integer code from :data:`CONTACT_LAWS`) [N]."""
    if law == HOOKE:
        return hooke_normal_force(overlap, normal_velocity, stiffness, damping)
    return math.nan


def stiffness_for_overlap(max_overlap_ratio, diameter, density_excess, load_factor, gravity):
    """Reference stiffness k [N/m] such that ``load_factor`` buoyant weights compress a contact by ratio * d.

    k = load_factor * (rho_p - rho_f) g pi d^3 / 6 / (max_overlap_ratio * d).

    max_overlap_ratio [-] (e.g. 0.01), diameter d [m] (the reference diameter d_ref of :func:`pair_stiffness`),
    density_excess rho_p - rho_f [kg/m^3], load_factor [-] (how many droplet weights one contact carries: about
    the number of droplet layers resting on it divided by the number of contacts below each droplet; a settling
    cluster in drag-dominated flow needs few), gravity [m/s^2].
    Example: the DEM benchmark's k_n = 5 N/m for 0.5 mm matte in slag corresponds to 40 weights at 2 %.

    Mixed sizes in a pile: the column above a small droplet weighs what it weighs whatever that droplet's size, so
    pass the smallest diameter as d (and as d_ref) and count the load in its weights, layers x (d_large/d_small)^3;
    the d_small^2 scaling then only stiffens the contacts of larger droplets.
    """
    if not (0.0 < max_overlap_ratio < 1.0):
        raise ValueError(f"contacts: max_overlap_ratio = {max_overlap_ratio} must lie in (0, 1)")
    if diameter <= 0.0 or load_factor <= 0.0 or gravity <= 0.0:
        raise ValueError(f"contacts: diameter ({diameter} m), load_factor ({load_factor}) and gravity "
                         f"({gravity} m/s^2) must be positive")
    weight = abs(density_excess) * gravity * math.pi / 6.0 * diameter**3
    return load_factor * weight / (max_overlap_ratio * diameter)


def contact_time(stiffness, mass_effective, zeta=0.0):
    """Duration of a linear spring-dashpot contact [s]: pi / sqrt(k/m_eff - (gamma/2m_eff)^2).

    zeta = 0 gives the undamped t_c = pi sqrt(m_eff/k); damping lengthens the contact by 1/sqrt(1 - zeta^2).
    """
    return math.pi * math.sqrt(mass_effective / stiffness) / math.sqrt(1.0 - zeta * zeta)


def stable_step(stiffness, mass_effective_min, steps_per_contact=30.0):
    """Time step [s] resolving the shortest contact with ``steps_per_contact`` steps.

    Uses the undamped contact time pi sqrt(m_eff/k) of the lightest pair (the shortest contact): the explicit
    velocity-Verlet update is stable below 2 sqrt(m_eff/k), i.e. for more than pi/2 steps per contact; 20 to 50
    steps keep the restitution coefficient within a few per cent (the benchmark case uses about 29). With the
    size-scaled stiffness of :func:`pair_stiffness` pass the stiffness and reduced mass of the smallest pair.
    """
    if steps_per_contact <= math.pi / 2.0:
        raise ValueError(f"contacts: steps_per_contact = {steps_per_contact} must exceed pi/2 for stability")
    return contact_time(stiffness, mass_effective_min) / steps_per_contact


class ContactLaw(NamedTuple):
    """A registry entry: the integer ``code`` the kernels receive, the scalar ``force`` law, and its reference."""

    code: int
    force: Callable
    reference: str


#: Registry of contact laws: name -> :class:`ContactLaw`. Tests loop over its keys.
CONTACT_LAWS = {
    "hooke": ContactLaw(HOOKE, hooke_normal_force,
                        "linear spring-dashpot, Cundall & Strack, Geotechnique 29 (1979) 47"),
}


def contact_law_code(name: str) -> int:
    """The kernel code of the contact law ``name``; a clear error names the allowed ones."""
    try:
        return CONTACT_LAWS[name].code
    except KeyError:
        raise ValueError(f"contacts: unknown contact law {name!r}; choose one of {sorted(CONTACT_LAWS)}") from None
