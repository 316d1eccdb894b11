"""Droplet-droplet contact loops: the pair force over the neighbour list's rows, the per-entry dashpot
coefficients, and the coalescence submodel's first-contact record.

One contact-row body (:func:`_row`) serves the full list (each droplet sums its own row) and the half list (each pair
once, the reaction subtracted from the partner).


The pointwise laws the loops apply are in :mod:`fulldem.dem.laws`; their NumPy twin is
:func:`fulldem.dem.twins.contact_forces_reference`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..droplets import COALESCING
from . import laws
from .records import FASTMATH, FREE_FLIGHT
from .walls import _wall_force


@njit(cache=True, inline="always")
def _mutual_partner(p, flags, partner):
    """The coalescence partner of p if both are marked and point at each other, else -1 (they do not repel)."""
    if (flags[p] & COALESCING) == 0:  # the common case, decided by the one-byte flags
        return -1
    q = partner[p]
    if q >= 0 and (flags[q] & COALESCING) != 0 and partner[q] == p:
        return q
    return -1


@njit(cache=True, inline="always")
def _separation(position, j, xi, yi, zi, periodic_any, period, inverse_period):
    """x_j - x_i (minimum image on periodic axes) and its squared length [m], [m^2].

    ``periodic_any`` is loop-invariant: a box without periodic axes skips the image arithmetic (10-20 % of a
    contact kernel) at the cost of one well-predicted branch.
    """
    dx = position[j, 0] - xi
    dy = position[j, 1] - yi
    dz = position[j, 2] - zi
    if periodic_any:
        dx -= period[0] * np.rint(dx * inverse_period[0])
        dy -= period[1] * np.rint(dy * inverse_period[1])
        dz -= period[2] * np.rint(dz * inverse_period[2])
    return dx, dy, dz, dx * dx + dy * dy + dz * dz


@njit(cache=True, inline="always")
def _pair_force(position, velocity, diameter, j, xi, yi, zi, ui, vi, wi, di, stiffness_ref, diameter_ref, damping,
                law, periodic_any, period, inverse_period):
    """Force of a touching droplet j on droplet i with dashpot ``damping`` [N s/m]: (fx, fy, fz, overlap, smaller
    diameter, normal relative velocity vn) [N], [m], [m/s] (vn < 0: approaching)."""
    dx, dy, dz, r2 = _separation(position, j, xi, yi, zi, periodic_any, period, inverse_period)
    dj = diameter[j]
    dist = math.sqrt(r2)
    inv = 1.0 / dist
    nx, ny, nz = dx * inv, dy * inv, dz * inv
    vn = (velocity[j, 0] - ui) * nx + (velocity[j, 1] - vi) * ny + (velocity[j, 2] - wi) * nz
    small = min(di, dj)
    overlap = 0.5 * (di + dj) - dist
    k = laws.pair_stiffness(stiffness_ref, diameter_ref, small)
    f = laws.normal_force(law, overlap, vn, k, damping)
    return -f * nx, -f * ny, -f * nz, overlap, small, vn


@njit(cache=True, inline="always")
def _damping_of_pair(diameter, mass, i, j, stiffness_ref, diameter_ref, zeta):
    """Dashpot coefficient 2 zeta sqrt(k_ij m_eff) of pair (i, j) [N s/m] (the same value from either side)."""
    k = laws.pair_stiffness(stiffness_ref, diameter_ref, min(diameter[i], diameter[j]))
    return laws.damping_coefficient(k, laws.effective_mass(mass[i], mass[j]), zeta)


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def pair_damping(start, index, diameter, mass, count, stiffness_ref, diameter_ref, zeta, damping):
    """damping[k] = dashpot coefficient [N s/m] of list entry k (pair i, index[k]), for :class:`Contacts`.

    Computed after each list build and whenever sizes or masses change: it takes a square root and a division out
    of every contact evaluation (a fifth of the dense case's force loop).
    """
    for i in prange(count):
        for k in range(start[i], start[i + 1]):
            damping[k] = _damping_of_pair(diameter, mass, i, index[k], stiffness_ref, diameter_ref, zeta)


@njit(cache=True, inline="always")
def _touching_entries(i, position, diameter, flags, partner, start, index, periodic_any, period, inverse_period,
                      touching):
    """Write into ``touching`` the list entries k of row i whose partner overlaps droplet i (not its mutual
    coalescence partner, nor a droplet in free flight: :data:`FREE_FLIGHT`), without a branch per entry; returns how
    many."""
    xi, yi, zi = position[i, 0], position[i, 1], position[i, 2]
    di = diameter[i]
    skip = _mutual_partner(i, flags, partner)
    found = 0
    for k in range(start[i], start[i + 1]):
        j = index[k]
        r2 = _separation(position, j, xi, yi, zi, periodic_any, period, inverse_period)[3]
        reach = 0.5 * (di + diameter[j])
        touching[found] = k
        found += (r2 < reach * reach) & (r2 > 0.0) & (j != skip) & ((flags[j] & FREE_FLIGHT) == 0)
    return found


@njit(cache=True, inline="always")
def _row(i, position, velocity, diameter, mass, flags, partner, start, index, damping, periodic_any, period,
         inverse_period, stiffness_ref, diameter_ref, law, approach, record_window, walls, wall_lower, wall_upper, outlet_side,
         outlet_height, outlet_transverse, outlet_radius, wall_zeta, touching, force, half, worst):
    """The one contact-row body: force on droplet i from row i of the list and from the walls (if ``walls``):
    (fx, fy, fz, the larger of ``worst`` and the row's largest overlap ratio) [N], [-] (a running maximum: the
    ratio's division happens only for a new maximum). The arguments are the fields of :class:`Bodies`, :class:`Contacts`
    and :class:`Walls`, unpacked by the calling kernel (see the module docstring, *Records*); the walls take the
    pair law. (At most 30 arguments: Python 3.11 passes more as a tuple, which numba cannot inline.)

    The row is first filtered into the entries of touching partners (``touching``: a work row, filled without a
    branch per entry), then only their forces are computed, with the entries' dashpot coefficients. With ``half``
    (a half list: each pair in one row only) each pair force is also subtracted from ``force[j]`` of the partner;
    with a full list ``force`` is not touched (the caller stores or uses the returned force). Contacts are written
    to ``approach`` when it has entries (see :class:`Contacts`): first contacts, whose overlap is less than the
    approach speed times ``record_window`` (the DEM step [s]), or every contact where ``record_window`` < 0
    (``Contacts.every_contact``; one argument for both, since a call of more than 30 arguments compiles to a
    star-args call, which Numba cannot inline).
    """
    xi, yi, zi = position[i, 0], position[i, 1], position[i, 2]
    di = diameter[i]
    found = _touching_entries(i, position, diameter, flags, partner, start, index, periodic_any, period,
                              inverse_period, touching)
    fx = 0.0
    fy = 0.0
    fz = 0.0
    if found:
        record = approach.shape[0] > 0
        ui, vi, wi = velocity[i, 0], velocity[i, 1], velocity[i, 2]
        for q in range(found):
            k = touching[q]
            j = index[k]
            gx, gy, gz, overlap, small, vn = _pair_force(position, velocity, diameter, j, xi, yi, zi, ui, vi, wi,
                                                         di, stiffness_ref, diameter_ref, damping[k], law,
                                                         periodic_any, period, inverse_period)
            fx += gx
            fy += gy
            fz += gz
            if half:
                force[j, 0] -= gx
                force[j, 1] -= gy
                force[j, 2] -= gz
            if overlap > worst * small:  # the largest ratio without a division per contact
                worst = overlap / small
            if record and ((flags[i] | flags[j]) & COALESCING) == 0:
                if record_window < 0.0:  # every contact, at its current approach speed (0 for a pair at rest)
                    approach[k] = max(-vn, 0.0)
                elif overlap < -vn * record_window:  # first contact: one step earlier the pair did not touch
                    approach[k] = -vn
    if walls:
        gx, gy, gz, ratio = _wall_force(i, position, velocity, diameter, mass, wall_lower, wall_upper, outlet_side,
                                        outlet_height, outlet_transverse, outlet_radius, stiffness_ref, diameter_ref,
                                        wall_zeta, law)
        fx += gx
        fy += gy
        fz += gz
        worst = max(worst, ratio)
    return fx, fy, fz, worst


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def contact_forces_full(position, velocity, b, count, c, w, nchunk, candidates, force):
    """Pair forces from a *full* neighbour list, plus the walls': force (overwritten) [N].

    Each droplet sums its own row, so threads never write the same entry. ``b`` :class:`Bodies`, ``c``
    :class:`Contacts`, ``w`` :class:`Walls`; ``candidates`` (nchunk, longest row) int32: work rows. Returns the
    largest overlap ratio (overlap / smaller diameter) [-]. Mutual coalescence partners exert no force on each other.
    """
    diameter, mass, flags, partner = b
    (start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, dem_step,
     every_contact) = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    record_window = -1.0 if every_contact else dem_step  # < 0: every contact recorded (Contacts.every_contact)
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for i in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            fx, fy, fz, local = _row(i, position, velocity, diameter, mass, flags, partner, start, index, damping,
                                     periodic_any, period, inverse_period, stiffness_ref, diameter_ref, law,
                                     approach, record_window, walls, wall_lower, wall_upper, side, height, transverse, radius,
                                     wall_zeta, candidates[ch], force, False, local)
            force[i, 0] = fx
            force[i, 1] = fy
            force[i, 2] = fz
        worst[ch] = local
    return worst.max()


@njit(cache=True, inline="always")
def _slab_rows(lo, hi, position, velocity, diameter, mass, flags, partner, start, index, damping, periodic_any,
               period, inverse_period, stiffness_ref, diameter_ref, law, approach, record_window, walls, wall_lower, wall_upper,
               outlet_side, outlet_height, outlet_transverse, outlet_radius, wall_zeta, touching, force):
    """Add the forces of the half-list rows lo..hi-1 (a slab: each pair to both droplets, and the walls') to
    ``force``; returns the largest overlap ratio. Rows of droplets in free flight (:data:`FREE_FLIGHT`) are
    skipped: they touch nothing (the free-flight selection's guarantee)."""
    local = 0.0
    for i in range(lo, hi):
        if flags[i] & FREE_FLIGHT:
            continue
        fx, fy, fz, local = _row(i, position, velocity, diameter, mass, flags, partner, start, index, damping,
                                 periodic_any, period, inverse_period, stiffness_ref, diameter_ref, law, approach, record_window,
                                 walls, wall_lower, wall_upper, outlet_side, outlet_height, outlet_transverse,
                                 outlet_radius, wall_zeta, touching, force, True, local)
        force[i, 0] += fx
        force[i, 1] += fy
        force[i, 2] += fz
    return local


#: Most slabs of the half-list kernels. More, shorter slabs keep a slab's droplets in cache between its kick pass
#: and its force pass (measured at 163 000 droplets: 16 slabs 4 % faster than 8, 32 no better than 16).
MAX_SLABS = 16


def slab_count(count, longest_jump):
    """Number of slabs for the half-list kernels: even, at most :data:`MAX_SLABS`, each at least twice the longest
    jump between list partners long (so that slabs processed together never write the same droplet); 1 (serial)
    when the droplets are too few. It does not depend on the thread count, so neither do the results."""
    slabs = MAX_SLABS
    while slabs >= 2 and count // slabs < 2 * longest_jump + 1:
        slabs -= 2
    return max(slabs, 1)


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def contact_forces_half(position, velocity, b, count, c, w, nslab, candidates, force):
    """Pair forces from a *half* neighbour list (each pair once), plus the walls': force (overwritten) [N].

    Each pair's force is computed once and added to both droplets. The droplets are cut into ``nslab`` slabs of
    consecutive indices (:func:`slab_count`); the even slabs run in parallel, then the odd ones. A slab writes only
    within the longest jump between partners of its own indices, and slabs two apart are at least twice that jump
    apart, so no two threads write the same droplet, without per-thread copies of the force array. The result does
    not depend on the thread count or timing. ``candidates`` (nslab, longest row) int32: work rows; other arguments
    as :func:`contact_forces_full`. Returns the largest overlap ratio [-].
    """
    for s in prange(nslab):
        for i in range(s * count // nslab, (s + 1) * count // nslab):
            force[i, 0] = 0.0
            force[i, 1] = 0.0
            force[i, 2] = 0.0
    diameter, mass, flags, partner = b
    (start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, dem_step,
     every_contact) = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    record_window = -1.0 if every_contact else dem_step  # < 0: every contact recorded (Contacts.every_contact)
    worst = np.zeros(nslab)
    for phase in range(2):
        for q in prange((nslab - phase + 1) // 2):
            s = 2 * q + phase
            worst[s] = _slab_rows(s * count // nslab, (s + 1) * count // nslab, position, velocity, diameter, mass,
                                  flags, partner, start, index, damping, periodic_any, period, inverse_period,
                                  stiffness_ref, diameter_ref, law, approach, record_window, walls, wall_lower, wall_upper, side,
                                  height, transverse, radius, wall_zeta, candidates[s], force)
    return worst.max()


@njit(cache=True)
def first_contacts(start, index, approach, count, ident, out_a, out_b, out_speed, reset):
    """The first contacts recorded in ``approach`` (see :class:`Contacts`), as droplet idents (a, b) and approach
    speeds [m/s] written to the ``out_`` arrays (at least as long as the list); returns how many. With ``reset`` the
    entries read are set back to -1."""
    found = 0
    for i in range(count):
        for k in range(start[i], start[i + 1]):
            speed = approach[k]
            if speed >= 0.0:
                out_a[found] = ident[i]
                out_b[found] = ident[index[k]]
                out_speed[found] = speed
                found += 1
                if reset:
                    approach[k] = -1.0
    return found
