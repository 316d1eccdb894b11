"""The coupled CFD-DEM step: slag on the grid, droplets as soft spheres, two-way coupled (model A).

One fluid step of length dt, from droplets at x^n and fluid (u^n, p^n):

1. feed: droplets due by the feed schedule are inserted over the inlet disk without overlaps;
2. the droplets' volume and volume flux are deposited on the faces at x^n (void fraction eps^n, flux q^n);
3. the fluid is advanced with eps^n (and last step's eps as ``eps_faces_old``), q^n and the drag reaction owed
   from the previous step, giving u^{n+1}, p^{n+1};
4. at x^n, with the *same* weights, each droplet receives the fluid velocity u^{n+1} and the pressure force
   V_p interp(-grad p^{n+1} + b); its drag coefficient beta (Schiller-Naumann, Di Felice hindrance, corrected for
   its own disturbance) is computed from them;
5. DEM sub-steps of length dt/n_sub integrate contacts, buoyant weight, pressure force and the drag (exactly, with
   the exponential integrator), accumulating each droplet's drag impulse J; droplets that touch nothing over the
   fluid step skip the sub-steps and move in one exact step (free flight, :mod:`fulldem.dem`; ``self.dem.free_flight
   = False`` sub-steps every droplet, for comparison);
6. -J is deposited at x^n as the face force the fluid receives in the next step (so it is owed, not lost);
7. droplets touching the bottom are removed as *settled*, those leaving by the outlet as *lost*.

Event points. The droplet set (:class:`fulldem.droplets.DropletStore`, its only owner) changes only between fluid
steps: at the step's end, after the owed force is deposited (step 7: merges, exits; re-created droplets belong here
too), and at the next step's start, before anything is deposited (step 1: the feed). The processes acting there are
the run's submodels (:mod:`fulldem.submodels`). Between the first deposit
(2) and the owed deposit (6) the droplets keep their order and number -- the deposits and interpolations of a step
share per-droplet rows and stencils -- and a change there is refused (RuntimeError). The DEM stepper notices changes
by the store's version and rebuilds its list once, at the next step.

Momentum: droplets and fluid exchange drag and pressure forces through adjoint weights, so the total momentum
(fluid + droplets + the impulse owed to the fluid) changes only by the imposed body forces, to round-off
(tests/test_fulldem_stepper.py). Matte mass: fed = in slag + settled + lost, counted droplet by droplet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from settler.derived import settling_velocity
from settler.output import PROFILE_BANDS
from settler.physics import DRAG_LAWS, HINDRANCE, STANDARD_GRAVITY, FeedSchedule, sphere_mass, sphere_volume

from .boundaries import boundaries_for
from .coupling import filtered, mobility, smoothing
from .coupling.drag import drag_coefficients
from .coupling.exchange import (DEPOSIT_COMPONENTS, INTERPOLATE_COMPONENTS, drift_rows, forcing_rows, owed_rows,
                                start_rows)
from .dem.diagnostics import deepest_pair, droplet_masses, max_speed
from .dem.laws import effective_mass, stable_step, stiffness_for_overlap
from .dem.stepper import DemStepper
from .droplets import COALESCING, DropletStore
from .fluid import solver
from .fluid import walls as fluid_walls
from .fluid.grid import Grid
from .submodels.base import submodels_for
from .submodels.coalescence import empty_size_table, size_bin
from .submodels.exits import classify_exits
from .submodels.feed import draw_inlet_candidates, draw_slot_candidates, place_without_overlap
from .tuning import SKIN_MIN, SORT_INTERVAL, PhaseTimes, skin_for


#: Ratios sigma/h at which the grid's self-mobility factor is tabulated (see fulldem.coupling).
MOBILITY_RATIOS = np.array([0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 4.0])


@dataclass
class Counters:
    """Matte mass bookkeeping [kg] and event counts since t = 0 (``recreated``: the stepped reaction's changes of
    material; ``marks``: pairs marked by the delayed coalescence; ``refused_size``: evaluated pairs refused because
    the merged droplet would exceed the size limit); ``merges_reported`` (``marks_reported``,
    ``refused_reported``): ``merges`` (``marks``, ``refused_size``) at the last time-series row;
    ``merges_by_size``: merges by the size bins of the two droplets
    (:func:`fulldem.submodels.coalescence.size_bin`, smaller first); ``merges_by_height``: merges by the height band
    (:data:`settler.output.PROFILE_BANDS`, from the bottom) and place (under the inlet, elsewhere) of the larger
    droplet's centre (``merges_by_height.csv``, :func:`merge_places`)."""

    mass_fed: float = 0.0
    mass_settled: float = 0.0
    mass_lost: float = 0.0
    mass_reacted: float = 0.0
    fed: int = 0
    settled: int = 0
    lost: int = 0
    merges: int = 0
    recreated: int = 0
    marks: int = 0
    refused_size: int = 0
    merges_reported: int = 0
    marks_reported: int = 0
    refused_reported: int = 0
    merges_by_size: np.ndarray = field(default_factory=empty_size_table)
    merges_by_height: np.ndarray = field(default_factory=lambda: np.zeros((PROFILE_BANDS, 2), dtype=np.int64))

    def __post_init__(self):
        self.merges_by_size = np.asarray(self.merges_by_size, dtype=np.int64).reshape(empty_size_table().shape)
        self.merges_by_height = np.asarray(self.merges_by_height, dtype=np.int64).reshape(PROFILE_BANDS, 2)

    def state(self) -> dict:
        """Plain JSON-able numbers (the tables as nested lists)."""
        return {**vars(self), "merges_by_size": self.merges_by_size.tolist(),
                "merges_by_height": self.merges_by_height.tolist()}

    def totals(self) -> dict:
        """The counts and masses without the tables (for summaries)."""
        return {k: v for k, v in vars(self).items()
                if k not in ("merges_by_size", "merges_by_height", "merges_reported", "marks_reported",
                             "refused_reported")}


def merge_places(position, lower, height, inlet):
    """(height band, place) of merges at ``position`` (n, 3) [m] in a slag of ``height`` [m] above ``lower`` [m]:
    the band of :func:`settler.output.band_edges` (clipped to the slag) and 0 under ``inlet``
    (:class:`fulldem.boundaries.Inlet`: its disk or slot extended down), 1 elsewhere; int64 arrays."""
    position = np.asarray(position, dtype=float).reshape(-1, 3)
    band = np.floor((position[:, 2] - lower[2]) / height * PROFILE_BANDS).astype(np.int64)
    band = np.clip(band, 0, PROFILE_BANDS - 1)
    place = np.where(inlet.contains(position[:, 0], position[:, 1]), 0, 1).astype(np.int64)
    return band, place


def contact_scales(case):
    """(stiffness at the mean fed diameter [N/m], stiffness of the smallest fed pair [N/m], the smallest fed
    droplet's mass [kg]) of a case: what sets its contact time, hence its DEM step."""
    f, fd = case.feed, case.fulldem
    d_ref = f.mean_diameter
    excess = case.matte.density - case.slag.density
    stiffness_ref = stiffness_for_overlap(fd.max_overlap, d_ref, excess, fd.load_factor, STANDARD_GRAVITY)
    d_min = f.mean_diameter * f.scale_min
    return stiffness_ref, stiffness_ref * (d_min / d_ref) ** 2, sphere_mass(d_min, case.matte.density)


class StepDiagnostics(dict):
    """Per-step numbers: max_cell_reynolds, max_cfl, max_overlap_ratio, pressure_iterations, feed_backlog,
    free_fraction (droplets advanced in one exact step instead of the DEM sub-steps, see fulldem.dem *Free flight*),
    free_flight_breaches (fluid steps since the simulation was built or resumed whose DEM advance was redone with
    every droplet sub-stepped because a sub-stepped droplet left its budget)..."""


class Simulation:
    """A coupled run of one case. Construct, then call :meth:`advance` (or :meth:`step`).

    case: a :class:`settler.cases.Case`. Keyword options, mainly for verification set-ups:
    box: (size, lower) of the computational box [m] (default: the case's geometry at the origin);
    periodic: (3,) bools (periodic axes have no walls, inlet or outlet);
    feed: insert droplets over the inlet at the case's rate (default: True when feed.mass_rate > 0);
    inlet, outlet: use the case's slag inlet/outlet patches (default True where the box is the case's);
    absorbing_bottom: remove droplets touching the bottom as settled (default: True unless z is periodic);
    body_force: uniform mean pressure gradient b [N/m^3] on the mixture (fluid eps b, droplets V_p b);
    gravity: gravity vector [m/s^2] (default (0, 0, -g)).
    """

    def __init__(self, case, *, box=None, periodic=(False, False, False), feed=None, inlet=None, outlet=None,
                 absorbing_bottom=None, body_force=(0.0, 0.0, 0.0), gravity=None, droplets=None):
        self.case = case
        fd = case.fulldem
        g = case.geometry
        self.own_box = box is None
        size, lower = ((g.width, g.depth, g.height), (0.0, 0.0, 0.0)) if box is None else box
        self.grid = Grid.for_box(size, fd.cell_size, lower, periodic)
        self.lower = np.asarray(self.grid.lower, dtype=float)
        self.upper = self.grid.upper
        self.periodic = np.asarray(periodic, dtype=np.bool_)
        self.density = case.slag.density
        self.viscosity = case.slag_viscosity
        self.gravity = np.array((0.0, 0.0, -STANDARD_GRAVITY) if gravity is None else gravity, dtype=float)
        self.body_force = np.asarray(body_force, dtype=float)
        self.time = 0.0
        self.steps = 0
        self.counters = Counters()
        self.initial_mass = 0.0  # matte present at the start (droplet lists), counted as fed [kg]
        self.store = droplets if droplets is not None else DropletStore(4096)

        # boundaries: one description (fulldem.boundaries) for the fluid, the feed, the exits and the contacts
        use_inlet = (self.own_box and case.slag.feed_rate > 0.0) if inlet is None else inlet
        use_outlet = (self.own_box and case.has_outlet) if outlet is None else outlet
        self.bounds = boundaries_for(case, self.lower, self.upper, periodic, slag_inlet=use_inlet,
                                     outlet=use_outlet,
                                     absorbing_bottom=(not periodic[2]) if absorbing_bottom is None else absorbing_bottom)
        self.boundary = fluid_walls.make_boundary(self.grid, inlet=self.bounds.fluid_inlet(),
                                         outlet=self.bounds.fluid_outlet(), inflow_flux=self.bounds.inflow_flux)
        self.fluid = solver.rest_state(self.grid)

        # feed
        f = case.feed
        self.feed_on = (f.mass_rate > 0.0) if feed is None else feed
        self.submodels = submodels_for(case)  # what acts at the step's event points (fulldem.submodels)
        self.schedule = FeedSchedule(f.mass_rate, f.mean_diameter, case.matte.density, f.scale_std, f.scale_min,
                                     f.scale_max, seed=f.seed)
        self.backlog = np.empty(0)
        self.rng = np.random.default_rng(f.seed + 1)

        # contacts and the DEM step
        d_ref = f.mean_diameter
        self.stiffness_ref, k_min, m_min = contact_scales(case)
        self.contact_step = stable_step(k_min, effective_mass(m_min, m_min), fd.contact_steps)
        dem_step = fd.dem_step if fd.dem_step > 0.0 else self.contact_step
        self.substeps = max(1, math.ceil(fd.fluid_step / dem_step - 1e-9))
        self.dt = fd.fluid_step
        self.dem_step = self.dt / self.substeps
        self.d_ref = d_ref
        self.dem = DemStepper(self.store, self.lower, self.grid.size, self.periodic, self.dem_step, self.stiffness_ref,
                              d_ref, fd.restitution, SKIN_MIN * d_ref, np.zeros(3),
                              absorbing_bottom=self.bounds.absorbing_bottom, outlet=self.bounds.contact_outlet(),
                              sort_on_rebuild=False, record_first_contacts=case.coalescence.enabled,
                              every_contact=case.coalescence.trigger == "every_contact")

        # coupling tables and work arrays
        self.kernel = (fd.sigma_cells, fd.sigma_diameter, smoothing.DEFAULT_CUT)
        self.filtered = None
        # the drag's velocity and reaction with the walls' boundary faces (fulldem.near_wall = "wall"; filtered only)
        self.wall_faces = fd.near_wall == "wall" and fd.kernel == "filtered"
        self.mobility_ratios = MOBILITY_RATIOS
        if fd.kernel == "filtered":
            try:
                self.filtered = filtered.FilteredKernel(self.grid.shape, self.periodic, fd.sigma_cells, smoothing.DEFAULT_CUT)
            except ValueError as error:
                raise ValueError(f"fulldem.kernel = 'filtered' with fulldem.sigma_cells = {fd.sigma_cells} on a "
                                 f"{self.grid.shape} grid: {error}; use fulldem.kernel = 'direct' (with "
                                 f"fulldem.near_wall = 'interior')") from None
            # the filtered kernel's own discrete factor at sigma = sigma_cells h; wider droplets use the direct one
            wider = MOBILITY_RATIOS[MOBILITY_RATIOS > fd.sigma_cells * (1.0 + 1e-9)]
            self.mobility_ratios = np.concatenate([[fd.sigma_cells], wider])
            self.mobility = np.array([filtered.filtered_mobility_factor(fd.sigma_cells)]
                                     + [mobility.discrete_mobility_factor(r) for r in wider])
        else:
            self.mobility = np.array([mobility.discrete_mobility_factor(r) for r in MOBILITY_RATIOS])
        self.oseen_logs, self.oseen_values = mobility.oseen_table()
        self.drag_law = DRAG_LAWS[case.drag.law]
        self.viscosity_ratio = case.matte.viscosity / self.viscosity if case.drag.fluid_drop else 0.0
        self.eps_old = None
        self.owed_force = self.grid.zeros_faces()  # -J deposited, applied in the next fluid step [N/m^3]
        self.last = StepDiagnostics()
        self.phase_times = PhaseTimes()  # wall seconds per phase of the steps (fulldem.tuning.PhaseTimes)
        self._merges = []  # (first, second) index arrays proposed during the step, applied by apply_events
        self._work = {}  # work arrays of the filtered kernel, by (purpose, index)
        self._alloc(self.store.capacity)

    # ------------------------------------------------------------------------------------------------ helpers
    def _alloc(self, capacity):
        self.beta = np.zeros(capacity)
        self.fluid_velocity = np.zeros((capacity, 3))
        self.drift_velocity = np.zeros((capacity, 3))  # u + F/beta, what the DEM sees (see step)
        self.drift_version = -1  # the store version drift_velocity belongs to (see step)
        self.deposited = np.zeros((len(DEPOSIT_COMPONENTS), capacity))
        self.interpolated = np.zeros((len(INTERPOLATE_COMPONENTS), capacity))
        self.own = np.zeros(capacity)
        self.eps_around = np.ones(capacity)
        self.table = smoothing.stencil_table(capacity)  # the droplets' stencils at x^n, shared by the step's three passes
        self.impulse = np.zeros((capacity, 3))
        self.external = np.zeros((capacity, 3))
        self.volume = np.zeros(capacity)
        self.start_position = np.zeros((capacity, 3))
        self.per_droplet = np.zeros(capacity)
        self.mass = np.zeros(capacity)
        self.exit_code = np.zeros(capacity, dtype=np.int64)

    def _ensure_capacity(self):
        if self.beta.shape[0] < self.store.capacity:
            self._alloc(self.store.capacity)

    def _grid_args(self):
        return (self.grid.spacing, self.lower, np.asarray(self.grid.shape), self.periodic)

    def deposit(self, positions, values, component, out):
        """Deposit per-droplet ``values`` (already divided by the cell volume) on ``component`` (0-2 faces, 3 cells)."""
        rows = np.zeros((1, self.store.capacity))
        rows[0, : self.store.count] = values[: self.store.count]
        return self.deposit_many(positions, rows, np.array([component], dtype=np.int64), [out])[0]

    def _wide(self):
        """Indices of the droplets whose kernel is wider than sigma_cells h (they use the direct Gaussian)."""
        fd, s = self.case.fulldem, self.store
        return np.nonzero(fd.sigma_diameter * s.diameter[: s.count] > fd.sigma_cells * self.grid.spacing)[0]

    def _scratch_for(self, m):
        nx, ny, nz = self.grid.shape
        size = smoothing.thread_count() * m * (nx + 1) * (ny + 1) * (nz + 1)
        if getattr(self, "_scratch", np.zeros(0)).size < size:
            self._scratch = np.zeros(size)  # work array for every deposit; its chunks are zeroed by the kernel
        return self._scratch[:size].reshape(smoothing.thread_count(), m, nx + 1, ny + 1, nz + 1)

    def _persistent(self, key, shape, zero=False):
        """A work array of the filtered kernel kept between steps, zeroed on request."""
        array = self._work.get(key)
        if array is None or array.shape != shape:
            array = self._work[key] = np.zeros(shape)
        elif zero:
            array[...] = 0.0
        return array

    def deposit_many(self, positions, values, components, outs, mode=smoothing.COMPUTE, wall_faces=False):
        """Add rows of ``values`` (m, cap), deposited with the coupling kernel, to the arrays ``outs`` (m arrays, of
        ``components``: 0-2 faces, 3 cells), one pass; ``mode``: with the stencil table (see
        :func:`fulldem.coupling.smoothing.droplet_stencils`); ``wall_faces``: the filtered kernel's trilinear step
        gives the wall-normal boundary faces their share, which goes to the wall (``fulldem.near_wall``). Returns
        ``outs``."""
        s, n, m = self.store, self.store.count, len(components)
        if self.filtered is None:
            smoothing.deposit_many(positions, s.diameter, values, n, components, tuple(outs), *self._grid_args(),
                            *self.kernel, self._scratch_for(m), *self.table, mode)
            return outs
        wide = self._wide()
        narrow = values
        if wide.size:
            narrow = values.copy()
            narrow[:, wide] = 0.0
        raws = [self._persistent(("raw", k), out.shape, zero=True) for k, out in enumerate(outs)]
        # trilinear weights are cheaper to recompute than to load from the stencil table (measured 2x)
        smoothing.cic_deposit_many(positions, narrow, n, components, tuple(raws), *self._grid_args(), self._scratch_for(m),
                                   wall_faces)
        for raw, out, c in zip(raws, outs, components):
            out += self.filtered.filter(raw, c)
        if wide.size:
            smoothing.deposit_many(np.ascontiguousarray(positions[wide]), np.ascontiguousarray(s.diameter[wide]),
                            np.ascontiguousarray(values[:, wide]), wide.size, components, tuple(outs),
                            *self._grid_args(), *self.kernel, self._scratch_for(m), *smoothing.NO_TABLE, smoothing.COMPUTE)
        return outs

    def interpolate_many(self, positions, fields, components, out, own=smoothing.NO_OWN, mode=smoothing.COMPUTE,
                         wall_faces=False):
        """out[k, p] = the coupling kernel's interpolation of ``fields[k]`` (of ``components``) at droplet p; with
        ``own`` (cap,), also each droplet's self weight sum_cells w_p^2; ``wall_faces``: the adjoint of
        :meth:`deposit_many`'s. Returns ``out``."""
        s, n = self.store, self.store.count
        if self.filtered is None:
            smoothing.interpolate_many(positions, s.diameter, n, components, tuple(fields), out, own, *self._grid_args(),
                                *self.kernel, *self.table, mode)
            return out
        filtered = tuple(self.filtered.filter(f, c, out=self._persistent(("filtered", k), f.shape))
                         for k, (f, c) in enumerate(zip(fields, components)))
        smoothing.cic_interpolate_many(positions, n, components, filtered, out, *self._grid_args(), wall_faces)
        if own.shape[0]:
            self.filtered.self_weight(positions, n, self.grid.spacing, self.lower, own)
        wide = self._wide()
        if wide.size:
            part = np.zeros((len(components), wide.size))
            part_own = np.zeros(wide.size) if own.shape[0] else smoothing.NO_OWN
            smoothing.interpolate_many(np.ascontiguousarray(positions[wide]), np.ascontiguousarray(s.diameter[wide]),
                                wide.size, components, tuple(fields), part, part_own, *self._grid_args(),
                                *self.kernel, *smoothing.NO_TABLE, smoothing.COMPUTE)
            out[:, wide] = part
            if own.shape[0]:
                own[wide] = part_own
        return out

    def interpolate(self, positions, field, component, out):
        """out[p] = the coupling kernel's interpolation of ``field`` (of ``component``) at droplet p."""
        rows = np.zeros((1, max(self.store.capacity, 1)))
        self.interpolate_many(positions, (field,), np.array([component], dtype=np.int64), rows)
        out[: self.store.count] = rows[0, : self.store.count]
        return out

    def void_fraction(self):
        """Void fraction on faces (3 arrays) and at cells from the droplets' current positions [-]."""
        s, n = self.store, self.store.count
        volume = self.per_droplet
        volume[:n] = sphere_volume(s.diameter[:n]) / self.grid.cell_volume
        faces = [1.0 - self.deposit(s.position, volume, a, np.zeros(self.grid.face_shape(a))) for a in range(3)]
        cells = 1.0 - self.deposit(s.position, volume, 3, self.grid.zeros_cells())
        return faces, cells

    def particle_flux(self):
        s, n = self.store, self.store.count
        out = []
        for a in range(3):
            values = sphere_volume(s.diameter[:n]) * s.velocity[:n, a] / self.grid.cell_volume
            buf = np.zeros(s.capacity)
            buf[:n] = values
            out.append(self.deposit(s.position, buf, a, np.zeros(self.grid.face_shape(a))))
        return out

    # ------------------------------------------------------------------------------------------------ feed & exits
    def insert(self, diameters):
        """Insert droplets of the given diameters over the inlet (disk or slot) without overlap; unplaced ones wait."""
        diameters = np.concatenate([self.backlog, diameters])
        if diameters.size == 0:
            return 0
        fd, inlet = self.case.fulldem, self.bounds.inlet
        top, radius = inlet.top, inlet.radius
        cx, cy = inlet.centre
        if inlet.is_slot:
            candidates = draw_slot_candidates(self.rng, diameters, (cx, cy), inlet.half_extent, top,
                                              fd.insertion_layer, fd.insertion_tries)
        else:
            candidates = draw_inlet_candidates(self.rng, diameters, (cx, cy), radius, top, fd.insertion_layer,
                                               fd.insertion_tries)
        # the droplets present as the contacts see them: a partner marked for coalescence has grown its contact
        # diameter towards the merged droplet's (fulldem.submodels.coalescence), and a droplet placed against its
        # plain diameter starts up to a quarter of a diameter deep in it (the runaway overlap that stopped cubic
        # at 111.9 s and the double feed's wall run at 14.8 s)
        present = self.store.contact_diameter
        reach = max(float(diameters.max()), float(present[: self.store.count].max()) if self.store.count else 0.0)
        hx, hy = inlet.half_extent
        lower = np.array([cx - hx, cy - hy, top - fd.insertion_layer - diameters.max()])
        upper = np.array([cx + hx, cy + hy, top])
        chosen = np.empty(len(diameters), dtype=np.int64)
        place_without_overlap(candidates, diameters, self.store.position, present, self.store.count,
                              lower, upper, reach, chosen)
        ok = chosen >= 0
        self.backlog = diameters[~ok]
        if not ok.any():
            return 0
        positions = candidates[np.nonzero(ok)[0], chosen[ok]]
        d = diameters[ok]
        rho = self.case.matte.density
        velocity = np.zeros((len(d), 3))
        velocity[:, 2] = -self.terminal_velocity(d)  # fed at their own terminal velocity
        self.store.add(positions, d, rho, velocity=velocity)
        self.counters.mass_fed += float(np.sum(sphere_mass(d, rho)))
        self.counters.fed += len(d)
        self._ensure_capacity()  # the DEM sees the store's new version and rebuilds once, at the next step
        return len(d)

    def remove_exits(self):
        s = self.store
        n = s.count
        if n == 0:
            return
        leaving = classify_exits(s.position, s.diameter, n, *self.bounds.exit_args(), self.exit_code)
        if leaving == 0:
            return
        code = self.exit_code[:n]
        settled, lost = np.flatnonzero(code == 1), np.flatnonzero(code == 2)  # the masses of the leaving only
        self.counters.mass_settled += float(sphere_mass(s.diameter[settled], s.density[settled]).sum())
        self.counters.mass_lost += float(sphere_mass(s.diameter[lost], s.density[lost]).sum())
        self.counters.settled += settled.size
        self.counters.lost += lost.size
        s.remove(code > 0)

    # ------------------------------------------------------------------------------------------------ the step
    def step(self):
        """Advance the coupled system by one fluid step dt (see the module docstring)."""
        fd = self.case.fulldem
        lap = self.phase_times.lap
        self.phase_times.start()
        for submodel in self.submodels:  # the start-of-step event point: the feed
            submodel.at_start(self)
            lap(f"start: {submodel.name}")
        s = self.store
        self._ensure_capacity()
        if s.count and (not self.dem.ready or self.steps % SORT_INTERVAL == 0):
            # the skin first: the sort and the build then lay out the same cells, so a half list's rows hold
            # partners ahead in memory (see NeighbourList.spatial_order)
            self.dem.neighbours.skin = self.skin_for(max_speed(s.velocity, s.count))
            # droplets appended at the inlet (or moved into the holes of exits) would otherwise lie far in memory
            # from their neighbours, which cuts the parallel slabs of the DEM kernels to one (fulldem.dem.pairs.slab_count)
            s.reorder(self.dem.neighbours.spatial_order(s.position, s.diameter, s.count))
        lap("sort")
        # the DEM is set up at the first step even without droplets (a run may start empty and feed later)
        rebuilt = not self.dem.ready
        if rebuilt:  # one list build per step for this step's insertions, the last one's exits and a sort
            self.dem.droplets_changed()  # computes the contact forces at this state too
        elif self.dem.sizes_stale:  # sizes changed in place at the last event point (growth, reaction)
            self.dem.sizes_changed()
        lap("neighbour list and forces" if rebuilt else "contact sizes")
        n = s.count
        inv_cell_volume = 1.0 / self.grid.cell_volume

        # volume and volume flux at x^n, one pass: eps on faces and cells, q on faces
        values = self.deposited
        volume = self.volume
        start_rows(s.position, s.diameter, s.velocity, n, inv_cell_volume, self.start_position, volume, values)
        faces = [np.zeros(self.grid.face_shape(a)) for a in range(3)]
        phi_cells = self.grid.zeros_cells()
        flux = [np.zeros(self.grid.face_shape(a)) for a in range(3)]
        self.deposit_many(s.position, values, DEPOSIT_COMPONENTS, faces + [phi_cells] + flux, smoothing.STORE)
        deposited_version = s.version  # the stencil table and start rows are per droplet: see the check below
        eps_faces = [np.subtract(1.0, f, out=f) for f in faces]
        if min(float(e.min()) for e in eps_faces) <= 0.0:
            raise FloatingPointError("void fraction reached zero on a face: droplets overfill a cell")
        lap("deposit volume")
        state, fdiag = solver.step(self.grid, self.fluid, self.boundary, self.density, self.viscosity, self.dt,
                               eps_faces=eps_faces, particle_flux=flux, force=self.owed_force,
                               body_force=self.body_force, eps_faces_old=self.eps_old,
                               advection="koren" if fd.advection else "none", timer=self.phase_times)
        self.fluid = state
        self.eps_old = eps_faces
        self.momentum_eps = eps_faces

        # what the droplets feel, interpolated at x^n with the deposition weights, one pass
        pressure_force = solver.pressure_force_density(self.grid, state.p, self.body_force)
        droplet_masses(s.diameter, s.density, n, self.mass)
        seen = self.interpolated
        self.interpolate_many(s.position, (state.u, state.v, state.w, *pressure_force, phi_cells),
                              INTERPOLATE_COMPONENTS, seen, self.own, smoothing.LOAD)
        if self.wall_faces:  # the slag velocity again, now with the walls' zero normal velocity (fulldem.near_wall)
            self.interpolate_many(s.position, (state.u, state.v, state.w), INTERPOLATE_COMPONENTS[:3], seen[:3],
                                  wall_faces=True)
        lap("interpolate")
        eps_around = self.eps_around
        forcing_rows(seen, self.own, volume, self.mass, self.density, self.gravity, inv_cell_volume, n,
                     self.fluid_velocity, self.external, eps_around)
        drag_coefficients(s.diameter, s.velocity, self.fluid_velocity, eps_around, n, self.density, self.viscosity,
                          self.drag_law, HINDRANCE[fd.hindrance], self.viscosity_ratio, self.grid.spacing,
                          fd.sigma_cells, fd.sigma_diameter, fd.self_correction, self.mobility_ratios, self.mobility,
                          self.oseen_logs, self.oseen_values, self.beta)

        # DEM sub-steps with the external force F (buoyant weight and pressure force) held over the fluid step and
        # folded into the fluid velocity: dv/dt = (F + contacts)/m + (u - v)/tau equals contacts/m + (u + F/beta -
        # v)/tau, so the DEM sees u + F/beta and its contact kernels stay free of extra terms (whole sub-steps run
        # fused); its drag impulse then includes F h per sub-step, subtracted below
        drift_rows(self.fluid_velocity, self.external, self.beta, n, self.drift_velocity, self.impulse)
        self.dem.set_drag(self.beta)
        lap("drag")
        # forces at the step's start: those of the rebuild above, or recomputed (the last sub-step's kick changed the
        # velocities, hence the dashpot forces, after its forces were computed)
        at_start = self.dem.max_overlap_ratio if rebuilt else self.dem.compute_forces()
        # a failure's message names the pair while it still overlaps (contacts may push it apart within the step)
        start_pair = self._deepest_pair_text("at the step's start") if at_start > fd.overlap_abort else None
        self.dem.advance(self.substeps, self.drift_velocity, self.impulse)
        self.drift_version = s.version  # drift_velocity's rows are the store's droplets while this holds
        lap("dem")
        worst = max(at_start, self.dem.peak_overlap_ratio)
        # ... and the fluid is owed -J, deposited where the droplets felt the fluid
        owed_rows(self.impulse, self.external, self.substeps * self.dem_step, n, -inv_cell_volume / self.dt, values)
        if s.version != deposited_version:
            raise RuntimeError("stepper: droplets were added, removed or reordered between the step's deposits; the "
                               "droplet set may change only at the step's event points (see the module docstring)")
        self.owed_force = self.deposit_many(self.start_position, values[:3], INTERPOLATE_COMPONENTS[:3],
                                            [np.zeros(self.grid.face_shape(a)) for a in range(3)], smoothing.LOAD,
                                            self.wall_faces)
        lap("deposit drag")
        self.time += self.dt
        self.steps += 1
        self.apply_events()
        self.last = StepDiagnostics(max_cell_reynolds=fdiag.cell_reynolds, max_cfl=fdiag.courant,
                                    max_overlap_ratio=worst, pressure_iterations=fdiag.pressure_iterations,
                                    feed_backlog=len(self.backlog), free_fraction=self.dem.last_free_fraction,
                                    free_flight_breaches=self.dem.free_flight_counts.breaches)
        if not np.isfinite(s.position[: s.count]).all() or not np.isfinite(state.u).all():
            raise FloatingPointError(f"non-finite state at t = {self.time:.6g} s")
        if worst > fd.overlap_abort:
            origin = ("already at the step's start, where droplets had been placed or grown before it (initial "
                      "droplets, feed, merges)" if start_pair else "reached during the DEM sub-steps")
            pair = start_pair or self._deepest_pair_text("at the step's end")
            raise FloatingPointError(f"runaway overlap: {worst:.3f} of a diameter at t = {self.time:.6g} s "
                                     f"(fulldem.overlap_abort = {fd.overlap_abort}), {origin}; {pair}")
        lap("checks")
        return self.last

    def _deepest_pair_text(self, when: str) -> str:
        """The most overlapping pair of droplets now, described for a runaway overlap's message; ``when`` says at
        which point of the step (an overlap reached during the sub-steps may have relaxed by the step's end)."""
        s = self.store
        i, j, ratio = deepest_pair(s.position, s.contact_diameter, s.partner, s.count)
        if i < 0:
            return f"no droplets overlap {when}"

        def one(p):
            state = "marked for coalescence" if s.flags[p] & COALESCING else "free"
            where = ", ".join(f"{c * 1e3:.1f}" for c in s.position[p])
            return (f"droplet {s.ident[p]} (diameter {s.diameter[p] * 1e3:.3g} mm, contact "
                    f"{s.contact_diameter[p] * 1e3:.3g} mm, {state}, age {s.age[p]:.3g} s, at ({where}) mm)")

        return f"deepest pair {when}: {ratio:.3f} of a diameter, {one(i)} and {one(j)}"

    def propose_merges(self, first, second):
        """Ask for pairs of droplets (indices at this step) to be merged at the step's end-of-step event point (see
        :meth:`fulldem.droplets.DropletStore.merge`); the coalescence submodel's contact loop proposes them."""
        self._merges.append((np.asarray(first, dtype=np.int64).ravel(), np.asarray(second, dtype=np.int64).ravel()))

    def apply_events(self):
        """The end-of-step event point, after the owed drag is deposited: each submodel's ``at_end`` in order
        (:func:`fulldem.submodels.base.submodels_for`: merges, the case's submodels, exits)."""
        for submodel in self.submodels:
            submodel.at_end(self)
            self.phase_times.lap(f"end: {submodel.name}")

    def apply_merges(self):
        """Merge the pairs proposed during the step, in a fixed order (by the pair's lower ident, so a run does not
        depend on thread timing)."""
        if self._merges:
            first = np.concatenate([m[0] for m in self._merges])
            second = np.concatenate([m[1] for m in self._merges])
            self._merges = []
            ident = self.store.ident
            order = np.argsort(np.minimum(ident[first], ident[second]), kind="stable")
            self.merge(first[order], second[order])

    def merge(self, first, second):
        """Merge pairs of droplets now (:meth:`fulldem.droplets.DropletStore.merge`, periodic images taken into
        account), counting them in :attr:`counters` (``merges``, ``merges_by_size``); only at an event point.

        The one merge path of the engine: the coalescence submodel calls it at the end-of-step event point, and
        :meth:`apply_merges` calls it for the pairs proposed during the step."""
        s = self.store
        first = np.asarray(first, dtype=np.int64).ravel()
        second = np.asarray(second, dtype=np.int64).ravel()
        small = np.minimum(s.diameter[first], s.diameter[second])
        large = np.maximum(s.diameter[first], s.diameter[second])
        np.add.at(self.counters.merges_by_size, (size_bin(small), size_bin(large)), 1)
        bigger = np.where(s.diameter[first] >= s.diameter[second], first, second)
        np.add.at(self.counters.merges_by_height,
                  merge_places(s.position[bigger], self.lower, self.grid.size[2], self.bounds.inlet), 1)
        self.counters.merges += int(first.size)
        return s.merge(first, second, self.lower, self.dem.neighbours.period)

    def skin_for(self, speed):
        """Neighbour-list skin [m] for droplets moving at most ``speed`` [m/s] (see :func:`fulldem.tuning.skin_for`)."""
        return skin_for(speed, self.dt, self.d_ref)

    # ------------------------------------------------------------------------------------------------ diagnostics
    def momentum(self):
        """Total momentum [kg m/s]: fluid (with the void fraction of its last step) + droplets + impulse owed."""
        s, n = self.store, self.store.count
        mass = sphere_mass(s.diameter[:n], s.density[:n])
        droplets = (mass[:, None] * s.velocity[:n]).sum(axis=0)
        fluid = solver.total_momentum(self.grid, self.fluid, self.density, getattr(self, "momentum_eps", None))
        owed = np.array([float(np.sum(self.owed_force[a][solver._unique_faces(self.grid, a)])) for a in range(3)])
        return fluid + droplets + owed * self.dt * self.grid.cell_volume

    def backlog_mass(self):
        """Matte mass due by the feed schedule but waiting for room over the inlet [kg]."""
        return float(self.case.matte.density * math.pi / 6.0 * np.sum(self.backlog**3))

    def mass_in_slag(self):
        s, n = self.store, self.store.count
        return float(np.sum(sphere_mass(s.diameter[:n], s.density[:n])))

    def terminal_velocity(self, diameter):
        """Single-droplet terminal velocity in the case's slag, drag law and fluid-drop switch [m/s] (positive
        down): the balance of the drag kernel's law against the buoyant weight, the same function popbal uses."""
        return settling_velocity(self.case, diameter)
