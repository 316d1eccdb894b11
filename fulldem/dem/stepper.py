"""The DEM stepper: advances the droplets of a store by DEM sub-steps within one fluid step.

:class:`DemStepper` orchestrates the kernels of this folder -- the integrator (:mod:`.integrators`), the contact
loops (:mod:`.pairs`, :mod:`.walls`), free flight (:mod:`.free_flight`) and the neighbour list (:mod:`.neighbours`)
-- passing them arrays and the records of :mod:`.records`. The kernels have plain NumPy twins in :mod:`.twins` that
the tests compare them with; the DEM-only benchmark's driver is ``benchmarks/bench_dem.py``.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

from ..droplets import permute_rows
from ..tuning import ThreadChoice, compose
from . import laws
from .diagnostics import droplet_masses
from .free_flight import (FREE_FLIGHT_MARGIN, FREE_FLIGHT_MIN_FRACTION, FREE_FLIGHT_SEGMENT_FILL, FREE_FLIGHT_SEGMENTS,
                          FreeFlightCounts, free_flight_candidates, free_flight_jump, free_flight_pairs,
                          free_flight_violations)
from .gather import Gathered
from .integrators import (drag_factors_into, finish_even_slabs, integrate_final, integrate_initial,
                          integrate_kick_drift, slab_bounds, step_fused, step_half_many)
from .neighbours import NeighbourList, wrap_positions
from .pairs import contact_forces_full, contact_forces_half, first_contacts, pair_damping, slab_count
from .records import NO_DEVIATION, NO_RECORD, Bodies, Contacts, Motion, _chunks, contacts_record, walls_record


#: The ``impulse`` argument that tracks no drag impulse.
NO_IMPULSE = np.zeros((0, 3))


class DemStepper:
    """Advances the droplets of a :class:`fulldem.droplets.DropletStore` by DEM steps.

    One step: first half of the integrator, periodic wrap, neighbour-list upkeep, contact and wall forces at the new
    positions, second half (:meth:`step` for one, :meth:`advance` for several in a row, faster). The list is checked
    exactly (:meth:`NeighbourList.needs_rebuild`) only once the sum of the steps' largest displacements exceeds
    skin/2, so most steps skip the check; a rebuild may re-sort the droplets by cell (``sort_on_rebuild``) for memory
    locality. Threads are chosen by :class:`fulldem.tuning.ThreadChoice` (one below a few thousand droplets).

    Parameters: box ``lower``/``size`` (3,) [m], ``periodic`` (3,) bool, DEM step ``dem_step`` [s], contact ``stiffness_ref``
    [N/m] at ``diameter_ref`` [m], ``restitution`` [-] of droplet pairs and ``wall_restitution`` [-] (default: the
    same), ``skin`` [m], ``body_acceleration`` (3,) [m/s^2], ``law`` (a key of :data:`laws.CONTACT_LAWS`),
    ``absorbing_bottom``, ``outlet`` (side, height, transverse, radius) or None, ``half_list`` (default; False: a
    full list, each pair computed from both sides but a whole step in one pass -- measured slower on the benchmark,
    1.5x single-threaded), ``sort_on_rebuild``, ``cell_diameter`` [m] (None: 99th percentile), ``threads`` (None:
    chosen by timing, see :meth:`advance`); ``record_first_contacts`` keeps the record of :class:`Contacts` for the coalescence
    submodel, ``every_contact`` records every contact of free droplets instead of first ones only).

    The caller (the coupling) owns the drag: :meth:`set_drag` with beta (cap,) [kg/s] whenever it changes, the fluid
    velocity at the droplets (cap, 3) or (1, 3) [m/s] and the ``impulse`` accumulator (cap, 3) [N s] passed to
    :meth:`step`. After adding or removing droplets call :meth:`droplets_changed` (then :meth:`set_drag`); after
    changing sizes or densities in place, :meth:`sizes_changed` (then :meth:`set_drag`).

    Re-sorting permutes the store and this stepper's arrays, plus the ``fluid_velocity`` (if per droplet) and
    ``impulse`` arrays passed to that step, in place; :meth:`step` / :meth:`advance` then return the permutation
    (new p is old order[p]; ``ident`` follows the droplets), else None. A caller holding other per-droplet arrays
    permutes them with it, or passes ``sort_on_rebuild=False``.
    """

    #: Run a free-flight advance's sub-steps on the sub-stepped droplets gathered into arrays of their own
    #: (:mod:`fulldem.dem.gather`; bit-identical, 2.4-2.7 times faster on the simple case's steady state) rather
    #: than in place among the free ones (False: the tests' reference).
    gather_free = True

    def __init__(self, store, lower, size, periodic, dem_step, stiffness_ref, diameter_ref, restitution, skin,
                 body_acceleration, wall_restitution=None, law="hooke", absorbing_bottom=False, outlet=None,
                 half_list=True, sort_on_rebuild=True, cell_diameter=None, threads=None, record_first_contacts=False,
                 free_flight=True, every_contact=False):
        self.store = store
        self.lower = np.asarray(lower, dtype=float)
        self.size = np.asarray(size, dtype=float)
        self.upper = self.lower + self.size
        self.periodic = np.asarray(periodic, dtype=np.bool_)
        self.dem_step = float(dem_step)
        self.stiffness_ref = float(stiffness_ref)
        self.diameter_ref = float(diameter_ref)
        self.zeta = float(laws.damping_ratio(restitution))
        self.wall_zeta = self.zeta if wall_restitution is None else float(laws.damping_ratio(wall_restitution))
        self.law = laws.contact_law_code(law)
        self.body_acceleration = np.asarray(body_acceleration, dtype=float)
        self.absorbing_bottom = bool(absorbing_bottom)
        side, height, transverse, radius = outlet if outlet is not None else (-1, 0.0, 0.0, 0.0)
        if not -1 <= int(side) <= 3:
            raise ValueError(f"dem: outlet side {side} must be 0..3 (x-, x+, y-, y+) or -1 (none)")
        self.outlet = (int(side), float(height), float(transverse), float(radius))
        self.walls = walls_record(self.lower, self.upper, self.periodic, self.absorbing_bottom, self.outlet,
                                  self.wall_zeta)
        self.record_first_contacts = bool(record_first_contacts)
        self.every_contact = bool(every_contact)  # the record holds every contact, not only first ones
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
        self._gathered = Gathered()  # the sub-stepped droplets of a free-flight advance (see _advance_gathered)
        # the travel bound's growth over the last advance [m] (sub-steps: the sum of their largest displacements;
        # free flight: the free droplets' jumps included), what the next one expects (list checks, segments)
        self._advance_travel = 0.0
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
        drag_factors_into(self.mass, beta, self.dem_step, n, self.drag)
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
        """Advance by one DEM step; see :meth:`advance`."""
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

    def _free_flight_possible(self) -> bool:
        # a whole step per kernel call when nothing else enters the force (a subclass that adds forces in
        # compute_forces takes the general path: forces, then kick and drift of consecutive steps in one pass)
        fused = type(self).compute_forces is DemStepper.compute_forces
        return self.free_flight and fused and self.neighbours.half and self.store.count > 0

    def _advance(self, steps, fluid_velocity, impulse):
        """The advance, as consecutive free-flight advances where the list would not last a whole one
        (:data:`fulldem.dem.free_flight.FREE_FLIGHT_SEGMENT_FILL`)."""
        segments = 1
        if self._free_flight_possible() and self._advance_steps:
            expected = self._advance_travel * steps / self._advance_steps
            fill = FREE_FLIGHT_SEGMENT_FILL * 0.5 * self.neighbours.skin
            segments = min(max(math.ceil(expected / fill), 1), steps)
        if segments == 1 or segments > FREE_FLIGHT_SEGMENTS:  # (more: even the segments would be sub-stepped)
            return self._advance_once(steps, fluid_velocity, impulse)
        order = None
        free = 0.0
        for q in range(segments):
            part = (q + 1) * steps // segments - q * steps // segments
            order = compose(order, self._advance_once(part, fluid_velocity, impulse))
            free += self.last_free_fraction * part
        self.last_free_fraction = free / steps
        return order

    def _advance_once(self, steps, fluid_velocity, impulse):
        s, n, nl = self.store, self.store.count, self.neighbours
        nchunk = _chunks(n)
        fused = type(self).compute_forces is DemStepper.compute_forces
        self._order = None
        self.last_free_fraction = 0.0
        if self._free_flight_possible() and self._advance_free(steps, fluid_velocity, impulse, nchunk):
            return self._order
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.dem_step, impulse)
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
                                                                  self.dem_step, impulse), n, nchunk)
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
        duration = steps * self.dem_step
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
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.dem_step, impulse, self._deviation)
        self._travel_bound += integrate_initial(s.position, s.velocity, self.force, self.mass, motion, n, nchunk)
        sub_steps = self._advance_gathered if self.gather_free else partial(self._advance_half, free=True)
        if not sub_steps(steps, fluid_velocity, impulse) or (
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
        # what the next advance expects (list checks, segments): the bound's growth, the free droplets' jumps included
        self._advance_travel = self._travel_bound - start_bound
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
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.dem_step, NO_IMPULSE, self._deviation)
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
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.dem_step, impulse,
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
                                                            bodies.flags, motion, n, slab_bounds(n, nslab))
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
                n, self._contacts(), self.walls, motion, slab_bounds(n, nslab), self.candidates, self.force, pending)
            travelled += self._travel_bound - before
            if taken:
                self.max_overlap_ratio = worst
                self.peak_overlap_ratio = max(self.peak_overlap_ratio, peak)
            done += taken
            self.steps += taken
        self._advance_travel, self._advance_steps = travelled, steps
        return True

    def _advance_gathered(self, steps, fluid_velocity, impulse) -> bool:
        """The sub-steps of a free-flight advance, run on the sub-stepped droplets gathered into arrays of their own
        (:class:`fulldem.dem.gather.Gathered`: bit-identical to :meth:`_advance_half` with ``free``, and faster
        since the free droplets' rows are not in the way). Returns False, having stopped, when the list must be
        checked; else True."""
        s, n, nl = self.store, self.store.count, self.neighbours
        self.force[:n] = 0.0
        if self._travel_bound > 0.5 * nl.skin:
            return False
        bounds = slab_bounds(n, slab_count(n, nl.longest_jump))
        motion = Motion(self.drag, fluid_velocity, self.body_acceleration, self.dem_step, impulse, self._deviation)
        contacts = self._contacts()
        g = self._gathered
        bodies, gathered_contacts, gathered_motion = g.gather(self._free_flags, n, contacts, bounds, s.position,
                                                              s.velocity, self._bodies(self._free_flags), motion)
        self._ensure_candidates(bounds.shape[0] - 1)  # (the gathered rows are no longer than the list's)
        before = self._travel_bound
        taken, peak, worst, self._travel_bound, _ = step_half_many(
            steps, self._travel_bound, 0.5 * nl.skin, self.lower, g.position, g.velocity, bodies, g.count,
            gathered_contacts, self.walls, gathered_motion, g.bounds, self.candidates, g.force, False)
        g.scatter(s.position, s.velocity, self.force, contacts.approach)
        if taken:
            self.max_overlap_ratio = worst
            self.peak_overlap_ratio = max(self.peak_overlap_ratio, peak)
        self.steps += taken
        if taken < steps:
            return False
        self._advance_travel, self._advance_steps = self._travel_bound - before, steps
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
                                  Motion(self.drag, fluid_velocity, self.body_acceleration, self.dem_step, impulse), nchunk,
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
                               approach, self.dem_step, self.every_contact)

    def _ensure_candidates(self, nchunk):
        longest = self.neighbours.longest_row
        if self.candidates.shape[0] < nchunk or self.candidates.shape[1] < longest:
            self.candidates = np.zeros((max(nchunk, self.candidates.shape[0]),
                                        max(2 * longest, self.candidates.shape[1])), dtype=np.int32)
