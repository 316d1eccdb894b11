"""Droplet-wall contacts: the box's planes and the outlet hole in a side wall, with the pair law at m_eff = m.

NumPy twin: :func:`fulldem.dem.twins.wall_forces_reference`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import laws
from .records import FASTMATH


#: Wall codes of the box faces, and of the outlet's side wall: x-, x+, y-, y+, z-, z+.
X_LOW, X_HIGH, Y_LOW, Y_HIGH, Z_LOW, Z_HIGH = range(6)


@njit(cache=True, inline="always")
def _in_outlet(p, position, side, outlet_side, outlet_height, outlet_transverse, outlet_radius):
    """True if droplet p's centre faces the outlet hole in wall ``side`` (that wall then exerts no force)."""
    if side != outlet_side:
        return False
    transverse = position[p, 1] if side < Y_LOW else position[p, 0]
    dz = position[p, 2] - outlet_height
    dt = transverse - outlet_transverse
    return dz * dz + dt * dt < outlet_radius * outlet_radius


@njit(cache=True, inline="always")
def _wall_force(p, position, velocity, diameter, mass, wall_lower, wall_upper, outlet_side, outlet_height,
                outlet_transverse, outlet_radius, stiffness_ref, diameter_ref, zeta, law):
    """Force of the box's planes on droplet p: (fx, fy, fz, largest overlap ratio) [N], [-] (the fields of
    :class:`Walls`, unpacked).

    Planes at -inf/+inf where there is none, so the common case -- touching no wall -- costs six comparisons.
    """
    radius = 0.5 * diameter[p]
    x, y, z = position[p, 0], position[p, 1], position[p, 2]
    if (x - wall_lower[0] >= radius) & (wall_upper[0] - x >= radius) & (y - wall_lower[1] >= radius) \
            & (wall_upper[1] - y >= radius) & (z - wall_lower[2] >= radius) & (wall_upper[2] - z >= radius):
        return 0.0, 0.0, 0.0, 0.0
    k = laws.pair_stiffness(stiffness_ref, diameter_ref, diameter[p])
    gamma = laws.damping_coefficient(k, mass[p], zeta)
    worst = 0.0
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    for a in range(3):
        low = radius - (position[p, a] - wall_lower[a])
        high = radius - (wall_upper[a] - position[p, a])
        f = 0.0
        # lower plane: the droplet separates from it moving along +a
        if low > 0.0 and not _in_outlet(p, position, 2 * a, outlet_side, outlet_height, outlet_transverse,
                                        outlet_radius):
            f += laws.normal_force(law, low, velocity[p, a], k, gamma)
            worst = max(worst, low / diameter[p])
        if high > 0.0 and not _in_outlet(p, position, 2 * a + 1, outlet_side, outlet_height, outlet_transverse,
                                         outlet_radius):
            f -= laws.normal_force(law, high, -velocity[p, a], k, gamma)
            worst = max(worst, high / diameter[p])
        if a == 0:
            f0 = f
        elif a == 1:
            f1 = f
        else:
            f2 = f
    return f0, f1, f2, worst


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def wall_forces(position, velocity, diameter, mass, count, w, stiffness_ref, diameter_ref, law, nchunk, force):
    """Add the contact force of the box's planes (:class:`Walls` w) to ``force`` [N]; returns the largest ratio [-].

    The wall law is the pair law (``law``, ``stiffness_ref`` [N/m] at ``diameter_ref`` [m]) with m_eff = m and the
    stiffness of the droplet's own diameter. An absorbing
    bottom exerts nothing (the caller removes droplets there); droplets whose centre faces the outlet hole pass.
    (The contact kernels apply the same walls in their own loop.)
    """
    _, wall_lower, wall_upper, side, height, transverse, radius, zeta = w
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for p in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            fx, fy, fz, ratio = _wall_force(p, position, velocity, diameter, mass, wall_lower, wall_upper, side,
                                            height, transverse, radius, stiffness_ref, diameter_ref, zeta, law)
            force[p, 0] += fx
            force[p, 1] += fy
            force[p, 2] += fz
            local = max(local, ratio)
        worst[ch] = local
    return worst.max()
