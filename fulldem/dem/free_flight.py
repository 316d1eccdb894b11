"""Free flight: droplets that nothing can touch during a fluid step skip the DEM sub-steps.

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
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..droplets import COALESCING
from .integrators import drag_factors
from .pairs import _separation
from .records import FASTMATH, FREE_FLIGHT


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
    drag, fluid_velocity, body_acceleration, dem_step, impulse, deviation = m
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
    start, index, _, period, inverse_period, periodic_any, _, _, _, _, _, _ = c
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

#: An advance over which the droplets are expected (the travel bound's growth at the last advance's rate, free
#: droplets' jumps included) to travel more than this fraction of skin/2 runs as consecutive free-flight advances,
#: each expected within it, if at most :data:`FREE_FLIGHT_SEGMENTS` are needed (the list is checked, and rebuilt
#: if need be, between them); a whole advance that cannot keep the list valid would be sub-stepped without free
#: flight. 1: split only advances that would otherwise be declined; the skin already carries a margin
#: (fulldem.tuning.SKIN_TRAVEL: skin/2 = 1.25 v_max dt), and 0.8 cancelled it, splitting the steady state's
#: advances in two with a list check between (bench_steady, simple, 2 threads: DEM 42.7 against 31.5 ms a step).
#: Measured on the simple case's slag spin-up (bench_steady's warm-up, 150-180 mm/s in the channel at the 4 ms
#: fluid step, skin/2 = 0.5 mm): whole advances 0 % free and 370 ms a step, segments 88-89 % and 230-240 ms.
FREE_FLIGHT_SEGMENT_FILL = 1.0
FREE_FLIGHT_SEGMENTS = 4


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
