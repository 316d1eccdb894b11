"""NumPy twins of the DEM kernels (fulldem.dem) that the tests compare the compiled kernels with; not used by runs.

Written for clarity, not speed: every pair or droplet in a plain NumPy expression, in SI units as the kernels.
"""

from __future__ import annotations

import numpy as np

from ..droplets import COALESCING
from . import laws
from .walls import Y_LOW, Z_LOW


def contact_forces_reference(position, velocity, diameter, mass, flags, partner, count, pair_i, pair_j,
                             stiffness_ref, diameter_ref, zeta, law, period):
    """NumPy twin of the contact kernels over candidate pairs (pair_i, pair_j) (each pair once).

    Returns (force (count, 3) [N], largest overlap ratio [-]).
    """
    law_force = {c.code: c.force for c in laws.CONTACT_LAWS.values()}[law]
    pos, vel = position[:count], velocity[:count]
    d, m = diameter[:count], mass[:count]
    i, j = np.asarray(pair_i), np.asarray(pair_j)
    period = np.asarray(period, dtype=float)
    delta = pos[j] - pos[i]
    safe = np.where(period > 0.0, period, 1.0)
    delta -= np.where(period > 0.0, period * np.rint(delta / safe), 0.0)
    dist = np.sqrt(np.einsum("pk,pk->p", delta, delta))
    reach = 0.5 * (d[i] + d[j])
    mutual = ((flags[i] & COALESCING) != 0) & ((flags[j] & COALESCING) != 0) & (partner[i] == j) & (partner[j] == i)
    touching = (dist < reach) & (dist > 0.0) & ~mutual
    i, j, delta, dist, reach = i[touching], j[touching], delta[touching], dist[touching], reach[touching]
    normal = delta / dist[:, None]
    vn = np.einsum("pk,pk->p", vel[j] - vel[i], normal)
    small = np.minimum(d[i], d[j])
    k = stiffness_ref * (small / diameter_ref) ** 2
    m_eff = m[i] * m[j] / (m[i] + m[j])
    gamma = 2.0 * zeta * np.sqrt(k * m_eff)
    f = np.array([law_force(o, v, kk, g) for o, v, kk, g in zip(reach - dist, vn, k, gamma)])
    force = np.zeros((count, 3))
    if f.size:
        np.add.at(force, i, -f[:, None] * normal)
        np.add.at(force, j, f[:, None] * normal)
    worst = float(np.max((reach - dist) / small)) if f.size else 0.0
    return force, worst


def wall_forces_reference(position, velocity, diameter, mass, count, box_lower, box_upper, periodic,
                          absorbing_bottom, outlet_side, outlet_height, outlet_transverse, outlet_radius,
                          stiffness_ref, diameter_ref, zeta, law):
    """NumPy twin of :func:`wall_forces`: returns (wall force (count, 3) [N], largest overlap ratio [-])."""
    law_force = np.vectorize({c.code: c.force for c in laws.CONTACT_LAWS.values()}[law].py_func)
    pos, vel, d, m = position[:count], velocity[:count], diameter[:count], mass[:count]
    k = stiffness_ref * (d / diameter_ref) ** 2
    gamma = 2.0 * zeta * np.sqrt(k * m)
    force = np.zeros((count, 3))
    worst = 0.0
    for a in range(3):
        if periodic[a]:
            continue
        for side, gap, sign in ((2 * a, pos[:, a] - box_lower[a], 1.0), (2 * a + 1, box_upper[a] - pos[:, a], -1.0)):
            overlap = 0.5 * d - gap
            active = overlap > 0.0
            if side == Z_LOW and absorbing_bottom:
                active[:] = False
            if side == outlet_side:
                transverse = pos[:, 1] if side < Y_LOW else pos[:, 0]
                hole = (pos[:, 2] - outlet_height) ** 2 + (transverse - outlet_transverse) ** 2 < outlet_radius**2
                active &= ~hole
            f = np.where(active, law_force(overlap, sign * vel[:, a], k, gamma), 0.0)
            force[:, a] += sign * f
            if active.any():
                worst = max(worst, float(np.max(overlap[active] / d[active])))
    return force, worst


def integrate_reference(position, velocity, force_old, force_new_of, mass, beta, fluid_velocity, body_acceleration,
                        dem_step, count):
    """NumPy twin of one whole step; ``force_new_of(position, velocity)`` gives the force at the new state.

    Returns (position, velocity, impulse) as new arrays; the drag factors use expm1 directly (no series).
    """
    x, v = position[:count].copy(), velocity[:count].copy()
    m = mass[:count, None]
    u = np.broadcast_to(fluid_velocity, (count, 3)) if len(fluid_velocity) == 1 else fluid_velocity[:count]
    rate = beta[:count, None] / m
    with np.errstate(divide="ignore", invalid="ignore"):
        z = rate * dem_step
        phi1 = np.where(z > 0, -np.expm1(-z) / np.where(z > 0, rate, 1.0), dem_step)
        phi2 = np.where(z > 0, (dem_step - phi1) / np.where(z > 0, rate, 1.0), 0.5 * dem_step * dem_step)
    e = np.exp(-z)
    acc_old = force_old[:count] / m + body_acceleration
    v_start = v.copy()
    x = x + u * dem_step + (v - u) * phi1 + acc_old * phi2
    v = u + (v - u) * e + acc_old * (phi1 - phi2 / dem_step)
    acc_new = force_new_of(x, v) / m + body_acceleration
    v = v + acc_new * phi2 / dem_step
    impulse = m * (v - v_start) - m * dem_step * 0.5 * (acc_old + acc_new)
    return x, v, impulse
