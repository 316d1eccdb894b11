"""The records the DEM kernels read, and the rules the kernels keep.

Records. The kernels take the droplets' ``position`` and ``velocity`` (cap, 3) and the work array ``force`` (cap, 3)
[N] (contact + wall + any other force except drag and a_body) as arrays, and everything else in four records:

* :class:`Bodies` -- per-droplet properties fixed over a step: contact diameter, mass, coalescence flags and partner;
* :class:`Contacts` -- the neighbour list (rows, per-entry dashpot coefficients), the periodic images, the contact
  law, and the first-contact record of the coalescence submodel;
* :class:`Walls` -- the box's planes, the outlet hole and the wall law;
* :class:`Motion` -- the integrator's drag factors, fluid velocity, body acceleration, step and impulse accumulator.

Records are unpacked at the top of each kernel, before its parallel loops, and the inline helpers (:func:`_row`,
:func:`_kick_drift`, ...) take plain arrays and numbers. Two reasons, both measured with numba 0.68: writes made
through a record's array field inside a ``prange`` loop are lost (the values vanish, no error; the impulse of the
integrator test was zero), and kernels whose helpers read the records' fields inside the loops ran 20-33 % slower
(bench_dem, 130 000 droplets, one thread: 2.5e7 against 3.7e7 particle-steps/s) for reasons the inlined IR does
not show.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np


#: LLVM fast-math flags of the hot kernels: fused multiply-add and reciprocal; no reassociation (the pair forces
#: stay exactly antisymmetric, so momentum is conserved to round-off) and no assumption that values are finite.
FASTMATH = {"contract", "arcp"}

#: Bit of the ``flags`` the kernels read (:class:`Bodies`) marking a droplet in free flight for the current advance
#: (see *Free flight* in the module docstring). Set only in the stepper's own copy of the store's flags, never in
#: the store, and far above the store's bits (:data:`fulldem.droplets.COALESCING`, ``MERGED``).
FREE_FLIGHT = 1 << 16


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
    ``diameter_ref`` [m]; ``law``: a code of :data:`fulldem.dem.laws.CONTACT_LAWS`. ``approach`` (entries,) [m/s]:
    the first-contact record -- a kernel writes the approach speed of each touching pair at its first contact (the
    pair's overlap is less than its approach speed times ``dem_step`` [s], so one step earlier they did not touch) where
    neither droplet is marked for coalescence, into the pair's entry (threads never write the same entry); entries
    not written keep their value (the caller sets -1). An array with no entries: nothing is recorded. With
    ``every_contact`` every touching pair of free droplets is recorded at every step, with max(-v_n, 0) (the
    coalescence submodel's ``trigger = "every_contact"``).
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
    dem_step: float
    every_contact: bool = False


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
    (1, 3) for one velocity everywhere [m/s]; ``body_acceleration`` (3,) [m/s^2]; ``dem_step`` [s]; ``impulse`` (cap, 3)
    [N s]: the drag impulse accumulator (an array with no rows: not tracked); ``deviation`` (cap,) [m]: each
    sub-stepped droplet's path away from drift with the fluid, sum over steps of |x_step - u h| (free flight's
    safety check, see *Free flight*; an array with no rows: not tracked).
    """

    drag: np.ndarray
    fluid_velocity: np.ndarray
    body_acceleration: np.ndarray
    dem_step: float
    impulse: np.ndarray
    deviation: np.ndarray = NO_DEVIATION


#: The ``approach`` array of a :class:`Contacts` that records nothing.
NO_RECORD = np.zeros(0)


def contacts_record(neighbours, damping, stiffness_ref, diameter_ref, law, approach=NO_RECORD,
                    dem_step=0.0, every_contact=False) -> Contacts:
    """A :class:`Contacts` for a :class:`fulldem.dem.neighbours.NeighbourList`'s current rows."""
    period = neighbours.period
    return Contacts(neighbours.start, neighbours.index, damping, period, neighbours.inverse_period,
                    bool((np.asarray(period) > 0.0).any()), float(stiffness_ref), float(diameter_ref), int(law),
                    approach, float(dem_step), bool(every_contact))


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
