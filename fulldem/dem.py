"""DEM kernels for matte droplets: contact and wall forces, and an exponential velocity-Verlet integrator.

Kernels are ``@njit(cache=True)`` functions of arrays and small records (SI units); :class:`DemStepper` orchestrates
them. The contact, wall and integrator kernels have plain NumPy twins in :mod:`fulldem.reference` that the tests
compare them with; the DEM-only benchmark's driver is ``benchmarks/bench_dem.py``.

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
it *is* velocity Verlet: symplectic, second order (restitution 0.505 for e = 0.5 at 29 steps per contact). A
one-call step with the force frozen over the whole step -- x + v h + a h^2/2, v + a h in the beta = 0 limit -- gains
energy in every contact step (restitution 0.550 in the same collision); hence the two halves. Consecutive steps fuse
the second half of one with the first half of the next (:func:`integrate_kick_drift`, :func:`step_fused`,
:func:`step_half`).

The drag impulse exchanged over the step, J = beta integral (u - v) dt = m (v_new - v) - m h (a_old + a_new)/2, is
added per droplet to an ``impulse`` array the caller zeroes, so the fluid can receive exactly -J. Over consecutive
steps the momentum share telescopes: :func:`integrate_initial` subtracts m v at the start, the step that ends an
advance adds m v at the end, and the steps between add only the force share -h (F + m a_body), which is zero for a
droplet without contacts when there is no body acceleration (the coupled stepper folds it into the fluid velocity):
its impulse row is then not touched in the sub-steps. The array holds J only once the advance has ended.

Free flight. Over an advance of T = steps h with drag and u frozen, a droplet that touches nothing follows the
exact solution, which the sub-steps reproduce to round-off (the exponential step is exact for drag plus a constant
acceleration a; a = a_body without contacts):

    x(t) = x0 + u t + (v0 - u) phi1(t) + a phi2(t),   v(t) = u + (v0 - u) E(t) + a phi1(t)   (factors at t),

so :class:`DemStepper` (``free_flight=True``, half list, fused path) moves such droplets in one step at the end
(:func:`free_flight_jump`) and the sub-step kernels skip them: their rows, their kicks and drifts, and every pair
with one of them (:data:`FREE_FLIGHT` in the kernels' copy of the flags). Which droplets are free is decided at the
advance's start from positions that are exact there, with budgets checked afterwards:

* each droplet's drift with the fluid, u t, is split off: |x(t) - x0 - u t| <= s = |v0 - u| phi1(T) + |a| phi2(T)
  for a free droplet (phi1, phi2 grow with t); a sub-stepped droplet q gets the budget S_q = s_q + margin d_q
  (:data:`FREE_FLIGHT_MARGIN`) for its path away from drift, sum over steps of |x_step - u h| (``Motion.deviation``,
  accumulated by the kernels; a path bounds the distance at every step);
* p is free if nothing pushes it now, it is not marked for coalescence, every plane is farther than |u_p| T + s_p,
  and for every list partner q the gap is at least |u_p - u_q| T + s_p + S_q: the most the pair's separation can
  shrink while q keeps its budget (S_q >= s_q covers a free q too). Relative drift, not each droplet's own reach:
  droplets carried together by the slag (50 mm/s in the simple case's channel) move 100 um per fluid step but
  barely towards each other (|u_p - u_q| T: 1 um median, 7 um at the 99th percentile);
* pairs off the list had a gap of at least skin - 2 x travel bound at the advance's start, so p is free only if
  |u_p| T + s_p + D fits in that, D the farthest another droplet can go: max_q (|u_q| T + S_q), or skin/2 - travel
  bound if less (the list stays valid within the advance: checked after the steps, with the budgets);
* after the sub-steps, any sub-stepped droplet over its budget (:func:`free_flight_violations`) voids the
  guarantee: the advance is redone from its saved start with every droplet sub-stepped, so a breach costs time,
  never accuracy. So does a neighbour-list check falling inside the advance (a rebuild would renumber the list
  under the free droplets); the stepper checks the list at the start when the last advance's travel says one
  would fall inside. :class:`FreeFlightCounts` counts both.

The free droplets' drag impulse is the sub-steps' telescoped sum, J0 - m v0 - m a T + m v(T); the travel bound of
the list adds their jump. On the simple case at 30 s (146 000 droplets, 36 sub-steps of a 2 ms fluid step) 83 %
of the droplets fly free; the other 17 % are in or near contact, at walls or marked for coalescence.

Records. The kernels take the droplets' ``position`` and ``velocity`` (cap, 3) and the work array ``force`` (cap, 3)
[N] (contact + wall + any other force except drag and a_body) as arrays, and everything else in four records:

* :class:`Bodies` -- per-droplet properties fixed over a step: contact diameter, mass, coalescence flags and partner;
* :class:`Contacts` -- the neighbour list (rows, per-entry dashpot coefficients), the periodic images, the contact
  law, and the first-contact record of the coalescence submodel;
* :class:`Walls` -- the box's planes, the outlet hole and the wall law;
* :class:`Motion` -- the integrator's drag factors, fluid velocity, body acceleration, step and impulse accumulator.

One contact-row body (:func:`_row`) serves the full list (each droplet sums its own row) and the half list (each pair
once, the reaction subtracted from the partner).

Records are unpacked at the top of each kernel, before its parallel loops, and the inline helpers (:func:`_row`,
:func:`_kick_drift`, ...) take plain arrays and numbers. Two reasons, both measured with numba 0.68: writes made
through a record's array field inside a ``prange`` loop are lost (the values vanish, no error; the impulse of the
integrator test was zero), and kernels whose helpers read the records' fields inside the loops ran 20-33 % slower
(bench_dem, 130 000 droplets, one thread: 2.5e7 against 3.7e7 particle-steps/s) for reasons the inlined IR does
not show.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, prange

from . import contacts
from .droplets import COALESCING
from .neighbours import NeighbourList, permute_rows, wrap_positions
from .tuning import PARALLEL_MIN_DROPLETS, THREAD_PROBE_EVERY, THREAD_PROBE_STEPS, ThreadChoice  # noqa: F401

#: LLVM fast-math flags of the hot kernels: fused multiply-add and reciprocal; no reassociation (the pair forces
#: stay exactly antisymmetric, so momentum is conserved to round-off) and no assumption that values are finite.
FASTMATH = {"contract", "arcp"}

#: Bit of the ``flags`` the kernels read (:class:`Bodies`) marking a droplet in free flight for the current advance
#: (see *Free flight* in the module docstring). Set only in the stepper's own copy of the store's flags, never in
#: the store, and far above the store's bits (:data:`fulldem.droplets.COALESCING`, ``MERGED``).
FREE_FLIGHT = 1 << 16

#: Wall codes of the box faces, and of the outlet's side wall: x-, x+, y-, y+, z-, z+.
X_LOW, X_HIGH, Y_LOW, Y_HIGH, Z_LOW, Z_HIGH = range(6)

# 1/(k+2)! for k = 0..15: the series of phi2/h^2 = (z - 1 + e^-z)/z^2 = sum_k (-z)^k/(k+2)!, exact to round-off
# for z <= 0.5 with 16 terms (0.5^16/18! < 1e-20).
_SERIES = np.array([1.0 / math.factorial(k + 2) for k in range(16)])
_SERIES_LIMIT = 0.5


# ---------------------------------------------------------------------------------------------------- records
class Bodies(NamedTuple):
    """Per-droplet properties the kernels read, fixed over a step (arrays of the store's capacity).

    ``diameter`` [m]: the *contact* diameter (the store's ``contact_diameter``: the true diameter, or a coalescing
    droplet's grown one); ``mass`` [kg]: from the true diameter; ``flags`` int32 and ``partner`` int64: coalescence
    marks (mutual partners do not touch).
    """

    diameter: np.ndarray
    mass: np.ndarray
    flags: np.ndarray
    partner: np.ndarray


class Contacts(NamedTuple):
    """The neighbour list and the droplet-droplet contact law, as the contact kernels read them.

    ``start`` (n + 1,) int64 and ``index`` (entries,) int32: the list's rows; ``damping`` (entries,) [N s/m]: each
    entry's dashpot coefficient (:func:`pair_damping`); ``period`` (3,) [m] (0 on bounded axes) and
    ``inverse_period`` (3,) [1/m]; ``periodic_any``: some axis is periodic; ``stiffness_ref`` [N/m] at
    ``diameter_ref`` [m]; ``law``: a code of :data:`fulldem.contacts.CONTACT_LAWS`. ``approach`` (entries,) [m/s]:
    the first-contact record -- a kernel writes the approach speed of each touching pair at its first contact (the
    pair's overlap is less than its approach speed times ``h`` [s], so one step earlier they did not touch) where
    neither droplet is marked for coalescence, into the pair's entry (threads never write the same entry); entries
    not written keep their value (the caller sets -1). An array with no entries: nothing is recorded.
    """

    start: np.ndarray
    index: np.ndarray
    damping: np.ndarray
    period: np.ndarray
    inverse_period: np.ndarray
    periodic_any: bool
    stiffness_ref: float
    diameter_ref: float
    law: int
    approach: np.ndarray
    h: float


class Walls(NamedTuple):
    """The box's planes and the outlet hole, as the wall kernels read them (:func:`walls_record`).

    ``on``: some plane exists; ``lower``/``upper`` (3,) [m]: the planes' positions, -inf/+inf where there is none
    (periodic axis, absorbing bottom); outlet hole of radius ``outlet_radius`` [m] in side wall ``outlet_side``
    (0..3: x-, x+, y-, y+; -1: none) centred at height ``outlet_height`` [m] and transverse coordinate
    ``outlet_transverse`` [m] (y on x walls, x on y walls); the wall law is the pair law (the contact law and
    stiffness of the kernel's :class:`Contacts`) with m_eff = m and damping ratio ``zeta`` [-].
    """

    on: bool
    lower: np.ndarray
    upper: np.ndarray
    outlet_side: int
    outlet_height: float
    outlet_transverse: float
    outlet_radius: float
    zeta: float


#: The ``deviation`` array of a :class:`Motion` that tracks nothing.
NO_DEVIATION = np.zeros(0)


class Motion(NamedTuple):
    """What the integrator needs besides positions, velocities, masses and forces.

    ``drag`` (cap, 3): the factors (E, phi1, phi2) of :func:`drag_factors_into`; ``fluid_velocity`` (cap, 3), or
    (1, 3) for one velocity everywhere [m/s]; ``body_acceleration`` (3,) [m/s^2]; ``h`` [s]; ``impulse`` (cap, 3)
    [N s]: the drag impulse accumulator (an array with no rows: not tracked); ``deviation`` (cap,) [m]: each
    sub-stepped droplet's path away from drift with the fluid, sum over steps of |x_step - u h| (free flight's
    safety check, see *Free flight*; an array with no rows: not tracked).
    """

    drag: np.ndarray
    fluid_velocity: np.ndarray
    body_acceleration: np.ndarray
    h: float
    impulse: np.ndarray
    deviation: np.ndarray = NO_DEVIATION


#: The ``approach`` array of a :class:`Contacts` that records nothing.
NO_RECORD = np.zeros(0)


def contacts_record(neighbours, damping, stiffness_ref, diameter_ref, law, approach=NO_RECORD, h=0.0) -> Contacts:
    """A :class:`Contacts` for a :class:`fulldem.neighbours.NeighbourList`'s current rows."""
    period = neighbours.period
    return Contacts(neighbours.start, neighbours.index, damping, period, neighbours.inverse_period,
                    bool((np.asarray(period) > 0.0).any()), float(stiffness_ref), float(diameter_ref), int(law),
                    approach, float(h))


def walls_record(box_lower, box_upper, periodic, absorbing_bottom, outlet, zeta) -> Walls:
    """A :class:`Walls` for a box [m] with ``periodic`` (3,) bool axes, an optionally absorbing bottom and ``outlet``
    (side, height, transverse, radius) or None."""
    lower, upper = wall_planes(box_lower, box_upper, periodic, absorbing_bottom)
    side, height, transverse, radius = outlet if outlet is not None else (-1, 0.0, 0.0, 0.0)
    return Walls(not bool(np.all(periodic)), lower, upper, int(side), float(height), float(transverse),
                 float(radius), float(zeta))


def wall_planes(box_lower, box_upper, periodic, absorbing_bottom):
    """Plane positions (wall_lower, wall_upper) (3,) [m] for the kernels: +-inf on periodic axes and, with an
    absorbing bottom, for the z- plane."""
    periodic = np.asarray(periodic, dtype=bool)
    lower = np.where(periodic, -np.inf, np.asarray(box_lower, dtype=float))
    upper = np.where(periodic, np.inf, np.asarray(box_upper, dtype=float))
    if absorbing_bottom:
        lower[2] = -np.inf
    return lower, upper


def _chunks(count):
    """Number of work chunks for a parallel loop: a few per thread (load balance), at least one."""
    return max(1, min(count, 8 * numba.get_num_threads()))


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
    k = contacts.pair_stiffness(stiffness_ref, diameter_ref, small)
    f = contacts.normal_force(law, overlap, vn, k, damping)
    return -f * nx, -f * ny, -f * nz, overlap, small, vn


@njit(cache=True, inline="always")
def _damping_of_pair(diameter, mass, i, j, stiffness_ref, diameter_ref, zeta):
    """Dashpot coefficient 2 zeta sqrt(k_ij m_eff) of pair (i, j) [N s/m] (the same value from either side)."""
    k = contacts.pair_stiffness(stiffness_ref, diameter_ref, min(diameter[i], diameter[j]))
    return contacts.damping_coefficient(k, contacts.effective_mass(mass[i], mass[j]), zeta)


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
    k = contacts.pair_stiffness(stiffness_ref, diameter_ref, diameter[p])
    gamma = contacts.damping_coefficient(k, mass[p], zeta)
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
            f += contacts.normal_force(law, low, velocity[p, a], k, gamma)
            worst = max(worst, low / diameter[p])
        if high > 0.0 and not _in_outlet(p, position, 2 * a + 1, outlet_side, outlet_height, outlet_transverse,
                                         outlet_radius):
            f -= contacts.normal_force(law, high, -velocity[p, a], k, gamma)
            worst = max(worst, high / diameter[p])
        if a == 0:
            f0 = f
        elif a == 1:
            f1 = f
        else:
            f2 = f
    return f0, f1, f2, worst


# ---------------------------------------------------------------------------------------------------- contact rows
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
         inverse_period, stiffness_ref, diameter_ref, law, approach, h, walls, wall_lower, wall_upper, outlet_side,
         outlet_height, outlet_transverse, outlet_radius, wall_zeta, touching, force, half, worst):
    """The one contact-row body: force on droplet i from row i of the list and from the walls (if ``walls``):
    (fx, fy, fz, the larger of ``worst`` and the row's largest overlap ratio) [N], [-] (a running maximum: the
    ratio's division happens only for a new maximum). The arguments are the fields of :class:`Bodies`, :class:`Contacts`
    and :class:`Walls`, unpacked by the calling kernel (see the module docstring, *Records*); the walls take the
    pair law. (At most 30 arguments: Python 3.11 passes more as a tuple, which numba cannot inline.)

    The row is first filtered into the entries of touching partners (``touching``: a work row, filled without a
    branch per entry), then only their forces are computed, with the entries' dashpot coefficients. With ``half``
    (a half list: each pair in one row only) each pair force is also subtracted from ``force[j]`` of the partner;
    with a full list ``force`` is not touched (the caller stores or uses the returned force). First contacts are
    written to ``approach`` when it has entries (see :class:`Contacts`).
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
            if record and overlap < -vn * h and ((flags[i] | flags[j]) & COALESCING) == 0:
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
    start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, h = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for i in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            fx, fy, fz, local = _row(i, position, velocity, diameter, mass, flags, partner, start, index, damping,
                                     periodic_any, period, inverse_period, stiffness_ref, diameter_ref, law,
                                     approach, h, walls, wall_lower, wall_upper, side, height, transverse, radius,
                                     wall_zeta, candidates[ch], force, False, local)
            force[i, 0] = fx
            force[i, 1] = fy
            force[i, 2] = fz
        worst[ch] = local
    return worst.max()


@njit(cache=True, inline="always")
def _slab_rows(lo, hi, position, velocity, diameter, mass, flags, partner, start, index, damping, periodic_any,
               period, inverse_period, stiffness_ref, diameter_ref, law, approach, h, walls, wall_lower, wall_upper,
               outlet_side, outlet_height, outlet_transverse, outlet_radius, wall_zeta, touching, force):
    """Add the forces of the half-list rows lo..hi-1 (a slab: each pair to both droplets, and the walls') to
    ``force``; returns the largest overlap ratio. Rows of droplets in free flight (:data:`FREE_FLIGHT`) are
    skipped: they touch nothing (the free-flight selection's guarantee)."""
    local = 0.0
    for i in range(lo, hi):
        if flags[i] & FREE_FLIGHT:
            continue
        fx, fy, fz, local = _row(i, position, velocity, diameter, mass, flags, partner, start, index, damping,
                                 periodic_any, period, inverse_period, stiffness_ref, diameter_ref, law, approach, h,
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
    start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, h = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    worst = np.zeros(nslab)
    for phase in range(2):
        for q in prange((nslab - phase + 1) // 2):
            s = 2 * q + phase
            worst[s] = _slab_rows(s * count // nslab, (s + 1) * count // nslab, position, velocity, diameter, mass,
                                  flags, partner, start, index, damping, periodic_any, period, inverse_period,
                                  stiffness_ref, diameter_ref, law, approach, h, walls, wall_lower, wall_upper, side,
                                  height, transverse, radius, wall_zeta, candidates[s], force)
    return worst.max()


# ---------------------------------------------------------------------------------------------------- walls
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
def integrate_initial(position, velocity, force, mass, m, count, nchunk):
    """First half of the exponential velocity-Verlet step: positions to t + h, velocities partly (in place).

    force (cap, 3) [N] at the current positions (contact + wall + other, no drag); mass (cap,) [kg]; ``m``
    :class:`Motion`. Adds the first part of the drag impulse to ``m.impulse`` (-m v - h (F + m a_body)/2, see the
    module docstring). Returns the largest displacement of a droplet in this step [m] (the neighbour list's cheap
    validity bound). Next: forces at the new positions, then :func:`integrate_final` with the same ``m``.
    """
    drag, fluid_velocity, body_acceleration, h, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    half_h = 0.5 * h
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for p in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            mp = mass[p]
            inv_m = 1.0 / mp
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
                if track:  # the momentum part telescopes: -m v here, +m v at the advance's end
                    impulse[p, a] -= mp * v + mp * acc * half_h
                velocity[p, a] = v_new
            local = max(local, moved)
        worst[ch] = local
    return math.sqrt(worst.max())


@njit(cache=True, inline="always")
def _kick(p, velocity, force, mass, drag, body_acceleration, h, impulse, track, half_h):
    """Second half of droplet p's step: add the end-of-step force's share to its velocity; complete its impulse."""
    mp = mass[p]
    inv_m = 1.0 / mp
    kick_end = drag[p, 2] / h
    for a in range(3):
        acc = force[p, a] * inv_m + body_acceleration[a]
        velocity[p, a] += acc * kick_end
        if track:
            impulse[p, a] += mp * velocity[p, a] - mp * acc * half_h


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def integrate_final(velocity, force, mass, m, count):
    """Second half of the step: add the end-of-step force's share to the velocities; complete the drag impulse.

    force (cap, 3) [N] at the new positions (and the partly updated velocities, as in velocity Verlet).
    """
    drag, _, body_acceleration, h, impulse, _ = m
    track = impulse.shape[0] > 0
    half_h = 0.5 * h
    for p in prange(count):
        _kick(p, velocity, force, mass, drag, body_acceleration, h, impulse, track, half_h)


@njit(cache=True, inline="always")
def _kick_drift(p, position, velocity, fx, fy, fz, mass, drag, fluid_velocity, stride, body_acceleration, h, track,
                impulse, position_out, velocity_out, deviation):
    """Finish droplet p's step with force (fx, fy, fz) and start the next one, writing the new state to the ``_out``
    arrays (which may be the inputs); add |step - u h| to ``deviation[p]`` when it has rows (:class:`Motion`).
    Returns the squared displacement [m^2]."""
    mp = mass[p]
    inv_m = 1.0 / mp
    e, phi1, phi2 = drag[p, 0], drag[p, 1], drag[p, 2]
    kick_end = phi2 / h
    kick_start = phi1 - kick_end
    moved = 0.0
    away = 0.0
    tracking = deviation.shape[0] > 0
    for a in range(3):
        f = fx if a == 0 else (fy if a == 1 else fz)
        acc = f * inv_m + body_acceleration[a]
        v = velocity[p, a] + acc * kick_end
        u = fluid_velocity[p * stride, a]
        w = v - u
        step = u * h + w * phi1 + acc * phi2
        position_out[p, a] = position[p, a] + step
        moved += step * step
        velocity_out[p, a] = u + w * e + acc * kick_start
        if tracking:
            relative = w * phi1 + acc * phi2
            away += relative * relative
    if tracking:
        deviation[p] += math.sqrt(away)
    # drag impulse: only the force's share, -h (F + m a_body) (the momentum share telescopes, see integrate_initial);
    # a droplet free of contacts in a run without body acceleration (the coupled stepper's) has none, and its
    # impulse row is then neither read nor written
    if track and ((fx != 0.0) | (fy != 0.0) | (fz != 0.0) | (body_acceleration[0] != 0.0)
                  | (body_acceleration[1] != 0.0) | (body_acceleration[2] != 0.0)):
        impulse[p, 0] -= h * (fx + mp * body_acceleration[0])
        impulse[p, 1] -= h * (fy + mp * body_acceleration[1])
        impulse[p, 2] -= h * (fz + mp * body_acceleration[2])
    return moved


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def integrate_kick_drift(position, velocity, force, mass, m, count, nchunk):
    """:func:`integrate_final` of one step then :func:`integrate_initial` of the next, in one pass over the droplets.

    Both use the same force (computed at the positions between the two steps), so this is exactly the two calls in
    a row, with one memory pass and one parallel launch instead of two. Returns the step's largest displacement [m].
    """
    drag, fluid_velocity, body_acceleration, h, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for p in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            moved = _kick_drift(p, position, velocity, force[p, 0], force[p, 1], force[p, 2], mass, drag,
                                fluid_velocity, stride, body_acceleration, h, track, impulse, position, velocity,
                                deviation)
            local = max(local, moved)
        worst[ch] = local
    return math.sqrt(worst.max())


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def step_fused(position, velocity, position_next, velocity_next, b, count, c, w, m, nchunk, candidates):
    """One whole step in one pass: forces at (position, velocity) as :func:`contact_forces_full`, then
    :func:`integrate_kick_drift`, the new state written to the *other* arrays (position_next, velocity_next).

    Reading one copy of the state and writing the other removes the race between a droplet's update and its
    neighbours' force computation, so the force array and a second pass over the droplets are not needed. Returns
    (largest overlap ratio [-], largest displacement [m]).
    """
    diameter, mass, flags, partner = b
    start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, _ = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    drag, fluid_velocity, body_acceleration, h, impulse, deviation = m  # (the contact record's h: the same step)
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    worst = np.zeros(nchunk)
    travel = np.zeros(nchunk)
    no_force = np.zeros((0, 3))
    for ch in prange(nchunk):
        local = 0.0
        moved = 0.0
        for i in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            fx, fy, fz, local = _row(i, position, velocity, diameter, mass, flags, partner, start, index, damping,
                                     periodic_any, period, inverse_period, stiffness_ref, diameter_ref, law,
                                     approach, h, walls, wall_lower, wall_upper, side, height, transverse, radius,
                                     wall_zeta, candidates[ch], no_force, False, local)
            moved = max(moved, _kick_drift(i, position, velocity, fx, fy, fz, mass, drag, fluid_velocity, stride,
                                           body_acceleration, h, track, impulse, position_next, velocity_next,
                                           deviation))
        worst[ch] = local
        travel[ch] = moved
    return worst.max(), math.sqrt(travel.max())


@njit(cache=True, inline="always")
def _slab_kick(s, nslab, count, position, velocity, force, mass, flags, drag, fluid_velocity, stride,
               body_acceleration, h, track, impulse, deviation, drift):
    """Finish the step of slab s's droplets with their force; with ``drift`` also start the next step and zero the
    force for the next accumulation. Droplets in free flight (``flags``) are left alone. Returns the largest
    squared displacement [m^2]."""
    moved = 0.0
    half_h = 0.5 * h
    for p in range(s * count // nslab, (s + 1) * count // nslab):
        if flags[p] & FREE_FLIGHT:
            continue
        if drift:
            fx, fy, fz = force[p, 0], force[p, 1], force[p, 2]
            moved = max(moved, _kick_drift(p, position, velocity, fx, fy, fz, mass, drag, fluid_velocity, stride,
                                           body_acceleration, h, track, impulse, position, velocity, deviation))
            if (fx != 0.0) | (fy != 0.0) | (fz != 0.0):  # most rows are zero already: no write, no dirty line
                force[p, 0] = 0.0
                force[p, 1] = 0.0
                force[p, 2] = 0.0
        else:
            _kick(p, velocity, force, mass, drag, body_acceleration, h, impulse, track, half_h)
    return moved


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def step_half(position, velocity, b, count, c, w, m, nslab, candidates, force, even_pending, last):
    """One step of the half-list scheme in two parallel phases (three for the ``last`` step).

    Phase A, even slabs: (if ``even_pending``) finish their previous step and start this one
    (:func:`integrate_kick_drift`), then add their rows' forces. Phase B, odd slabs: add their rows' forces, which
    completes their droplets' forces (no other slab running later writes them), then kick-drift them. The even
    slabs' droplets are left pending (their forces are complete only after phase B); the next call finishes them
    first. ``force`` must be zero on entry except for pending even droplets, and is left so. With ``last`` both
    parities only finish the step (no drift) and ``force`` keeps the forces at the final positions. Same
    partitioning rules as :func:`contact_forces_half`. Returns (largest overlap ratio [-], largest displacement [m]).
    """
    diameter, mass, flags, partner = b
    start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, _ = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    drag, fluid_velocity, body_acceleration, h, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    worst = np.zeros(nslab)
    travel = np.zeros(nslab)
    for q in prange((nslab + 1) // 2):
        s = 2 * q
        if even_pending:
            travel[s] = _slab_kick(s, nslab, count, position, velocity, force, mass, flags, drag, fluid_velocity,
                                   stride, body_acceleration, h, track, impulse, deviation, True)
        worst[s] = _slab_rows(s * count // nslab, (s + 1) * count // nslab, position, velocity, diameter, mass, flags,
                              partner, start, index, damping, periodic_any, period, inverse_period, stiffness_ref,
                              diameter_ref, law, approach, h, walls, wall_lower, wall_upper, side, height,
                              transverse, radius, wall_zeta, candidates[s], force)
    for q in prange(nslab // 2):
        s = 2 * q + 1
        worst[s] = _slab_rows(s * count // nslab, (s + 1) * count // nslab, position, velocity, diameter, mass, flags,
                              partner, start, index, damping, periodic_any, period, inverse_period, stiffness_ref,
                              diameter_ref, law, approach, h, walls, wall_lower, wall_upper, side, height,
                              transverse, radius, wall_zeta, candidates[s], force)
        travel[s] = _slab_kick(s, nslab, count, position, velocity, force, mass, flags, drag, fluid_velocity, stride,
                               body_acceleration, h, track, impulse, deviation, not last)
    if last:
        for q in prange((nslab + 1) // 2):
            _slab_kick(2 * q, nslab, count, position, velocity, force, mass, flags, drag, fluid_velocity, stride,
                       body_acceleration, h, track, impulse, deviation, False)
    return worst.max(), math.sqrt(travel.max())


@njit(cache=True)
def step_half_many(steps, travel_bound, half_skin, lower, position, velocity, b, count, c, w, m, nslab, candidates,
                   force, even_pending):
    """Up to ``steps`` consecutive :func:`step_half` calls in one compiled loop (no Python between steps: at ten
    thousand droplets a step takes about 0.2 ms, and a Python call a good part of that).

    Before each step the periodic positions are wrapped; the loop stops before a step when ``travel_bound`` (the
    sum of the steps' largest displacements since the list was built) exceeds ``half_skin``, since the neighbour
    list must then be checked in Python. The last of ``steps`` ends complete (``last``). Returns (steps done,
    largest overlap ratio over them, last step's overlap ratio, travel bound, even slabs pending).
    """
    pending = even_pending
    peak = 0.0
    worst = 0.0
    for k in range(steps):
        if c.periodic_any:
            wrap_positions(position, count, lower, c.period)
        if travel_bound > half_skin:
            return k, peak, worst, travel_bound, pending
        last = k + 1 == steps
        worst, moved = step_half(position, velocity, b, count, c, w, m, nslab, candidates, force, pending, last)
        peak = max(peak, worst)
        travel_bound += moved
        pending = not last
    return steps, peak, worst, travel_bound, pending


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def finish_even_slabs(position, velocity, force, mass, flags, m, count, nslab):
    """Kick-drift the pending even slabs of :func:`step_half` (all droplets then at the same time level, forces
    zero), e.g. before a neighbour-list rebuild; ``flags`` those of the :class:`Bodies` of the steps. Returns the
    largest displacement [m]."""
    drag, fluid_velocity, body_acceleration, h, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    travel = np.zeros(nslab)
    for q in prange((nslab + 1) // 2):
        travel[2 * q] = _slab_kick(2 * q, nslab, count, position, velocity, force, mass, flags, drag,
                                   fluid_velocity, stride, body_acceleration, h, track, impulse, deviation, True)
    return math.sqrt(travel.max())


# ---------------------------------------------------------------------------------------------------- free flight
@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def free_flight_candidates(position, velocity, force, b, count, w, m, rate, duration, margin, nchunk, free_flags,
                           transient, reach):
    """First pass of the free-flight selection (see *Free flight* in the module docstring), per droplet p:

    * ``transient[p]`` = s_p = |v - u| phi1(T) + |a| phi2(T) [m], the bound on |x(t) - x0 - u t| over t <= T =
      ``duration`` [s] if nothing touches p (a = force/m + a_body, the factors of :func:`drag_factors` for drag rate
      ``rate[p]`` = beta/m [1/s] and T);
    * ``reach[p]`` = S_p = s_p + ``margin`` d_p [m]: the deviation allowed to p if it is sub-stepped;
    * ``m.deviation[p]`` = |x(h) - x0 - u h| of its first step (what :func:`integrate_initial` will move it);
    * ``free_flags[p]``: the store's ``b.flags[p]`` plus :data:`FREE_FLIGHT` if p is a candidate: no contact or
      wall force now, not marked for coalescence, and each plane (:class:`Walls` w) farther than |u| T + s_p.

    Returns max_p (|u_p| T + S_p) [m], the farthest any droplet may move if its budget holds.
    """
    diameter, mass, flags, partner = b
    _, wall_lower, wall_upper, _, _, _, _, _ = w
    drag, fluid_velocity, body_acceleration, h, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    farthest = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for p in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            _, phi1_t, phi2_t = drag_factors(rate[p], duration)
            phi1, phi2 = drag[p, 1], drag[p, 2]
            inv_m = 1.0 / mass[p]
            drift2 = 0.0
            relative2 = 0.0
            acc2 = 0.0
            first2 = 0.0
            pushed = False
            for a in range(3):
                u = fluid_velocity[p * stride, a]
                rel = velocity[p, a] - u
                acc = force[p, a] * inv_m + body_acceleration[a]
                first = rel * phi1 + acc * phi2
                drift2 += u * u
                relative2 += rel * rel
                acc2 += acc * acc
                first2 += first * first
                pushed |= force[p, a] != 0.0
            own = math.sqrt(relative2) * phi1_t + math.sqrt(acc2) * phi2_t
            transient[p] = own
            reach[p] = own + margin * diameter[p]
            deviation[p] = math.sqrt(first2)
            travel = math.sqrt(drift2) * duration + own
            radius = 0.5 * diameter[p]
            clear = (not pushed) & ((flags[p] & COALESCING) == 0)
            for a in range(3):
                clear &= (position[p, a] - wall_lower[a] - radius >= travel) & (
                    wall_upper[a] - position[p, a] - radius >= travel)
            free_flags[p] = (flags[p] | FREE_FLIGHT) if clear else (flags[p] & ~FREE_FLIGHT)
            local = max(local, math.sqrt(drift2) * duration + reach[p])
        farthest[ch] = local
    return farthest.max()


@njit(cache=True, inline="always")
def _drift_gap(i, j, fluid_velocity, stride, duration):
    """|u_i - u_j| T [m]: how far the drift with the fluid moves droplets i and j apart or together over T [s]."""
    d2 = 0.0
    for a in range(3):
        du = fluid_velocity[i * stride, a] - fluid_velocity[j * stride, a]
        d2 += du * du
    return math.sqrt(d2) * duration


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def free_flight_pairs(position, diameter, count, c, fluid_velocity, duration, farthest, unlisted, nslab, free_flags,
                      transient, reach):
    """Second pass of the free-flight selection: clear :data:`FREE_FLIGHT` in ``free_flags`` of every candidate p

    * that some droplet off the list could reach: |u_p| T + s_p + ``farthest`` > ``unlisted`` [m] (the smallest
      gap a pair off the list can have, skin - 2 x travel bound), ``farthest`` from :func:`free_flight_candidates`;
    * with a list partner q closer than the most their gap can close: gap_pq < |u_p - u_q| T + s_p + S_q [m]
      (``transient`` s, ``reach`` S; S_q >= s_q bounds q whether q flies free or is sub-stepped within budget).

    A *half* list (:class:`Contacts` c), each pair visited once, both ends cleared from its row: slabs as in
    :func:`contact_forces_half` (a pair writes only within the longest jump of its row's slab). Returns the number
    of droplets left free.
    """
    start, index, _, period, inverse_period, periodic_any, _, _, _, _, _ = c
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    for phase in range(2):
        for q in prange((nslab - phase + 1) // 2):
            s = 2 * q + phase
            for i in range(s * count // nslab, (s + 1) * count // nslab):
                drift2 = 0.0
                for a in range(3):
                    drift2 += fluid_velocity[i * stride, a] ** 2
                if math.sqrt(drift2) * duration + transient[i] + farthest > unlisted:
                    free_flags[i] &= ~FREE_FLIGHT
                xi, yi, zi = position[i, 0], position[i, 1], position[i, 2]
                for k in range(start[i], start[i + 1]):
                    j = index[k]
                    r2 = _separation(position, j, xi, yi, zi, periodic_any, period, inverse_period)[3]
                    gap = math.sqrt(r2) - 0.5 * (diameter[i] + diameter[j])
                    closing = _drift_gap(i, j, fluid_velocity, stride, duration)
                    if gap < closing + transient[i] + reach[j]:
                        free_flags[i] &= ~FREE_FLIGHT
                    if gap < closing + transient[j] + reach[i]:
                        free_flags[j] &= ~FREE_FLIGHT
    free = 0
    for p in prange(count):
        free += (free_flags[p] & FREE_FLIGHT) != 0
    return free


@njit(cache=True, parallel=True)
def free_flight_violations(free_flags, deviation, reach, count):
    """Number of sub-stepped droplets (no :data:`FREE_FLIGHT` bit) whose ``deviation`` [m] exceeds their ``reach``
    [m]: the free-flight guarantee does not hold for the advance if this is not 0."""
    over = 0
    for p in prange(count):
        over += ((free_flags[p] & FREE_FLIGHT) == 0) & (deviation[p] > reach[p])
    return over


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def free_flight_jump(position, velocity, free_flags, mass, rate, m, duration, start_position, start_velocity,
                     start_impulse, count, nchunk):
    """Advance the droplets in free flight (``free_flags``) by ``duration`` T [s] in one exact step from their state
    at the advance's start (``start_`` arrays), as the sub-steps would (to round-off):

        x = x0 + u T + (v0 - u) phi1 + a phi2,   v = u + (v0 - u) E + a phi1   (factors of :func:`drag_factors`
        for ``rate`` = beta/m [1/s] and T, a = a_body: no force touches them),

    and their drag impulse (``m.impulse``, if tracked) = J0 - m v0 - m a T + m v, the sub-steps' telescoped sum
    (:func:`integrate_initial`). Returns the largest displacement [m].
    """
    _, fluid_velocity, body_acceleration, _, impulse, _ = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for p in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            if (free_flags[p] & FREE_FLIGHT) == 0:
                continue
            e, phi1, phi2 = drag_factors(rate[p], duration)
            mp = mass[p]
            moved = 0.0
            for a in range(3):
                u = fluid_velocity[p * stride, a]
                acc = body_acceleration[a]
                v0 = start_velocity[p, a]
                rel = v0 - u
                step = u * duration + rel * phi1 + acc * phi2
                position[p, a] = start_position[p, a] + step
                moved += step * step
                v = u + rel * e + acc * phi1
                velocity[p, a] = v
                if track:
                    impulse[p, a] = start_impulse[p, a] - mp * v0 - mp * acc * duration + mp * v
            local = max(local, moved)
        worst[ch] = local
    return math.sqrt(worst.max())


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


# ---------------------------------------------------------------------------------------------------- diagnostics
@njit(cache=True)
def kinetic_energy(velocity, mass, count):
    """Translational kinetic energy sum m v^2 / 2 [J]."""
    total = 0.0
    for p in range(count):
        total += 0.5 * mass[p] * (velocity[p, 0] ** 2 + velocity[p, 1] ** 2 + velocity[p, 2] ** 2)
    return total


@njit(cache=True, parallel=True)
def max_speed(velocity, count):
    """Largest |v| of the first ``count`` droplets [m/s] (0 for none)."""
    worst = 0.0
    for p in prange(count):  # a max reduction
        worst = max(worst, velocity[p, 0] ** 2 + velocity[p, 1] ** 2 + velocity[p, 2] ** 2)
    return math.sqrt(worst)


@njit(cache=True, parallel=True)
def droplet_masses(diameter, density, count, mass):
    """mass[p] = rho pi d^3 / 6 [kg] (written in place)."""
    for p in prange(count):
        mass[p] = density[p] * (math.pi / 6.0) * diameter[p] ** 3


# ---------------------------------------------------------------------------------------------------- orchestration
#: The ``impulse`` argument that tracks no drag impulse.
NO_IMPULSE = np.zeros((0, 3))

#: Free flight: the deviation from drift with the fluid allowed to a sub-stepped droplet over an advance, beyond its
#: own free-flight transient, in its contact diameters (S = s + FREE_FLIGHT_MARGIN d; see *Free flight*). Measured on
#: the simple case at 30 s (146 000 droplets, T = 2 ms): the largest such deviation was 0.024-0.041 d (collisions
#: and overlapping pairs pushed apart), 99.9 % of sub-stepped droplets stayed under 0.017 d; the free fraction
#: falls slowly with the margin (0.87 at 0.01 d, 0.83 at 0.05 d, 0.76 at 0.1 d) and a breach costs a redone
#: advance, so the margin is generous.
FREE_FLIGHT_MARGIN = 0.05

#: Free flight is used for an advance only if at least this fraction of the droplets qualifies (below it, the
#: selection's two passes and the saved state cost about what they save).
FREE_FLIGHT_MIN_FRACTION = 0.05


class FreeFlightCounts:
    """What free flight did since the stepper was made (:attr:`DemStepper.free_flight_counts`).

    ``advances``: advances that took the free-flight path; ``droplets``: droplet-advances in free flight (summed
    over those); ``breaches``: advances redone because a sub-stepped droplet left its budget (each breach: the
    advance is redone from its start without free flight, so the result is that of the sub-steps);
    ``breach_droplets``: how many droplets were over budget, summed; ``list_checks``: advances redone because the
    neighbour list had to be checked mid-advance (a rebuild would renumber the droplets in free flight);
    ``declined``: advances with too few free droplets (:data:`FREE_FLIGHT_MIN_FRACTION`), sub-stepped as before.
    """

    def __init__(self):
        self.advances = 0
        self.droplets = 0
        self.breaches = 0
        self.breach_droplets = 0
        self.list_checks = 0
        self.declined = 0

    def as_dict(self) -> dict:
        return dict(vars(self))


class DemStepper:
    """Advances the droplets of a :class:`fulldem.droplets.DropletStore` by DEM steps.

    One step: first half of the integrator, periodic wrap, neighbour-list upkeep, contact and wall forces at the new
    positions, second half (:meth:`step` for one, :meth:`advance` for several in a row, faster). The list is checked
    exactly (:meth:`NeighbourList.needs_rebuild`) only once the sum of the steps' largest displacements exceeds
    skin/2, so most steps skip the check; a rebuild may re-sort the droplets by cell (``sort_on_rebuild``) for memory
    locality. Threads are chosen by :class:`fulldem.tuning.ThreadChoice` (one below a few thousand droplets).

    Parameters: box ``lower``/``size`` (3,) [m], ``periodic`` (3,) bool, step ``h`` [s], contact ``stiffness_ref``
    [N/m] at ``diameter_ref`` [m], ``restitution`` [-] of droplet pairs and ``wall_restitution`` [-] (default: the
    same), ``skin`` [m], ``body_acceleration`` (3,) [m/s^2], ``law`` (a key of :data:`contacts.CONTACT_LAWS`),
    ``absorbing_bottom``, ``outlet`` (side, height, transverse, radius) or None, ``half_list`` (default; False: a
    full list, each pair computed from both sides but a whole step in one pass -- measured slower on the benchmark,
    1.5x single-threaded), ``sort_on_rebuild``, ``cell_diameter`` [m] (None: 99th percentile), ``threads`` (None:
    chosen by timing, see :meth:`advance`).

    The caller (the coupling) owns the drag: :meth:`set_drag` with beta (cap,) [kg/s] whenever it changes, the fluid
    velocity at the droplets (cap, 3) or (1, 3) [m/s] and the ``impulse`` accumulator (cap, 3) [N s] passed to
    :meth:`step`. After adding or removing droplets call :meth:`droplets_changed` (then :meth:`set_drag`); after
    changing sizes or densities in place, :meth:`sizes_changed` (then :meth:`set_drag`).

    Re-sorting permutes the store and this stepper's arrays, plus the ``fluid_velocity`` (if per droplet) and
    ``impulse`` arrays passed to that step, in place; :meth:`step` / :meth:`advance` then return the permutation
    (new p is old order[p]; ``ident`` follows the droplets), else None. A caller holding other per-droplet arrays
    permutes them with it, or passes ``sort_on_rebuild=False``.
    """

    def __init__(self, store, lower, size, periodic, h, stiffness_ref, diameter_ref, restitution, skin,
                 body_acceleration, wall_restitution=None, law="hooke", absorbing_bottom=False, outlet=None,
                 half_list=True, sort_on_rebuild=True, cell_diameter=None, threads=None, record_first_contacts=False,
                 free_flight=True):
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
        self.walls = walls_record(self.lower, self.upper, self.periodic, self.absorbing_bottom, self.outlet,
                                  self.wall_zeta)
        self.record_first_contacts = bool(record_first_contacts)
        self.approach = np.zeros(0)  # the list entries' first-contact record (Contacts.approach), when recording
        self._first_contacts = []  # (ident a, ident b, approach speed) arrays read from the record since the last take
        self.sort_on_rebuild = bool(sort_on_rebuild)
        self.thread_choice = ThreadChoice(threads)
        self.neighbours = NeighbourList(self.lower, self.size, self.periodic, skin, half=half_list,
                                        cell_diameter=cell_diameter)
        self.mass = np.zeros(0)
        self.force = np.zeros((0, 3))
        self.drag = np.zeros((0, 3))
        self.candidates = np.zeros((0, 0), dtype=np.int32)
        self.damping = np.zeros(0)
        self._spare_position = np.zeros((0, 3))
        self._spare_velocity = np.zeros((0, 3))
        self.max_overlap_ratio = 0.0
        self.peak_overlap_ratio = 0.0
        self.steps = 0
        self._travel_bound = 0.0
        self._drag_set = False
        self._seen_version = -1  # the store's version when the list and work arrays were last set up
        self._seen_sizes = -1  # the store's size_version when masses and the list's damping were last set
        # free flight (see the module docstring): work arrays sized to the store's capacity on first use
        self.free_flight = bool(free_flight)
        self.free_flight_counts = FreeFlightCounts()
        self.last_free_fraction = 0.0  # fraction of the droplets in free flight in the last advance
        self.rate = np.zeros(0)  # beta/m [1/s] of set_drag
        self._free_flags = np.zeros(0, dtype=np.int32)  # the store's flags plus FREE_FLIGHT, for the kernels
        self._transient = np.zeros(0)
        self._reach = np.zeros(0)
        self._deviation = np.zeros(0)
        self._start = {}  # the state at the start of a free-flight advance, to redo it (position, velocity, ...)
        self._advance_travel = 0.0  # the sum of the largest step displacements over the last half-list advance [m]
        self._advance_steps = 0  # ... and its steps

    # -- set-up
    @property
    def ready(self) -> bool:
        """Whether the work arrays and the neighbour list match the store: False before the first
        :meth:`droplets_changed` and whenever the store's version moved since (droplets added, removed, reordered)."""
        return self._seen_version == self.store.version

    def invalidate(self) -> None:
        """Set up anew (:meth:`droplets_changed`) at the next step even if the store did not change."""
        self._seen_version = -1

    def droplets_changed(self) -> None:
        """Droplets were added or removed: grow work arrays, re-sort, rebuild the list and the forces."""
        store, n = self.store, self.store.count
        if self.mass.shape[0] < store.capacity:
            self.mass = np.zeros(store.capacity)
            self.force = np.zeros((store.capacity, 3))
            self.drag = np.zeros((store.capacity, 3))
        if self.sort_on_rebuild and n:
            store.reorder(self.neighbours.spatial_order(store.position, store.contact_diameter, n))
        droplet_masses(store.diameter, store.density, n, self.mass)
        self._build_list()
        self._drag_set = False
        self.compute_forces()
        self._seen_version = store.version
        self._seen_sizes = store.size_version

    def list_state(self) -> dict:
        """The neighbour list and the travel bound since its build, for a checkpoint (see :meth:`restore_list`)."""
        state = self.neighbours.state()
        state["travel_bound"] = np.array([self._travel_bound])
        # what free flight expects of the next advance (it decides whether the list is checked at its start)
        state["advance_travel"] = np.array([self._advance_travel, self._advance_steps])
        return state

    def restore_list(self, state: dict) -> None:
        """Set up for the store's droplets with the list of :meth:`list_state` instead of a new build: the next
        steps then see the same rows, hence sum the contact forces in the same order, as the run that saved it."""
        store = self.store
        if self.mass.shape[0] < store.capacity:
            self.mass = np.zeros(store.capacity)
            self.force = np.zeros((store.capacity, 3))
            self.drag = np.zeros((store.capacity, 3))
        droplet_masses(store.diameter, store.density, store.count, self.mass)
        self.neighbours.restore(state)
        self._reset_record()
        self._travel_bound = float(state["travel_bound"][0])
        travel, steps = state.get("advance_travel", (0.0, 0))  # (absent from checkpoints before free flight)
        self._advance_travel, self._advance_steps = float(travel), int(steps)
        self._refresh_damping()
        self._drag_set = False
        self.compute_forces()
        self._seen_version = store.version
        self._seen_sizes = store.size_version

    @property
    def sizes_stale(self) -> bool:
        """Whether the store's sizes or densities changed in place since the masses were set (then call
        :meth:`sizes_changed`)."""
        return self._seen_sizes != self.store.size_version

    def sizes_changed(self) -> None:
        """Diameters, contact diameters or densities changed in place: new masses and dashpots, and an exact list
        check now (a grown droplet may reach beyond the list's skin); then call :meth:`set_drag`."""
        s, nl = self.store, self.neighbours
        droplet_masses(s.diameter, s.density, s.count, self.mass)
        if nl.builds and nl.needs_rebuild(s.position, s.contact_diameter, s.count):
            self._build_list()
        else:
            self._refresh_damping()
            self._travel_bound = nl.last_travel if nl.builds else math.inf
        self._drag_set = False
        self._seen_sizes = s.size_version

    def _build_list(self) -> None:
        s = self.store
        self.neighbours.build(s.position, s.contact_diameter, s.count)
        self._travel_bound = 0.0
        self._refresh_damping()
        self._reset_record()

    # -- the first-contact record (coalescence)
    def _reset_record(self) -> None:
        """Size the first-contact record to the list and clear it (-1: no first contact). The record is read (by
        ident) at the end of every :meth:`advance` and before the advance's own list rebuilds, while the store still
        matches the list; what a lone :meth:`compute_forces` records before the store changes is dropped here."""
        if not self.record_first_contacts:
            return
        entries = self.neighbours.index.shape[0]
        if self.approach.shape[0] < entries:
            self.approach = np.zeros(entries)
        self.approach[:] = -1.0

    def _read_first_contacts(self) -> None:
        """Move the record's first contacts into :meth:`take_first_contacts`'s list (by ident, so they survive the
        list rebuilds and re-sorts that change entries and indices) and clear it."""
        nl = self.neighbours
        if not self.record_first_contacts or nl.builds == 0 or self.approach.shape[0] == 0:
            return
        entries = int(nl.start[nl.count]) if nl.count else 0
        a, b = np.empty(entries, dtype=np.int64), np.empty(entries, dtype=np.int64)
        speed = np.empty(entries)
        found = first_contacts(nl.start, nl.index, self.approach, nl.count, self.store.ident, a, b, speed, True)
        if found:
            self._first_contacts.append((a[:found], b[:found], speed[:found]))

    def take_first_contacts(self):
        """The first contacts (touching pairs, neither marked for coalescence, that did not touch a step earlier)
        since the last call: idents (a, b) int64 and approach speeds [m/s], in the order they were read (a pair may
        appear more than once). Only with ``record_first_contacts``."""
        found, self._first_contacts = self._first_contacts, []
        if not found:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)
        return tuple(np.concatenate(parts) for parts in zip(*found))

    def _refresh_damping(self) -> None:
        """Per-entry dashpot coefficients of the list, from the current sizes and masses."""
        nl, s = self.neighbours, self.store
        if self.damping.shape[0] < nl.index.shape[0]:
            self.damping = np.zeros(nl.index.shape[0])
        pair_damping(nl.start, nl.index, s.contact_diameter, self.mass, nl.count, self.stiffness_ref, self.diameter_ref,
                     self.zeta, self.damping)

    def set_drag(self, beta) -> None:
        """Drag coefficients beta (cap,) [kg/s] of the droplets (0: no drag), frozen until the next call."""
        n = self.store.count
        drag_factors_into(self.mass, beta, self.h, n, self.drag)
        if self.rate.shape[0] < self.mass.shape[0]:
            self.rate = np.zeros(self.mass.shape[0])
        np.divide(beta[:n], self.mass[:n], out=self.rate[:n])
        self._drag_set = True

    def compute_forces(self) -> float:
        """Contact + wall forces at the current state into ``self.force``; returns the largest overlap ratio."""
        s, nl, n = self.store, self.neighbours, self.store.count
        nchunk = _chunks(n)
        if nl.half:
            nslab = slab_count(n, nl.longest_jump)
            self._ensure_candidates(nslab)
            worst = contact_forces_half(s.position, s.velocity, self._bodies(), n, self._contacts(), self.walls,
                                        nslab, self.candidates, self.force)
        else:
            self._ensure_candidates(nchunk)
            worst = contact_forces_full(s.position, s.velocity, self._bodies(), n, self._contacts(), self.walls,
                                        nchunk, self.candidates, self.force)
        self.max_overlap_ratio = worst
        self.peak_overlap_ratio = max(self.peak_overlap_ratio, worst)
        return worst

    # -- stepping
    def step(self, fluid_velocity, impulse):
        """Advance by one step h; see :meth:`advance`."""
        return self.advance(1, fluid_velocity, impulse)

    def advance(self, steps, fluid_velocity, impulse):
        """Advance by ``steps`` steps h with the drag and fluid velocity frozen (one fluid step's DEM sub-steps).

        Consecutive steps run fused: a half-list step in two parallel phases (:func:`step_half`), a full-list step
        in one double-buffered pass (:func:`step_fused`; the store's ``position`` and ``velocity`` arrays are then
        replaced by the stepper's spare ones -- hold no references to them across calls), or, when a subclass adds
        forces in :meth:`compute_forces`, forces then kick-drift (:func:`integrate_kick_drift`). The last step ends
        complete. ``max_overlap_ratio`` is that of the last step, ``peak_overlap_ratio`` the largest over the
        advance's steps (and any :meth:`compute_forces` since the advance began). Returns the droplet permutation
        if the droplets were re-sorted (new p is old order[p]), else None.

        Threads: chosen by :class:`fulldem.tuning.ThreadChoice` (one below
        :data:`fulldem.tuning.PARALLEL_MIN_DROPLETS` droplets; else ``threads``, or the faster of one and all).
        """
        if not self.ready:
            self.droplets_changed()
        if not self._drag_set:
            raise RuntimeError("dem: call set_drag(beta) after droplets_changed() / sizes_changed()")
        if steps <= 0:
            return None
        steps = int(steps)
        self.peak_overlap_ratio = 0.0
        order = self.thread_choice.run(self.store.count, steps, lambda k: self._advance(k, fluid_velocity, impulse))
        self._read_first_contacts()  # before anyone changes the store
        return order

    def _advance(self, steps, fluid_velocity, impulse):
        s, n, nl = self.store, self.store.count, self.neighbours
        nchunk = _chunks(n)
        # a whole step per kernel call when nothing else enters the force (a subclass that adds forces in
        # compute_forces takes the general path: forces, then kick and drift of consecutive steps in one pass)
        fused = type(self).compute_forces is DemStepper.compute_forces
        self._order = None
        self.last_free_fraction = 0.0
        if self.free_flight and fused and nl.half and n and self._advance_free(steps, fluid_velocity, impulse, nchunk):
            return self._order
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.h, impulse)
        self._travel_bound += integrate_initial(s.position, s.velocity, self.force, self.mass, motion, n, nchunk)
        if fused and nl.half:
            self._advance_half(steps, fluid_velocity, impulse)
            return self._order
        for k in range(steps):
            self._keep_list(fluid_velocity, impulse)
            if k + 1 == steps:
                self.compute_forces()
                integrate_final(s.velocity, self.force, self.mass, motion, n)
            elif fused:
                self._step_fused(fluid_velocity, impulse, nchunk)
            else:
                self.compute_forces()
                self._travel_bound += integrate_kick_drift(s.position, s.velocity, self.force, self.mass,
                                                           Motion(self.drag, fluid_velocity, self.body_acceleration,
                                                                  self.h, impulse), n, nchunk)
            self.steps += 1
        return self._order

    # -- free flight (see the module docstring)
    def _advance_free(self, steps, fluid_velocity, impulse, nchunk) -> bool:
        """Advance with the droplets that touch nothing in free flight: select them, sub-step the others, check that
        every sub-stepped droplet stayed within its budget, then move the free ones in one exact step. Returns False
        if the advance was not taken (too few free droplets) or was undone (a budget breach, or a neighbour-list
        check falling inside the advance): the caller then sub-steps every droplet, as without free flight."""
        s, n, nl = self.store, self.store.count, self.neighbours
        counts = self.free_flight_counts
        duration = steps * self.h
        expected = self._advance_travel * steps / max(self._advance_steps, 1)
        if expected > 0.5 * nl.skin:  # the list would not last the advance
            counts.declined += 1
            return False
        farthest = self._free_candidates(duration, fluid_velocity, nchunk)
        # a list check inside the advance would undo it: check (and rebuild) the list now if the sub-stepped
        # droplets may travel as far as the last advance's did
        limit = 0.5 * nl.skin - expected
        if self._travel_bound > limit:
            builds = nl.builds
            self._keep_list(fluid_velocity, impulse, max(limit, 0.0) / nl.skin)
            if nl.builds != builds:  # (perhaps re-sorted: the candidates' rows moved)
                farthest = self._free_candidates(duration, fluid_velocity, nchunk)
        # the sub-stepped droplets move at most their budgets, and at most what keeps the list valid (skin/2 less
        # the travel bound: checked after the steps), whichever is less
        valid = 0.5 * nl.skin - self._travel_bound
        free = self._free_pairs(duration, fluid_velocity, min(farthest, valid))
        if free < FREE_FLIGHT_MIN_FRACTION * n:
            counts.declined += 1
            return False
        self._save_start(impulse)
        start_bound = self._travel_bound
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.h, impulse, self._deviation)
        self._travel_bound += integrate_initial(s.position, s.velocity, self.force, self.mass, motion, n, nchunk)
        if not self._advance_half(steps, fluid_velocity, impulse, free=True) or (
                farthest > valid and self._travel_bound > 0.5 * nl.skin):
            counts.list_checks += 1
            self._restore_start(impulse)
            return False
        over = free_flight_violations(self._free_flags, self._deviation, self._reach, n)
        if over:
            counts.breaches += 1
            counts.breach_droplets += int(over)
            self._restore_start(impulse)
            return False
        start = self._start
        moved = free_flight_jump(s.position, s.velocity, self._free_flags, self.mass, self.rate, motion, duration,
                                 start["position"], start["velocity"], start["impulse"], n, nchunk)
        # the free droplets moved at most `moved` since the advance's start, the others as the steps' sum says
        self._travel_bound = max(self._travel_bound, start_bound + moved)
        counts.advances += 1
        counts.droplets += int(free)
        self.last_free_fraction = free / n
        return True

    def _free_candidates(self, duration, fluid_velocity, nchunk) -> float:
        """Mark in ``_free_flags`` the candidates for free flight over ``duration`` [s], with their budgets
        (:func:`free_flight_candidates`); returns the farthest any droplet may move [m]."""
        s, n = self.store, self.store.count
        capacity = s.capacity
        if self._free_flags.shape[0] < capacity:
            self._free_flags = np.zeros(capacity, dtype=np.int32)
            self._transient = np.zeros(capacity)
            self._reach = np.zeros(capacity)
            self._deviation = np.zeros(capacity)
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.h, NO_IMPULSE, self._deviation)
        return free_flight_candidates(s.position, s.velocity, self.force, self._bodies(), n, self.walls, motion,
                                      self.rate, duration, FREE_FLIGHT_MARGIN, nchunk, self._free_flags,
                                      self._transient, self._reach)

    def _free_pairs(self, duration, fluid_velocity, farthest) -> int:
        """Keep free the candidates that no list partner and no droplet off the list can reach if none moves
        farther than ``farthest`` [m] (:func:`free_flight_pairs`); returns how many."""
        s, n, nl = self.store, self.store.count, self.neighbours
        # pairs off the list were at least a skin apart at its build and each droplet has since moved (or grown)
        # at most the travel bound
        unlisted = nl.skin - 2.0 * self._travel_bound
        return int(free_flight_pairs(s.position, s.contact_diameter, n, self._contacts(), fluid_velocity, duration,
                                     farthest, unlisted, slab_count(n, nl.longest_jump), self._free_flags,
                                     self._transient, self._reach))

    def _save_start(self, impulse) -> None:
        """Keep what a free-flight advance changes, to redo it (:meth:`_restore_start`)."""
        s, n = self.store, self.store.count
        start = self._start
        for name, array in (("position", s.position), ("velocity", s.velocity), ("force", self.force),
                            ("impulse", impulse)):
            kept = start.get(name)
            if kept is None or kept.shape[0] < array.shape[0]:
                kept = start[name] = np.zeros_like(array)
            kept[:n] = array[:n]
        entries = int(self.neighbours.start[n])
        start["approach"] = self.approach[:entries].copy() if self.record_first_contacts else None
        start["scalars"] = (self._travel_bound, self.steps, self.max_overlap_ratio, self.peak_overlap_ratio)

    def _restore_start(self, impulse) -> None:
        """Put back the state :meth:`_save_start` kept (no list rebuild or re-sort happens in between)."""
        s, n = self.store, self.store.count
        start = self._start
        s.position[:n] = start["position"][:n]
        s.velocity[:n] = start["velocity"][:n]
        self.force[:n] = start["force"][:n]
        if impulse.shape[0]:
            impulse[:n] = start["impulse"][:n]
        if start["approach"] is not None:
            self.approach[: start["approach"].shape[0]] = start["approach"]
        self._travel_bound, self.steps, self.max_overlap_ratio, self.peak_overlap_ratio = start["scalars"]

    def _keep_list(self, fluid_velocity, impulse, threshold=0.5) -> None:
        """Wrap periodic positions; rebuild (and re-sort) the list when a droplet may have travelled skin/2. The
        exact check runs once the travel bound exceeds ``threshold`` skins (a rebuild only if it measures more than
        skin/2)."""
        s, n, nl = self.store, self.store.count, self.neighbours
        if self.periodic.any():
            wrap_positions(s.position, n, self.lower, nl.period)
        # the sum of the steps' largest displacements bounds every droplet's travel since the build
        if self._travel_bound <= threshold * nl.skin:
            return
        if nl.needs_rebuild(s.position, s.contact_diameter, n) or nl.last_travel > threshold * nl.skin:
            self._read_first_contacts()  # by ident, while the list's entries and indices still match the store
            if self.sort_on_rebuild:
                new = nl.spatial_order(s.position, s.contact_diameter, n)
                s.reorder(new)
                self._seen_version = s.version  # this stepper re-sorted its own arrays with the store
                for arr in (self.mass, self.drag, self.rate, self.force, impulse) + (
                        (fluid_velocity,) if len(fluid_velocity) > 1 else ()):
                    if len(arr) >= n:
                        permute_rows(arr, new)
                self._order = new if self._order is None else self._order[new]
            self._build_list()
        else:  # the measured travel is a tighter bound than the sum of the steps' largest displacements
            self._travel_bound = nl.last_travel

    def _advance_half(self, steps, fluid_velocity, impulse, free=False):
        """Whole steps with the half list, two parallel phases each (:func:`step_half`), run by the compiled loop
        :func:`step_half_many`, which returns here only when the neighbour list must be checked. With ``free`` (a
        free-flight advance: the droplets marked in ``_free_flags`` are skipped, the others' deviation tracked)
        returns False, having stopped, when the list must be checked; else True."""
        s, n, nl = self.store, self.store.count, self.neighbours
        self.force[:n] = 0.0
        pending = False
        nslab = slab_count(n, nl.longest_jump)
        # (a re-sort permutes these arrays in place, so the record stays valid)
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.h, impulse,
                        self._deviation if free else NO_DEVIATION)
        bodies = self._bodies(self._free_flags if free else None)
        done = 0
        travelled = 0.0
        while done < steps:
            if self._travel_bound > 0.5 * nl.skin:
                if free:
                    return False
                if pending:  # bring every droplet to the same time level before checking the list
                    self._travel_bound += finish_even_slabs(s.position, s.velocity, self.force, self.mass,
                                                            bodies.flags, motion, n, nslab)
                    pending = False
                builds = nl.builds
                self._keep_list(fluid_velocity, impulse)
                if nl.builds != builds:
                    nslab = slab_count(n, nl.longest_jump)
            self._ensure_candidates(nslab)
            # after a check the bound is at most skin/2 (0 after a rebuild, the measured travel otherwise), so the
            # loop takes at least one step
            before = self._travel_bound
            taken, peak, worst, self._travel_bound, pending = step_half_many(
                steps - done, self._travel_bound, 0.5 * nl.skin, self.lower, s.position, s.velocity, bodies,
                n, self._contacts(), self.walls, motion, nslab, self.candidates, self.force, pending)
            travelled += self._travel_bound - before
            if taken:
                self.max_overlap_ratio = worst
                self.peak_overlap_ratio = max(self.peak_overlap_ratio, peak)
            done += taken
            self.steps += taken
        self._advance_travel, self._advance_steps = travelled, steps
        return True

    def _step_fused(self, fluid_velocity, impulse, nchunk):
        """Forces and kick-drift in one pass (:func:`step_fused`), into the spare state arrays, which then become
        the store's (double buffering: the store's ``position`` and ``velocity`` arrays are swapped)."""
        s, n, nl = self.store, self.store.count, self.neighbours
        if self._spare_position.shape != s.position.shape:
            self._spare_position = np.zeros_like(s.position)
            self._spare_velocity = np.zeros_like(s.velocity)
        self._ensure_candidates(nchunk)
        worst, moved = step_fused(s.position, s.velocity, self._spare_position, self._spare_velocity, self._bodies(),
                                  n, self._contacts(), self.walls,
                                  Motion(self.drag, fluid_velocity, self.body_acceleration, self.h, impulse), nchunk,
                                  self.candidates)
        s.position, self._spare_position = self._spare_position, s.position
        s.velocity, self._spare_velocity = self._spare_velocity, s.velocity
        self.max_overlap_ratio = worst
        self.peak_overlap_ratio = max(self.peak_overlap_ratio, worst)
        self._travel_bound += moved

    def _bodies(self, flags=None) -> Bodies:
        s = self.store
        return Bodies(s.contact_diameter, self.mass, s.flags if flags is None else flags, s.partner)

    def _contacts(self) -> Contacts:
        approach = self.approach if self.record_first_contacts else NO_RECORD
        return contacts_record(self.neighbours, self.damping, self.stiffness_ref, self.diameter_ref, self.law,
                               approach, self.h)

    def _ensure_candidates(self, nchunk):
        longest = self.neighbours.longest_row
        if self.candidates.shape[0] < nchunk or self.candidates.shape[1] < longest:
            self.candidates = np.zeros((max(nchunk, self.candidates.shape[0]),
                                        max(2 * longest, self.candidates.shape[1])), dtype=np.int32)




