"""The exponential velocity-Verlet integrator of the DEM sub-steps, alone and fused with the contact loops.

Symbols: h is the DEM step (``dem_step`` in the code, Delta t_DEM in docs/glossary.md).

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

NumPy twin: :func:`fulldem.dem.twins.integrate_reference`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .neighbours import wrap_positions
from .pairs import _row, _slab_rows
from .records import FASTMATH, FREE_FLIGHT


# 1/(k+2)! for k = 0..15: the series of phi2/h^2 = (z - 1 + e^-z)/z^2 = sum_k (-z)^k/(k+2)!, exact to round-off
# for z <= 0.5 with 16 terms (0.5^16/18! < 1e-20).
_SERIES = np.array([1.0 / math.factorial(k + 2) for k in range(16)])
_SERIES_LIMIT = 0.5


@njit(cache=True, inline="always")
def drag_factors(rate, dem_step):
    """(E, phi1, phi2) of the exponential step for drag rate 1/tau = beta/m [1/s] and DEM step h = ``dem_step`` [s].

    E = exp(-h/tau) [-], phi1 = tau (1 - E) [s], phi2 = tau (h - phi1) [s^2]; rate = 0 gives (1, h, h^2/2).
    """
    z = rate * dem_step
    if z < _SERIES_LIMIT:
        p2 = 0.0
        for k in range(15, -1, -1):
            p2 = p2 * (-z) + _SERIES[k]
        p1 = 1.0 - z * p2
        return 1.0 - z * p1, p1 * dem_step, p2 * dem_step * dem_step
    e = math.exp(-z)
    p1 = (1.0 - e) / z
    return e, p1 * dem_step, (1.0 - p1) / z * dem_step * dem_step


@njit(cache=True, parallel=True, error_model="numpy")
def drag_factors_into(mass, beta, dem_step, count, drag):
    """drag[p] = (E, phi1, phi2) of :func:`drag_factors` for drag coefficient beta (cap,) [kg/s] and mass [kg].

    Computed when beta, the masses or h change (the coupling's drag update), not every step.
    """
    for p in prange(count):
        e, phi1, phi2 = drag_factors(beta[p] / mass[p], dem_step)
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
    drag, fluid_velocity, body_acceleration, dem_step, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    half_step = 0.5 * dem_step
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for p in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            mp = mass[p]
            inv_m = 1.0 / mp
            e, phi1, phi2 = drag[p, 0], drag[p, 1], drag[p, 2]
            kick = phi1 - phi2 / dem_step
            moved = 0.0
            for a in range(3):
                acc = force[p, a] * inv_m + body_acceleration[a]
                u = fluid_velocity[p * stride, a]
                v = velocity[p, a]
                w = v - u
                step = u * dem_step + w * phi1 + acc * phi2
                position[p, a] += step
                moved += step * step
                v_new = u + w * e + acc * kick
                if track:  # the momentum part telescopes: -m v here, +m v at the advance's end
                    impulse[p, a] -= mp * v + mp * acc * half_step
                velocity[p, a] = v_new
            local = max(local, moved)
        worst[ch] = local
    return math.sqrt(worst.max())


@njit(cache=True, inline="always")
def _kick(p, velocity, force, mass, drag, body_acceleration, dem_step, impulse, track, half_step):
    """Second half of droplet p's step: add the end-of-step force's share to its velocity; complete its impulse."""
    mp = mass[p]
    inv_m = 1.0 / mp
    kick_end = drag[p, 2] / dem_step
    for a in range(3):
        acc = force[p, a] * inv_m + body_acceleration[a]
        velocity[p, a] += acc * kick_end
        if track:
            impulse[p, a] += mp * velocity[p, a] - mp * acc * half_step


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def integrate_final(velocity, force, mass, m, count):
    """Second half of the step: add the end-of-step force's share to the velocities; complete the drag impulse.

    force (cap, 3) [N] at the new positions (and the partly updated velocities, as in velocity Verlet).
    """
    drag, _, body_acceleration, dem_step, impulse, _ = m
    track = impulse.shape[0] > 0
    half_step = 0.5 * dem_step
    for p in prange(count):
        _kick(p, velocity, force, mass, drag, body_acceleration, dem_step, impulse, track, half_step)


@njit(cache=True, inline="always")
def _kick_drift(p, position, velocity, fx, fy, fz, mass, drag, fluid_velocity, stride, body_acceleration, dem_step, track,
                impulse, position_out, velocity_out, deviation):
    """Finish droplet p's step with force (fx, fy, fz) and start the next one, writing the new state to the ``_out``
    arrays (which may be the inputs); add |step - u h| to ``deviation[p]`` when it has rows (:class:`Motion`).
    Returns the squared displacement [m^2]."""
    mp = mass[p]
    inv_m = 1.0 / mp
    e, phi1, phi2 = drag[p, 0], drag[p, 1], drag[p, 2]
    kick_end = phi2 / dem_step
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
        step = u * dem_step + w * phi1 + acc * phi2
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
        impulse[p, 0] -= dem_step * (fx + mp * body_acceleration[0])
        impulse[p, 1] -= dem_step * (fy + mp * body_acceleration[1])
        impulse[p, 2] -= dem_step * (fz + mp * body_acceleration[2])
    return moved


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def integrate_kick_drift(position, velocity, force, mass, m, count, nchunk):
    """:func:`integrate_final` of one step then :func:`integrate_initial` of the next, in one pass over the droplets.

    Both use the same force (computed at the positions between the two steps), so this is exactly the two calls in
    a row, with one memory pass and one parallel launch instead of two. Returns the step's largest displacement [m].
    """
    drag, fluid_velocity, body_acceleration, dem_step, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    worst = np.zeros(nchunk)
    for ch in prange(nchunk):
        local = 0.0
        for p in range(ch * count // nchunk, (ch + 1) * count // nchunk):
            moved = _kick_drift(p, position, velocity, force[p, 0], force[p, 1], force[p, 2], mass, drag,
                                fluid_velocity, stride, body_acceleration, dem_step, track, impulse, position, velocity,
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
    (start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, _,
     every_contact) = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    drag, fluid_velocity, body_acceleration, dem_step, impulse, deviation = m  # (the contact record's dem_step: the same step)
    record_window = -1.0 if every_contact else dem_step  # < 0: every contact recorded (Contacts.every_contact)
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
                                     approach, record_window, walls, wall_lower, wall_upper, side, height, transverse, radius,
                                     wall_zeta, candidates[ch], no_force, False, local)
            moved = max(moved, _kick_drift(i, position, velocity, fx, fy, fz, mass, drag, fluid_velocity, stride,
                                           body_acceleration, dem_step, track, impulse, position_next, velocity_next,
                                           deviation))
        worst[ch] = local
        travel[ch] = moved
    return worst.max(), math.sqrt(travel.max())


@njit(cache=True, inline="always")
def _slab_kick(lo, hi, position, velocity, force, mass, flags, drag, fluid_velocity, stride,
               body_acceleration, dem_step, track, impulse, deviation, drift):
    """Finish the step of a slab's droplets lo..hi-1 with their force; with ``drift`` also start the next step and
    zero the force for the next accumulation. Droplets in free flight (``flags``) are left alone. Returns the largest
    squared displacement [m^2]."""
    moved = 0.0
    half_step = 0.5 * dem_step
    for p in range(lo, hi):
        if flags[p] & FREE_FLIGHT:
            continue
        if drift:
            fx, fy, fz = force[p, 0], force[p, 1], force[p, 2]
            moved = max(moved, _kick_drift(p, position, velocity, fx, fy, fz, mass, drag, fluid_velocity, stride,
                                           body_acceleration, dem_step, track, impulse, position, velocity, deviation))
            if (fx != 0.0) | (fy != 0.0) | (fz != 0.0):  # most rows are zero already: no write, no dirty line
                force[p, 0] = 0.0
                force[p, 1] = 0.0
                force[p, 2] = 0.0
        else:
            _kick(p, velocity, force, mass, drag, body_acceleration, dem_step, impulse, track, half_step)
    return moved


def slab_bounds(count, nslab):
    """First index of each of ``nslab`` slabs of ``count`` droplets, and ``count`` at the end: (nslab + 1,) int64,
    slab s being droplets bounds[s]..bounds[s + 1]-1 (s count // nslab on: the partition of
    :func:`fulldem.dem.pairs.contact_forces_half`)."""
    return np.arange(nslab + 1, dtype=np.int64) * count // nslab


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def step_half(position, velocity, b, count, c, w, m, bounds, candidates, force, even_pending, last):
    """One step of the half-list scheme in two parallel phases (three for the ``last`` step).

    The droplets are cut into slabs of consecutive indices, slab s being bounds[s]..bounds[s + 1]-1 (``bounds``
    (nslab + 1,) int64, :func:`slab_bounds`, or a gathered system's own, :mod:`fulldem.dem.gather`). Phase A, even
    slabs: (if ``even_pending``) finish their previous step and start this one (:func:`integrate_kick_drift`), then
    add their rows' forces. Phase B, odd slabs: add their rows' forces, which completes their droplets' forces (no
    other slab running later writes them), then kick-drift them. The even slabs' droplets are left pending (their
    forces are complete only after phase B); the next call finishes them first. ``force`` must be zero on entry
    except for pending even droplets, and is left so. With ``last`` both parities only finish the step (no drift)
    and ``force`` keeps the forces at the final positions. Same partitioning rules as :func:`contact_forces_half`.
    Returns (largest overlap ratio [-], largest displacement [m]).
    """
    diameter, mass, flags, partner = b
    (start, index, damping, period, inverse_period, periodic_any, stiffness_ref, diameter_ref, law, approach, _,
     every_contact) = c
    walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta = w
    drag, fluid_velocity, body_acceleration, dem_step, impulse, deviation = m
    record_window = -1.0 if every_contact else dem_step  # < 0: every contact recorded (Contacts.every_contact)
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    nslab = bounds.shape[0] - 1
    worst = np.zeros(nslab)
    travel = np.zeros(nslab)
    for q in prange((nslab + 1) // 2):
        s = 2 * q
        lo, hi = bounds[s], bounds[s + 1]
        if even_pending:
            travel[s] = _slab_kick(lo, hi, position, velocity, force, mass, flags, drag, fluid_velocity, stride,
                                   body_acceleration, dem_step, track, impulse, deviation, True)
        worst[s] = _slab_rows(lo, hi, position, velocity, diameter, mass, flags, partner, start, index, damping,
                              periodic_any, period, inverse_period, stiffness_ref, diameter_ref, law, approach,
                              record_window, walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta,
                              candidates[s], force)
    for q in prange(nslab // 2):
        s = 2 * q + 1
        lo, hi = bounds[s], bounds[s + 1]
        worst[s] = _slab_rows(lo, hi, position, velocity, diameter, mass, flags, partner, start, index, damping,
                              periodic_any, period, inverse_period, stiffness_ref, diameter_ref, law, approach,
                              record_window, walls, wall_lower, wall_upper, side, height, transverse, radius, wall_zeta,
                              candidates[s], force)
        travel[s] = _slab_kick(lo, hi, position, velocity, force, mass, flags, drag, fluid_velocity, stride,
                               body_acceleration, dem_step, track, impulse, deviation, not last)
    if last:
        for q in prange((nslab + 1) // 2):
            s = 2 * q
            _slab_kick(bounds[s], bounds[s + 1], position, velocity, force, mass, flags, drag, fluid_velocity, stride,
                       body_acceleration, dem_step, track, impulse, deviation, False)
    return worst.max(), math.sqrt(travel.max())


@njit(cache=True)
def step_half_many(steps, travel_bound, half_skin, lower, position, velocity, b, count, c, w, m, bounds, candidates,
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
        worst, moved = step_half(position, velocity, b, count, c, w, m, bounds, candidates, force, pending, last)
        peak = max(peak, worst)
        travel_bound += moved
        pending = not last
    return steps, peak, worst, travel_bound, pending


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model="numpy")
def finish_even_slabs(position, velocity, force, mass, flags, m, count, bounds):
    """Kick-drift the pending even slabs of :func:`step_half` (all droplets then at the same time level, forces
    zero), e.g. before a neighbour-list rebuild; ``flags`` those of the :class:`Bodies` of the steps, ``bounds``
    their slabs. Returns the largest displacement [m]."""
    drag, fluid_velocity, body_acceleration, dem_step, impulse, deviation = m
    stride = 1 if fluid_velocity.shape[0] > 1 else 0
    track = impulse.shape[0] > 0
    nslab = bounds.shape[0] - 1
    travel = np.zeros(nslab)
    for q in prange((nslab + 1) // 2):
        s = 2 * q
        travel[s] = _slab_kick(bounds[s], bounds[s + 1], position, velocity, force, mass, flags, drag,
                               fluid_velocity, stride, body_acceleration, dem_step, track, impulse, deviation, True)
    return math.sqrt(travel.max())
