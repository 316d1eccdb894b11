"""DEM kernels for matte droplets: contact and wall forces, and an exponential velocity-Verlet integrator.

Kernels are ``@njit(cache=True)`` functions of arrays and scalars (SI units); :class:`DemStepper` orchestrates them
and :func:`run_dem` runs the DEM-only benchmark case (``benchmarks/bench_dem.py``). Each kernel has a plain NumPy
twin (suffix ``_reference``) that the tests compare it with.

Equation of motion of droplet p (mass m [kg], drag coefficient beta [kg/s], fluid velocity u [m/s] at the droplet,
both frozen over a step):

    dv/dt = a(t) + (u - v) / tau,   tau = m / beta,   a = (contact + wall + other forces) / m + a_body.

The integrator (:func:`integrate_initial` then forces at the new positions, then :func:`integrate_final`) solves the
drag part *exactly*, taking a(t) linear between its values at the two ends of the step (the force at the end is the
one computed at the new positions):

    x_new  = x + u h + (v - u) phi1 + a_old phi2
    v_new  = u + (v - u) E + a_old (phi1 - phi2/h) + a_new phi2/h
    E = exp(-h/tau),  phi1 = tau (1 - E),  phi2 = tau (h - phi1)       (series near h/tau = 0: no cancellation)

so the step is stable for h >> tau (set by the contacts, not by tau), a droplet under a constant force reaches the
terminal velocity u + a tau exactly and follows the analytic trajectory, and for beta = 0 (phi1 = h, phi2 = h^2/2)
it *is* velocity Verlet: symplectic, second order, the restitution of a collision preserved. (A one-call step with
the force frozen over the whole step -- x + v h + a h^2/2, v + a h in the beta = 0 limit -- gains energy by a factor
1 + (omega h)^2/2 per step in a contact, 9 % in the restitution at 29 steps per contact; hence the two halves.)

The drag impulse exchanged over the step, J = beta integral (u - v) dt = m (v_new - v) - m h (a_old + a_new)/2, is
added per droplet to an ``impulse`` array the caller zeroes, so the fluid can receive exactly -J.

Work arrays (prepared by the caller): ``mass`` (cap,) [kg], ``force`` (cap, 3) [N] (contact + wall + any other
force except drag and a_body), ``impulse`` (cap, 3) [N s]. Geometry: ``period`` (3,) [m] (box length on periodic
axes, 0 on bounded ones) and ``inverse_period`` (3,) [1/m] (0 on bounded axes).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np
from numba import njit, prange

from . import contacts
from .droplets import COALESCING
from .neighbours import NeighbourList, reorder_store, wrap_positions

#: LLVM fast-math flags of the hot kernels: fused multiply-add and reciprocal; no reassociation (the pair forces
#: stay exactly antisymmetric, so momentum is conserved to round-off) and no assumption that values are finite.
FASTMATH = {"contract", "arcp"}

#: Wall codes of the box faces, and of the outlet's side wall: x-, x+, y-, y+, z-, z+.
X_LOW, X_HIGH, Y_LOW, Y_HIGH, Z_LOW, Z_HIGH = range(6)

# 1/(k+2)! for k = 0..15: the series of phi2/h^2 = (z - 1 + e^-z)/z^2 = sum_k (-z)^k/(k+2)!, exact to round-off
# for z <= 0.5 with 16 terms (0.5^16/18! < 1e-20).
_SERIES = np.array([1.0 / math.factorial(k + 2) for k in range(16)])
_SERIES_LIMIT = 0.5


# ---------------------------------------------------------------------------------------------------- pointwise laws
@njit(cache=True, inline="always")
def drag_factors(rate, h):
    """(E, phi1, phi2) of the exponential step for drag rate 1/tau = beta/m [1/s] and step h [s].

    E = exp(-h/tau) [-], phi1 = tau (1 - E) [s], phi2 = tau (h - phi1) [s^2]; rate = 0 gives (1, h, h^2/2).
    """
    z = rate * h
    if z < _SERIES_LIMIT:
        p2 = 0.0
        for k in range(15, -1, -1):
            p2 = p2 * (-z) + _SERIES[k]
        p1 = 1.0 - z * p2
        return 1.0 - z * p1, p1 * h, p2 * h * h
    e = math.exp(-z)
    p1 = (1.0 - e) / z
    return e, p1 * h, (1.0 - p1) / z * h * h


@njit(cache=True, inline="always")
def _mutual_partner(p, flags, partner):
    """The coalescence partner of p if both are marked and point at each other, else -1 (they do not repel)."""
    q = partner[p]
    if q >= 0 and (flags[p] & COALESCING) != 0 and (flags[q] & COALESCING) != 0 and partner[q] == p:
        return q
    return -1


@njit(cache=True, inline="always")
def _pair_interaction(position, velocity, diameter, mass, i, j, xi, yi, zi, ui, vi, wi, di, mi, skip,
                      stiffness_ref, diameter_ref, zeta, law, period, inverse_period):
    """Force of j on i for one list entry: (touching, fx, fy, fz, overlap, smaller diameter) [N], [m]."""
    dx = position[j, 0] - xi
    dy = position[j, 1] - yi
    dz = position[j, 2] - zi
    dx -= period[0] * np.rint(dx * inverse_period[0])
    dy -= period[1] * np.rint(dy * inverse_period[1])
    dz -= period[2] * np.rint(dz * inverse_period[2])
    r2 = dx * dx + dy * dy + dz * dz
    dj = diameter[j]
    reach = 0.5 * (di + dj)
    if r2 >= reach * reach or r2 == 0.0 or j == skip:
        return False, 0.0, 0.0, 0.0, 0.0, 1.0
    dist = math.sqrt(r2)
    mj = mass[j]
    mass_sum = mi + mj
    # one division for both 1/dist and the reduced mass m_i m_j/(m_i + m_j) (symmetric in i, j: the pair forces
    # stay exactly opposite)
    both = 1.0 / (dist * mass_sum)
    inv = both * mass_sum
    mass_effective = mi * mj * (both * dist)
    nx, ny, nz = dx * inv, dy * inv, dz * inv
    vn = (velocity[j, 0] - ui) * nx + (velocity[j, 1] - vi) * ny + (velocity[j, 2] - wi) * nz
    small = min(di, dj)
    overlap = reach - dist
    k = contacts.pair_stiffness(stiffness_ref, diameter_ref, small)
    gamma = contacts.damping_coefficient(k, mass_effective, zeta)
    f = contacts.normal_force(law, overlap, vn, k, gamma)
    return True, -f * nx, -f * ny, -f * nz, overlap, small


#: Below this many droplets the stepper runs its kernels on one thread: a parallel launch costs more than it saves,
#: and on a machine shared with other busy processes a small parallel step waits for a descheduled thread.
PARALLEL_MIN_DROPLETS = 2000


def _chunks(count):
    """Number of work chunks for a parallel loop: a few per thread (load balance), at least one."""
    return max(1, min(count, 8 * numba.get_num_threads()))


# ---------------------------------------------------------------------------------------------------- contact forces
@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def contact_forces_full(position, velocity, diameter, mass, flags, partner, count, start, index, stiffness_ref,
                        diameter_ref, zeta, law, period, inverse_period, nchunk, force):
    """Pair forces from a *full* neighbour list: force[i] = sum over partners (overwritten) [N].

    Each droplet sums its own row, so threads never write the same entry. Returns the largest overlap ratio
    (overlap / smaller diameter) [-]. Mutual coalescence partners exert no force on each other.
    """
    worst = np.zeros(nchunk)
    for c in prange(nchunk):
        local = 0.0
        for i in range(c * count // nchunk, (c + 1) * count // nchunk):
            xi, yi, zi = position[i, 0], position[i, 1], position[i, 2]
            ui, vi, wi = velocity[i, 0], velocity[i, 1], velocity[i, 2]
            di, mi = diameter[i], mass[i]
            skip = _mutual_partner(i, flags, partner)
            fx = 0.0
            fy = 0.0
            fz = 0.0
            for k in range(start[i], start[i + 1]):
                touching, gx, gy, gz, overlap, small = _pair_interaction(
                    position, velocity, diameter, mass, i, index[k], xi, yi, zi, ui, vi, wi, di, mi, skip,
                    stiffness_ref, diameter_ref, zeta, law, period, inverse_period)
                if touching:
                    fx += gx
                    fy += gy
                    fz += gz
                    if overlap > local * small:  # the largest overlap ratio without a division per contact
                        local = overlap / small
            force[i, 0] = fx
            force[i, 1] = fy
            force[i, 2] = fz
        worst[c] = local
    return worst.max()


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def contact_forces_half(position, velocity, diameter, mass, flags, partner, count, start, index, stiffness_ref,
                        diameter_ref, zeta, law, period, inverse_period, nchunk, scratch, force):
    """Pair forces from a *half* neighbour list with per-thread accumulation: force (overwritten) [N].

    ``scratch`` (threads, cap, 3) holds each thread's partial forces (zeroed here); they are summed into ``force``
    afterwards. Returns the largest overlap ratio [-]. Mutual coalescence partners exert no force on each other.
    """
    nthread = scratch.shape[0]
    for t in prange(nthread):
        for i in range(t * count // nthread, (t + 1) * count // nthread):
            for a in range(nthread):
                scratch[a, i, 0] = 0.0
                scratch[a, i, 1] = 0.0
                scratch[a, i, 2] = 0.0
    worst = np.zeros(nchunk)
    for c in prange(nchunk):
        buf = scratch[numba.get_thread_id()]
        local = 0.0
        for i in range(c * count // nchunk, (c + 1) * count // nchunk):
            xi, yi, zi = position[i, 0], position[i, 1], position[i, 2]
            ui, vi, wi = velocity[i, 0], velocity[i, 1], velocity[i, 2]
            di, mi = diameter[i], mass[i]
            skip = _mutual_partner(i, flags, partner)
            fx = 0.0
            fy = 0.0
            fz = 0.0
            for k in range(start[i], start[i + 1]):
                j = index[k]
                touching, gx, gy, gz, overlap, small = _pair_interaction(
                    position, velocity, diameter, mass, i, j, xi, yi, zi, ui, vi, wi, di, mi, skip,
                    stiffness_ref, diameter_ref, zeta, law, period, inverse_period)
                if touching:
                    fx += gx
                    fy += gy
                    fz += gz
                    buf[j, 0] -= gx
                    buf[j, 1] -= gy
                    buf[j, 2] -= gz
                    if overlap > local * small:  # the largest overlap ratio without a division per contact
                        local = overlap / small
            buf[i, 0] += fx
            buf[i, 1] += fy
            buf[i, 2] += fz
        worst[c] = local
    for t in prange(nthread):
        for i in range(t * count // nthread, (t + 1) * count // nthread):
            sx = 0.0
            sy = 0.0
            sz = 0.0
            for a in range(nthread):
                sx += scratch[a, i, 0]
                sy += scratch[a, i, 1]
                sz += scratch[a, i, 2]
            force[i, 0] = sx
            force[i, 1] = sy
            force[i, 2] = sz
    return worst.max()


def contact_forces_reference(position, velocity, diameter, mass, flags, partner, count, pair_i, pair_j,
                             stiffness_ref, diameter_ref, zeta, law, period):
    """NumPy twin of the contact kernels over candidate pairs (pair_i, pair_j) (each pair once).

    Returns (force (count, 3) [N], largest overlap ratio [-]).
    """
    law_force = {c.code: c.force for c in contacts.CONTACT_LAWS.values()}[law]
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


# ---------------------------------------------------------------------------------------------------- walls
@njit(cache=True, inline="always")
def _in_outlet(p, position, outlet_side, side, outlet_height, outlet_transverse, outlet_radius):
    """True if droplet p's centre faces the outlet hole in wall ``side`` (that wall then exerts no force)."""
    if side != outlet_side:
        return False
    transverse = position[p, 1] if side < Y_LOW else position[p, 0]
    dz = position[p, 2] - outlet_height
    dt = transverse - outlet_transverse
    return dz * dz + dt * dt < outlet_radius * outlet_radius


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def wall_forces(position, velocity, diameter, mass, count, box_lower, box_upper, periodic, absorbing_bottom,
                outlet_side, outlet_height, outlet_transverse, outlet_radius, stiffness_ref, diameter_ref, zeta, law,
                nchunk, force):
    """Add the contact force of the box's planes on bounded axes to ``force`` [N]; returns the largest ratio [-].

    The wall law is the pair law with m_eff = m and the stiffness of the droplet's own diameter. With
    ``absorbing_bottom`` the z- plane exerts nothing (the caller removes droplets there). An outlet hole of radius
    ``outlet_radius`` [m] in side wall ``outlet_side`` (0..3: x-, x+, y-, y+; -1: none) centred at height
    ``outlet_height`` [m] and transverse coordinate ``outlet_transverse`` [m] (y on x walls, x on y walls) lets
    droplets whose centre faces it pass.
    """
    worst = np.zeros(nchunk)
    for c in prange(nchunk):
        local = 0.0
        for p in range(c * count // nchunk, (c + 1) * count // nchunk):
            radius = 0.5 * diameter[p]
            for a in range(3):
                if periodic[a]:
                    continue
                x = position[p, a]
                low = radius - (x - box_lower[a])
                high = radius - (box_upper[a] - x)
                if low <= 0.0 and high <= 0.0:
                    continue
                k = contacts.pair_stiffness(stiffness_ref, diameter_ref, diameter[p])
                gamma = contacts.damping_coefficient(k, mass[p], zeta)
                # lower plane: the droplet separates from it moving along +a
                if low > 0.0 and not (a == 2 and absorbing_bottom) and not _in_outlet(
                        p, position, outlet_side, 2 * a, outlet_height, outlet_transverse, outlet_radius):
                    force[p, a] += contacts.normal_force(law, low, velocity[p, a], k, gamma)
                    local = max(local, low / diameter[p])
                if high > 0.0 and not _in_outlet(p, position, outlet_side, 2 * a + 1, outlet_height,
                                                 outlet_transverse, outlet_radius):
                    force[p, a] -= contacts.normal_force(law, high, -velocity[p, a], k, gamma)
                    local = max(local, high / diameter[p])
        worst[c] = local
    return worst.max()


def wall_forces_reference(position, velocity, diameter, mass, count, box_lower, box_upper, periodic,
                          absorbing_bottom, outlet_side, outlet_height, outlet_transverse, outlet_radius,
                          stiffness_ref, diameter_ref, zeta, law):
    """NumPy twin of :func:`wall_forces`: returns (wall force (count, 3) [N], largest overlap ratio [-])."""
    law_force = np.vectorize({c.code: c.force for c in contacts.CONTACT_LAWS.values()}[law].py_func)
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


# ---------------------------------------------------------------------------------------------------- integrator
@njit(cache=True, parallel=True, error_model="numpy")
def drag_factors_into(mass, beta, h, count, drag):
    """drag[p] = (E, phi1, phi2) of :func:`drag_factors` for drag coefficient beta (cap,) [kg/s] and mass [kg].

    Computed when beta, the masses or h change (the coupling's drag update), not every step.
    """
    for p in prange(count):
        e, phi1, phi2 = drag_factors(beta[p] / mass[p], h)
        drag[p, 0] = e
        drag[p, 1] = phi1
        drag[p, 2] = phi2


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def integrate_initial(position, velocity, force, mass, drag, fluid_velocity, body_acceleration, h, count, nchunk,
                      impulse):
    """First half of the exponential velocity-Verlet step: positions to t + h, velocities partly (in place).

    force (cap, 3) [N] at the current positions (contact + wall + other, no drag); drag (cap, 3) the factors of
    :func:`drag_factors_into`; fluid_velocity (cap, 3), or (1, 3) for one velocity everywhere [m/s];
    body_acceleration (3,) [m/s^2]; h [s]. Adds the first part of the drag impulse to ``impulse`` (cap, 3) [N s]
    (an array with no rows: not tracked). Returns the largest displacement of a droplet in this step [m] (the
    neighbour list's cheap validity bound). Next: forces at the new positions, then :func:`integrate_final` with
    the same drag factors and fluid velocity.
    """
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    half_h = 0.5 * h
    worst = np.zeros(nchunk)
    for c in prange(nchunk):
        local = 0.0
        for p in range(c * count // nchunk, (c + 1) * count // nchunk):
            m = mass[p]
            inv_m = 1.0 / m
            e, phi1, phi2 = drag[p, 0], drag[p, 1], drag[p, 2]
            kick = phi1 - phi2 / h
            moved = 0.0
            for a in range(3):
                acc = force[p, a] * inv_m + body_acceleration[a]
                u = fluid_velocity[p * stride, a]
                v = velocity[p, a]
                w = v - u
                step = u * h + w * phi1 + acc * phi2
                position[p, a] += step
                moved += step * step
                v_new = u + w * e + acc * kick
                if track:
                    impulse[p, a] += m * (v_new - v) - m * acc * half_h
                velocity[p, a] = v_new
            local = max(local, moved)
        worst[c] = local
    return math.sqrt(worst.max())


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def integrate_final(velocity, force, mass, drag, body_acceleration, h, count, impulse):
    """Second half of the step: add the end-of-step force's share to the velocities; complete the drag impulse.

    force (cap, 3) [N] at the new positions (and the partly updated velocities, as in velocity Verlet).
    """
    track = impulse.shape[0] > 0
    half_h = 0.5 * h
    for p in prange(count):
        m = mass[p]
        inv_m = 1.0 / m
        kick = drag[p, 2] / h
        for a in range(3):
            acc = force[p, a] * inv_m + body_acceleration[a]
            velocity[p, a] += acc * kick
            if track:
                impulse[p, a] += m * acc * (kick - half_h)


def integrate_reference(position, velocity, force_old, force_new_of, mass, beta, fluid_velocity, body_acceleration,
                        h, count):
    """NumPy twin of one whole step; ``force_new_of(position, velocity)`` gives the force at the new state.

    Returns (position, velocity, impulse) as new arrays; the drag factors use expm1 directly (no series).
    """
    x, v = position[:count].copy(), velocity[:count].copy()
    m = mass[:count, None]
    u = np.broadcast_to(fluid_velocity, (count, 3)) if len(fluid_velocity) == 1 else fluid_velocity[:count]
    rate = beta[:count, None] / m
    with np.errstate(divide="ignore", invalid="ignore"):
        z = rate * h
        phi1 = np.where(z > 0, -np.expm1(-z) / np.where(z > 0, rate, 1.0), h)
        phi2 = np.where(z > 0, (h - phi1) / np.where(z > 0, rate, 1.0), 0.5 * h * h)
    e = np.exp(-z)
    acc_old = force_old[:count] / m + body_acceleration
    v_start = v.copy()
    x = x + u * h + (v - u) * phi1 + acc_old * phi2
    v = u + (v - u) * e + acc_old * (phi1 - phi2 / h)
    acc_new = force_new_of(x, v) / m + body_acceleration
    v = v + acc_new * phi2 / h
    impulse = m * (v - v_start) - m * h * 0.5 * (acc_old + acc_new)
    return x, v, impulse


# ---------------------------------------------------------------------------------------------------- diagnostics
@njit(cache=True)
def kinetic_energy(velocity, mass, count):
    """Translational kinetic energy sum m v^2 / 2 [J]."""
    total = 0.0
    for p in range(count):
        total += 0.5 * mass[p] * (velocity[p, 0] ** 2 + velocity[p, 1] ** 2 + velocity[p, 2] ** 2)
    return total


@njit(cache=True, parallel=True)
def droplet_masses(diameter, density, count, mass):
    """mass[p] = rho pi d^3 / 6 [kg] (written in place)."""
    for p in prange(count):
        mass[p] = density[p] * (math.pi / 6.0) * diameter[p] ** 3


# ---------------------------------------------------------------------------------------------------- orchestration
class DemStepper:
    """Advances the droplets of a :class:`fulldem.droplets.DropletStore` by DEM steps.

    One :meth:`step`: first half of the integrator, periodic wrap, neighbour-list upkeep, contact and wall forces at
    the new positions, second half. The list is checked exactly (:meth:`NeighbourList.needs_rebuild`) only once the
    sum of the steps' largest displacements exceeds skin/2, so most steps skip the check; a rebuild may re-sort the
    droplets by cell (``sort_on_rebuild``) for memory locality.

    Parameters: box ``lower``/``size`` (3,) [m], ``periodic`` (3,) bool, step ``h`` [s], contact ``stiffness_ref``
    [N/m] at ``diameter_ref`` [m], ``restitution`` [-] of droplet pairs and ``wall_restitution`` [-] (default: the
    same), ``skin`` [m], ``body_acceleration`` (3,) [m/s^2], ``law`` (a key of :data:`contacts.CONTACT_LAWS`),
    ``absorbing_bottom``, ``outlet`` (side, height, transverse, radius) or None, ``half_list`` (half list with
    per-thread sums instead of a full list), ``sort_on_rebuild``, ``cell_diameter`` [m] (None: 99th percentile).

    The caller (the coupling) owns the drag: :meth:`set_drag` with beta (cap,) [kg/s] whenever it changes, the fluid
    velocity at the droplets (cap, 3) or (1, 3) [m/s] and the ``impulse`` accumulator (cap, 3) [N s] passed to
    :meth:`step`. After adding or removing droplets call :meth:`droplets_changed` (then :meth:`set_drag`); after
    changing sizes or densities in place, :meth:`sizes_changed` (then :meth:`set_drag`).

    Re-sorting permutes the store and this stepper's arrays, plus the ``fluid_velocity`` (if per droplet) and
    ``impulse`` arrays passed to that step, in place; :meth:`step` then returns the permutation (new p is old
    order[p]; ``ident`` follows the droplets), else None. A caller holding other per-droplet arrays permutes them
    with it, or passes ``sort_on_rebuild=False``.
    """

    def __init__(self, store, lower, size, periodic, h, stiffness_ref, diameter_ref, restitution, skin,
                 body_acceleration, wall_restitution=None, law="hooke", absorbing_bottom=False, outlet=None,
                 half_list=False, sort_on_rebuild=True, cell_diameter=None):
        self.store = store
        self.lower = np.asarray(lower, dtype=float)
        self.size = np.asarray(size, dtype=float)
        self.upper = self.lower + self.size
        self.periodic = np.asarray(periodic, dtype=np.bool_)
        self.h = float(h)
        self.stiffness_ref = float(stiffness_ref)
        self.diameter_ref = float(diameter_ref)
        self.zeta = float(contacts.damping_ratio(restitution))
        self.wall_zeta = self.zeta if wall_restitution is None else float(contacts.damping_ratio(wall_restitution))
        self.law = contacts.contact_law_code(law)
        self.body_acceleration = np.asarray(body_acceleration, dtype=float)
        self.absorbing_bottom = bool(absorbing_bottom)
        side, height, transverse, radius = outlet if outlet is not None else (-1, 0.0, 0.0, 0.0)
        if not -1 <= int(side) <= 3:
            raise ValueError(f"dem: outlet side {side} must be 0..3 (x-, x+, y-, y+) or -1 (none)")
        self.outlet = (int(side), float(height), float(transverse), float(radius))
        self.sort_on_rebuild = bool(sort_on_rebuild)
        self.neighbours = NeighbourList(self.lower, self.size, self.periodic, skin, half=half_list,
                                        cell_diameter=cell_diameter)
        self.mass = np.zeros(0)
        self.force = np.zeros((0, 3))
        self.drag = np.zeros((0, 3))
        self.scratch = np.zeros((numba.get_num_threads(), 0, 3))
        self.max_overlap_ratio = 0.0
        self.steps = 0
        self._travel_bound = 0.0
        self._drag_set = False
        self._ready = False

    # -- set-up
    def droplets_changed(self) -> None:
        """Droplets were added or removed: grow work arrays, re-sort, rebuild the list and the forces."""
        store, n = self.store, self.store.count
        if self.mass.shape[0] < store.capacity:
            self.mass = np.zeros(store.capacity)
            self.force = np.zeros((store.capacity, 3))
            self.drag = np.zeros((store.capacity, 3))
            if self.neighbours.half:
                self.scratch = np.zeros((numba.get_num_threads(), store.capacity, 3))
        if self.sort_on_rebuild and n:
            reorder_store(store, self.neighbours.spatial_order(store.position, store.diameter, n))
        droplet_masses(store.diameter, store.density, n, self.mass)
        self.neighbours.build(store.position, store.diameter, n)
        self._travel_bound = 0.0
        self._drag_set = False
        self.compute_forces()
        self._ready = True

    def sizes_changed(self) -> None:
        """Diameters or densities changed in place: new masses, and an exact list check at the next step."""
        droplet_masses(self.store.diameter, self.store.density, self.store.count, self.mass)
        self._travel_bound = math.inf
        self._drag_set = False

    def set_drag(self, beta) -> None:
        """Drag coefficients beta (cap,) [kg/s] of the droplets (0: no drag), frozen until the next call."""
        drag_factors_into(self.mass, beta, self.h, self.store.count, self.drag)
        self._drag_set = True

    def compute_forces(self) -> float:
        """Contact + wall forces at the current state into ``self.force``; returns the largest overlap ratio."""
        s, nl, n = self.store, self.neighbours, self.store.count
        nchunk = _chunks(n)
        if nl.half:
            worst = contact_forces_half(s.position, s.velocity, s.diameter, self.mass, s.flags, s.partner, n,
                                        nl.start, nl.index, self.stiffness_ref, self.diameter_ref, self.zeta,
                                        self.law, nl.period, nl.inverse_period, nchunk, self.scratch, self.force)
        else:
            worst = contact_forces_full(s.position, s.velocity, s.diameter, self.mass, s.flags, s.partner, n,
                                        nl.start, nl.index, self.stiffness_ref, self.diameter_ref, self.zeta,
                                        self.law, nl.period, nl.inverse_period, nchunk, self.force)
        if not self.periodic.all():
            worst_wall = wall_forces(s.position, s.velocity, s.diameter, self.mass, n, self.lower, self.upper,
                                     self.periodic, self.absorbing_bottom, *self.outlet, self.stiffness_ref,
                                     self.diameter_ref, self.wall_zeta, self.law, nchunk, self.force)
            worst = max(worst, worst_wall)
        self.max_overlap_ratio = worst
        return worst

    # -- one step
    def step(self, fluid_velocity, impulse):
        """Advance by one step h. Returns the droplet permutation if the droplets were re-sorted, else None."""
        if not self._ready:
            self.droplets_changed()
        if not self._drag_set:
            raise RuntimeError("dem: call set_drag(beta) after droplets_changed() / sizes_changed()")
        threads = numba.get_num_threads()
        if self.store.count < PARALLEL_MIN_DROPLETS:
            numba.set_num_threads(1)
        try:
            return self._step(fluid_velocity, impulse)
        finally:
            numba.set_num_threads(threads)

    def _step(self, fluid_velocity, impulse):
        s, n, nl = self.store, self.store.count, self.neighbours
        self._travel_bound += integrate_initial(s.position, s.velocity, self.force, self.mass, self.drag,
                                                fluid_velocity, self.body_acceleration, self.h, n, _chunks(n),
                                                impulse)
        if self.periodic.any():
            wrap_positions(s.position, n, self.lower, nl.period)
        order = None
        # the sum of the steps' largest displacements bounds every droplet's travel since the build
        if self._travel_bound > 0.5 * nl.skin and nl.needs_rebuild(s.position, s.diameter, n):
            if self.sort_on_rebuild:
                order = nl.spatial_order(s.position, s.diameter, n)
                reorder_store(s, order)
                for arr in (self.mass, self.drag, impulse) + ((fluid_velocity,) if len(fluid_velocity) > 1 else ()):
                    if len(arr) >= n:
                        arr[:n] = arr[:n][order]
            nl.build(s.position, s.diameter, n)
            self._travel_bound = 0.0
        self.compute_forces()
        integrate_final(s.velocity, self.force, self.mass, self.drag, self.body_acceleration, self.h, n, impulse)
        self.steps += 1
        return order


NO_IMPULSE = np.zeros((0, 3))


def run_dem(store, steps, h, box_size, stiffness_ref, diameter_ref, restitution, wall_restitution, skin,
            body_acceleration, viscosity, report_steps=(), half_list=False, track_impulse=True):
    """DEM-only run in a closed box with all six walls and linear Stokes drag beta = 3 pi mu d in still fluid.

    Returns a dict: ``loop_seconds`` (the stepping loop only, set-up and first build excluded), ``rebuilds``
    (list builds during the loop), ``kinetic_energy`` {step: J} at ``report_steps``, ``max_overlap_ratio``,
    ``impulse`` (the drag impulses, (n, 3) [N s], if tracked) and the ``stepper``. Used by
    ``benchmarks/bench_dem.py``.
    """
    stepper = DemStepper(store, (0.0, 0.0, 0.0), box_size, (False, False, False), h, stiffness_ref, diameter_ref,
                         restitution, skin, body_acceleration, wall_restitution=wall_restitution,
                         half_list=half_list)
    stepper.droplets_changed()
    n = store.count
    stepper.set_drag(3.0 * math.pi * viscosity * store.diameter)
    still = np.zeros((1, 3))
    impulse = np.zeros((store.capacity, 3)) if track_impulse else NO_IMPULSE
    builds_before = stepper.neighbours.builds
    energies = {}
    loop = 0.0
    report = sorted(set(int(s) for s in report_steps if 0 < int(s) <= steps))
    done = 0
    for target in report + [steps]:
        t0 = time.perf_counter()
        for _ in range(target - done):
            stepper.step(still, impulse)
        loop += time.perf_counter() - t0
        done = max(done, target)
        if target in report:
            energies[target] = kinetic_energy(store.velocity, stepper.mass, n)
    return {"loop_seconds": loop, "rebuilds": stepper.neighbours.builds - builds_before,
            "kinetic_energy": energies, "max_overlap_ratio": stepper.max_overlap_ratio,
            "impulse": impulse[:n] if track_impulse else None, "stepper": stepper}
