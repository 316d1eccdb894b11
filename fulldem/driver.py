"""Running a case with the coupled engine: ``settler full CASE [overrides] --out DIR``.

Outputs in DIR (all written atomically):

* ``case.toml`` (the resolved case) and ``metadata.json`` (engine, units, grid, steps, start-up numbers);
* ``timeseries.csv`` with the columns of :data:`settler.output.TIME_SERIES`, a row every
  ``fulldem.output_interval`` of simulated time;
* ``snapshots.pvd`` with ``droplets_NNNNN.vtu`` / ``fluid_NNNNN.vti`` (the slag as VTK image data) every ``fulldem.snapshot_interval`` (open the
  .pvd in ParaView);
* ``timeseries.png`` and ``droplets.png`` (side and top views coloured by settling velocity) at the end;
* ``checkpoint.npz`` every ``fulldem.checkpoint_interval`` seconds of wall time and at the end: ``--resume``
  continues from it and loses nothing;
* on a numerical blow-up (non-finite values, runaway overlap) the run stops with a message and writes
  ``last_good.npz``, the state at the last time-series row before the failure (same format as a checkpoint).

A run can start from a droplet list (CSV with columns x, y, z, diameter and optionally density; SI units; header
line required; see :mod:`fulldem.io.droplet_list`) with the feed off: ``--droplets FILE --no-feed``.

Stopping and resuming. SIGINT (Ctrl-C) and SIGTERM (what a batch scheduler sends) end the step under way, write
``checkpoint.npz`` and the time series, and stop the run with :class:`RunInterrupted` (the command exits 130 or 143
and says how to resume); a second Ctrl-C stops at once, without a checkpoint. ``--resume`` continues from the
checkpoint bit for bit, but only with the case it was written with: the checkpoint carries the resolved case, and
any key that differs (other than the run-control keys of :data:`RUN_CONTROL_KEYS`) is refused by name.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import signal
import threading
import time as _time
from pathlib import Path

import numba
import numpy as np

from settler.cases import SCHEMA, CaseError, load_case
from settler.output import (MERGES_BY_SIZE, SNAPSHOT_TABLES, atomic_write_text, mass_balance_error, OutputError,
                            prepare_output_folder, read_table, read_time_series, time_series_frame, to_json,
                            write_run_metadata, write_table, write_time_series)

from .coupling import smoothing
from .coupling.filtered import filtered_width_allowed
from .dem.laws import contact_time, effective_mass
from .droplets import MERGED
from .fluid import solver as fl
from .io import channel, zones
from .io.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from .io.droplet_list import DropletListError, read_droplet_list
from .io.progress import Progress
from .io.snapshots import SnapshotWriter
from .stepper import Counters, Simulation, contact_scales
from .submodels.base import missing_submodels
from .submodels.coalescence import size_table_frame


#: Case keys that control how a run is carried out, not what it computes: they may differ between a checkpoint and
#: the case that resumes it (section, key).
RUN_CONTROL_KEYS = frozenset({("fulldem", "end_time"), ("fulldem", "output_interval"),
                              ("fulldem", "snapshot_interval"), ("fulldem", "checkpoint_interval"),
                              ("case", "description")})
#: Fewest fluid cells along an axis (chosen: the pressure solver's and the coupling filter's stencils need a few
#: cells; a grid coarser than this cannot resolve the flow around a droplet cloud anyway).
MIN_CELLS = 4
#: Memory a fluid cell costs in a coupled run [bytes]: BYTES_PER_CELL + BYTES_PER_CELL_THREAD per Numba thread (the
#: coupling's deposit scratch, 7 doubles a node and thread). Measured 2026-12-01 on 2 threads: the peak resident
#: memory of the demo case grows by 864-873 bytes per cell between 40^3, 80^3 and 100^3 grids (3 fed steps).
BYTES_PER_CELL = 760
BYTES_PER_CELL_THREAD = 56
#: Fraction of the machine's memory a run's grid may take before it is refused.
MEMORY_FRACTION = 0.7


class RunError(RuntimeError):
    """A run that cannot start or continue; the message says why."""


class RunRefused(RunError):
    """Input the run refuses before it takes a step (an end time, a droplet list, an output folder, a checkpoint of
    another case): the command line exits 2 for it, as for a refused case key."""


class RunInterrupted(RunError):
    """The run was stopped by a signal after its state was saved; ``signal_number`` says which."""

    def __init__(self, message, signal_number):
        super().__init__(message)
        self.signal_number = signal_number


def _machine_memory() -> float:
    """Physical memory of the machine [bytes] (inf where it cannot be read)."""
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return math.inf


#: The fewest DEM steps per contact a given fulldem.dem_step may give: the fewest fulldem.contact_steps allows.
MIN_CONTACT_STEPS = int(SCHEMA["fulldem"]["contact_steps"].minimum)


def check_case(case) -> None:
    """Refuse, with :class:`settler.cases.CaseError`, a case the engine cannot run: a cell size that does not divide
    the box into whole cubic cells, fewer than :data:`MIN_CELLS` cells along an axis, a grid too large for the
    machine's memory, a smoothing kernel wider than the box or one the filtered kernel cannot have, or a given DEM
    step that resolves the shortest contact with fewer than :data:`MIN_CONTACT_STEPS` steps (a DEM step equal to
    the fluid step, say), or a fluid step above the explicit viscous limit h^2 / (6 nu)
    (:func:`fulldem.fluid.solver.viscous_limit`; twice the slag's viscosity at 2.5 mm cells and the 4 ms step: the
    slag's velocity doubled every step and the run stopped on a runaway overlap at 0.58 s)."""
    g, fd = case.geometry, case.fulldem
    edges = {"geometry.width": g.width, "geometry.depth": g.depth, "geometry.height": g.height}
    counts = {k: v / fd.cell_size for k, v in edges.items()}
    few = {k: c for k, c in counts.items() if c < MIN_CELLS - 1e-6}
    if few:
        k, c = next(iter(few.items()))
        raise CaseError(f"fulldem.cell_size = {fd.cell_size:g} m: gives {c:.3g} cell(s) along {k} = {edges[k]:g} m; "
                        f"allowed: at least {MIN_CELLS} cells per edge, cell_size <= {min(edges.values()) / MIN_CELLS:g} m")
    uneven = [k for k, c in counts.items() if abs(c - round(c)) > 1e-6 * max(c, 1.0)]
    if uneven:
        edge_text = ", ".join(f"{k} = {v:g} m" for k, v in edges.items())
        raise CaseError(f"fulldem.cell_size = {fd.cell_size:g} m: must divide every box edge into whole cubic cells "
                        f"({edge_text}: {', '.join(f'{counts[k]:.4g} cells' for k in edges)}); allowed: "
                        f"{_dividing_sizes(list(edges.values()), fd.cell_size)}")
    cells = math.prod(round(c) for c in counts.values())
    need = cells * (BYTES_PER_CELL + BYTES_PER_CELL_THREAD * numba.get_num_threads())
    have = _machine_memory()
    if need > MEMORY_FRACTION * have:
        raise CaseError(f"fulldem.cell_size = {fd.cell_size:g} m: a grid of {' x '.join(str(round(c)) for c in counts.values())} "
                        f"= {cells:.3g} cells needs about {need / 2**30:.3g} GiB, more than {MEMORY_FRACTION:.0%} of this "
                        f"machine's {have / 2**30:.3g} GiB; allowed: a larger cell_size (at most "
                        f"{MEMORY_FRACTION * have * cells / need:.3g} cells)")
    sigma = fd.sigma_cells * fd.cell_size
    widest = 2.0 * smoothing.DEFAULT_CUT * sigma
    if widest > min(edges.values()):
        raise CaseError(f"fulldem.sigma_cells = {fd.sigma_cells:g}: a smoothing kernel of sigma = {sigma:g} m spans "
                        f"{widest:g} m (2 x {smoothing.DEFAULT_CUT:g} sigma), more than the box's smallest edge "
                        f"{min(edges.values()):g} m; allowed: sigma_cells <= "
                        f"{min(edges.values()) / (2.0 * smoothing.DEFAULT_CUT * fd.cell_size):g}")
    if fd.dem_step > 0.0:
        _, k_min, m_min = contact_scales(case)
        duration = contact_time(k_min, effective_mass(m_min, m_min))
        most = duration / MIN_CONTACT_STEPS
        if fd.dem_step > most:
            raise CaseError(f"fulldem.dem_step = {fd.dem_step:g} s: resolves the shortest contact (the smallest fed "
                            f"pair's, {duration:.3g} s) with {duration / fd.dem_step:.3g} steps; allowed: 0 (chosen "
                            f"from the contact time, fulldem.contact_steps per contact) or at most {most:.3g} s "
                            f"({MIN_CONTACT_STEPS} steps per contact, the fewest fulldem.contact_steps allows)")
    limit = fl.viscous_limit(fd.cell_size, case.slag.density, case.slag_viscosity)
    if fd.fluid_step > limit:
        raise CaseError(f"fulldem.fluid_step = {fd.fluid_step:g} s: above the explicit viscous limit h^2 / (6 nu) = "
                        f"{limit:.3g} s of cells of h = {fd.cell_size:g} m in slag of viscosity "
                        f"{case.slag_viscosity:.3g} Pa s (at {case.slag.temperature:g} K), where the slag's velocity "
                        f"grows without bound; allowed: fluid_step <= {limit:.3g} s (the reference runs keep "
                        f"nu dt / h^2 <= 0.1, i.e. fluid_step <= {0.6 * limit:.3g} s, where packed droplets shrink "
                        "the slag's share of a cell)")
    if fd.near_wall == "wall" and fd.kernel != "filtered":
        raise CaseError(f"fulldem.near_wall = 'wall' with fulldem.kernel = {fd.kernel!r}: the walls' faces enter the "
                        "filtered kernel's trilinear weights only; allowed: near_wall = 'interior', or kernel = "
                        "'filtered'")
    if fd.kernel == "filtered" and not filtered_width_allowed(fd.sigma_cells):
        raise CaseError(f"fulldem.sigma_cells = {fd.sigma_cells:g}: the filtered kernel's trilinear step alone is "
                        f"wider; allowed: sigma_cells > 1/sqrt(6) = {1 / math.sqrt(6):.4f}, or fulldem.kernel = 'direct' with "
                        "fulldem.near_wall = 'interior'")


def _dividing_sizes(edges, near) -> str:
    """Cell sizes near ``near`` [m] that divide every edge into whole cells, as text."""
    found = set()
    for n in range(max(1, int(edges[0] / near) - 40), int(edges[0] / near) + 41):
        h = edges[0] / n
        if all(abs(e / h - round(e / h)) < 1e-9 * (e / h) for e in edges):
            found.add(h)
    best = sorted(found, key=lambda h: abs(h - near))[:3]
    if not best:
        return "a common divisor of the edges"
    return "a common divisor of the edges, e.g. " + ", ".join(f"{h:.6g}" for h in sorted(best)) + " m"


def _threading_layer():
    """Numba's threading layer in use, or "not started" before the first parallel kernel ran."""
    try:
        return numba.threading_layer()
    except ValueError:
        return "not started"


def time_series_row(sim: Simulation, wall_time=math.nan) -> dict:
    """One row of the shared time-series schema from the simulation's current state (``wall_time`` [s]: the run's
    wall-clock time so far)."""
    s, n, c = sim.store, sim.store.count, sim.counters
    d = s.diameter[:n]
    down = -s.velocity[:n, 2]
    mid = sim.lower[2] + 0.5 * sim.grid.size[2]
    near_axis = sim.bounds.inlet.contains(s.position[:n, 0], s.position[:n, 1]) \
        & (np.abs(s.position[:n, 2] - mid) <= 0.1 * sim.grid.size[2])
    in_slag = sim.mass_in_slag()
    fed = c.mass_fed + sim.initial_mass
    coalesced = int(((s.flags[:n] & MERGED) != 0).sum())
    merges, c.merges_reported = c.merges - c.merges_reported, c.merges
    marks, c.marks_reported = c.marks - c.marks_reported, c.marks
    refused, c.refused_reported = c.refused_size - c.refused_reported, c.refused_size
    own = {k: v for submodel in sim.submodels for k, v in submodel.columns(sim).items()}
    return {
        "time": sim.time,
        "droplet_count": n,
        "mean_diameter": float(d.mean()) if n else math.nan,
        "sauter_diameter": float((d**3).sum() / (d**2).sum()) if n else math.nan,
        "mean_settling_velocity": float(down.mean()) if n else math.nan,
        "centreline_settling_velocity": float(down[near_axis].mean()) if near_axis.any() else math.nan,
        "mass_fed": fed,
        "mass_in_slag": in_slag,
        "mass_settled": c.mass_settled,
        "mass_lost": c.mass_lost,
        "mass_reacted": c.mass_reacted,
        "mass_balance_error": float(mass_balance_error(fed, in_slag, c.mass_settled, c.mass_lost, c.mass_reacted)),
        **channel.time_series_columns(sim),
        "coalesced_count": coalesced,
        "uncoalesced_count": n - coalesced,
        "merges": merges,
        "pairs_marked": marks if sim.case.coalescence.enabled else math.nan,
        "merges_refused_by_size": refused if sim.case.coalescence.enabled else math.nan,
        "pairs_waiting": own.get("pairs_waiting", math.nan),
        "longest_marked": own.get("longest_marked", math.nan),
        "max_cell_reynolds": sim.last.get("max_cell_reynolds", math.nan),
        "max_cfl": sim.last.get("max_cfl", math.nan),
        "max_overlap_ratio": sim.last.get("max_overlap_ratio", math.nan),
        "wall_time": wall_time,
        "feed_backlog": sim.backlog_mass(),
    }


# ------------------------------------------------------------------------------------------------ checkpoints
def case_identity(case) -> dict:
    """The resolved case without its run-control keys (:data:`RUN_CONTROL_KEYS`): what a checkpoint belongs to."""
    return {section: {k: v for k, v in values.items() if (section, k) not in RUN_CONTROL_KEYS}
            for section, values in case.to_dict().items()}


def case_fingerprint(case) -> str:
    """SHA-256 of :func:`case_identity` as canonical JSON: equal for cases that compute the same run."""
    text = json.dumps(case_identity(case), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


#: Case keys added after checkpoints existed, with the value that computes what the engine computed before the key:
#: a checkpoint without the key resumes under that value (and only under it).
KEYS_ADDED = {("coalescence", "trigger"): "first_contact", ("fulldem", "near_wall"): "interior"}


def case_differences(saved: dict, case) -> list[str]:
    """``section.key: saved -> now`` for every key of :func:`case_identity` that differs between a saved identity
    dict and ``case`` (a key of :data:`KEYS_ADDED` missing from the saved one counts as its old value)."""
    now = case_identity(case)
    out = []
    for section in sorted(set(saved) | set(now)):
        a, b = saved.get(section, {}), now.get(section, {})
        a = {**{k: v for (sec, k), v in KEYS_ADDED.items() if sec == section and k not in a and b}, **a}
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                out.append(f"{section}.{key}: checkpoint {a.get(key)!r}, now {b.get(key)!r}")
    return out


def checkpoint_state(sim: Simulation):
    """(arrays, meta) that restore ``sim`` exactly: every field of the droplet store (:data:`fulldem.droplets.FIELDS`),
    the fluid, the owed impulse, the neighbour list, counters, random states and the case it belongs to."""
    arrays = {f"droplet_{k}": v for k, v in sim.store.state().items() if k != "next_ident"}
    arrays.update(u=sim.fluid.u, v=sim.fluid.v, w=sim.fluid.w, p=sim.fluid.p, backlog=sim.backlog,
                  feed_pending=sim.schedule._pending)
    for a in range(3):
        arrays[f"owed_{a}"] = sim.owed_force[a]
        if sim.eps_old is not None:
            arrays[f"eps_old_{a}"] = sim.eps_old[a]
    if sim.dem.ready:
        arrays.update({f"list_{k}": v for k, v in sim.dem.list_state().items()})
    meta = {"time": sim.time, "steps": sim.steps, "next_ident": sim.store.next_ident,
            "counters": sim.counters.state(), "initial_mass": sim.initial_mass, "dem_stale": not sim.dem.ready,
            "schedule": {"fed_mass": sim.schedule.fed_mass, "time": sim.schedule.time,
                         "rng": sim.schedule._rng.bit_generator.state},
            "rng": sim.rng.bit_generator.state, "feed_on": bool(sim.feed_on),
            "case": case_identity(sim.case), "case_fingerprint": case_fingerprint(sim.case)}
    return arrays, meta


def restore_state(sim: Simulation, arrays, meta):
    """Put ``sim`` (built for the same case) into the state of :func:`checkpoint_state`."""
    state = {k[len("droplet_"):]: v for k, v in arrays.items() if k.startswith("droplet_")}
    state["next_ident"] = meta["next_ident"]
    try:
        sim.store.restore(state)  # every field of fulldem.droplets.FIELDS
    except KeyError as exc:
        raise CheckpointError(f"the checkpoint lacks part of the droplet state: {exc.args[0]}") from None
    shapes = {"u": sim.fluid.u.shape, "v": sim.fluid.v.shape, "w": sim.fluid.w.shape, "p": sim.fluid.p.shape}
    wrong = {k: arrays[k].shape for k in shapes if arrays[k].shape != shapes[k]}
    if wrong:
        raise CheckpointError(f"its fluid arrays {wrong} do not fit this case's grid {sim.grid.shape}")
    sim.fluid = fl.FluidState(arrays["u"], arrays["v"], arrays["w"], arrays["p"])
    sim.owed_force = [arrays[f"owed_{a}"] for a in range(3)]
    sim.eps_old = [arrays[f"eps_old_{a}"] for a in range(3)] if "eps_old_0" in arrays else None
    sim.momentum_eps = sim.eps_old
    sim.backlog = arrays["backlog"]
    sim.time, sim.steps = meta["time"], meta["steps"]
    sim.counters = Counters(**meta["counters"])
    sim.initial_mass = meta["initial_mass"]
    sched = meta["schedule"]
    sim.schedule.fed_mass, sim.schedule.time = sched["fed_mass"], sched["time"]
    sim.schedule._pending = arrays["feed_pending"]
    sim.schedule._rng.bit_generator.state = sched["rng"]
    sim.rng.bit_generator.state = meta["rng"]
    sim._ensure_capacity()
    listed = {k[len("list_"):]: v for k, v in arrays.items() if k.startswith("list_")}
    if listed:  # the saved list: the next steps sum contact forces in the same order as the run that saved it
        sim.dem.restore_list(listed)
        if meta.get("dem_stale", False):  # the saved run would have set the DEM up anew at its next step
            sim.dem.invalidate()
    else:  # a checkpoint of an older version: rebuild (resumes agree to round-off)
        sim.dem.droplets_changed()


def _read_checkpoint_for(case, checkpoint: Path, out: Path, log):
    """Load ``checkpoint`` and refuse it unless it belongs to ``case``."""
    try:
        arrays, meta = load_checkpoint(checkpoint)
    except CheckpointError as exc:
        raise RunError(str(exc)) from None
    saved = meta.get("case")
    if saved is None:  # written before checkpoints carried their case: compare with the run's case.toml
        try:
            saved = case_identity(load_case(out / "case.toml"))
        except (CaseError, OSError) as exc:
            raise RunError(f"--resume: {checkpoint} records no case and {out / 'case.toml'} cannot be read ({exc}); "
                           "start a new run") from None
        log(f"note: {checkpoint} is from an older version and records no case; it was checked against "
            f"{out / 'case.toml'}")
    differences = case_differences(saved, case)
    if differences:
        raise RunRefused(f"--resume: the checkpoint in {out} belongs to another case; keys that differ: "
                       + "; ".join(differences) + ". Resume with the run's own case (its case.toml), or start a new "
                       "run in another folder")
    return arrays, meta


class _SignalCatcher:
    """Within ``with``: SIGINT and SIGTERM only set ``caught`` (the run saves and stops after the step under way);
    a second SIGINT raises KeyboardInterrupt at once. Outside the main thread it does nothing, and a signal the
    process ignores stays ignored (a shell starts background jobs with SIGINT ignored, so that Ctrl-C on a script
    does not stop them)."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.caught = None
        self._previous = {}

    def _handle(self, signum, frame):
        if self.caught is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.caught = signum

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                if signal.getsignal(sig) is not signal.SIG_IGN:
                    self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        return False


# ------------------------------------------------------------------------------------------------ the run
def run_case(case, out_dir, *, end_time=None, resume=False, droplets=None, feed=None, progress=True, log=print,
             overwrite=False, command=None):
    """Run ``case`` into ``out_dir``; returns the time series (pandas DataFrame).

    end_time [s] overrides fulldem.end_time; resume continues from out_dir/checkpoint.npz (only with the case it was
    written with); droplets: a CSV path (see :func:`fulldem.io.droplet_list.read_droplet_list`) for the initial
    droplets; feed: force the feed on/off; overwrite: replace another run's files in out_dir (else refused);
    command: the command line, recorded in metadata.json. Raises :class:`RunError` (and :class:`RunInterrupted` on
    SIGINT / SIGTERM, after saving a checkpoint) or :class:`settler.cases.CaseError`.
    """
    fd = case.fulldem
    t_end = fd.end_time if end_time is None else float(end_time)
    if not (math.isfinite(t_end) and t_end > 0.0):
        raise RunRefused(f"end_time = {t_end!r} s: allowed: a finite number of seconds > 0")
    if resume and droplets:
        raise RunRefused("--droplets with --resume: a resumed run takes its droplets from the checkpoint; drop "
                       "--droplets, or start a new run in another folder")
    check_case(case)
    if resume and str(out_dir).strip() and not (Path(out_dir) / "checkpoint.npz").is_file():
        raise RunRefused(f"--resume: no checkpoint in {out_dir}; start without --resume")
    try:
        out = prepare_output_folder(out_dir, overwrite=overwrite, resume=resume)
    except OutputError as exc:
        raise RunRefused(str(exc)) from None
    checkpoint = out / "checkpoint.npz"
    loaded = _read_checkpoint_for(case, checkpoint, out, log) if resume else None
    if loaded is not None:
        if loaded[1].get("feed_on") is not None and feed is not None and bool(feed) != loaded[1]["feed_on"]:
            raise RunRefused(f"--resume: the run in {out} was started with the feed {'on' if loaded[1]['feed_on'] else 'off'}; "
                           "resume it the same way (--no-feed only if it was started with --no-feed)")
        feed = loaded[1].get("feed_on", feed)
        if t_end <= loaded[1]["time"] + 1e-12:
            raise RunRefused(f"--end-time {t_end:g} s: the checkpoint in {out} is already at t = {loaded[1]['time']:.6g} s; "
                           "allowed: a later end time")
    store = None
    if droplets:
        try:
            store = read_droplet_list(droplets, lower=(0.0, 0.0, 0.0),
                                      upper=(case.geometry.width, case.geometry.depth, case.geometry.height),
                                      slag_density=case.slag.density, default_density=case.matte.density,
                                      overlap_limit=1.0)  # engulfed or coincident pairs never separate
        except DropletListError as exc:
            raise RunRefused(str(exc)) from None
    sim = Simulation(case, droplets=store, feed=feed)
    sim.initial_mass = sim.mass_in_slag()
    rows = []
    tables = {name: [] for name in SNAPSHOT_TABLES}  # channel profile and zone rows, one set per snapshot
    wall_before = 0.0  # wall-clock seconds spent before this process (by the runs this one resumes)
    snaps = SnapshotWriter(out, sim.grid)
    if loaded is not None:
        arrays, meta = loaded
        try:
            restore_state(sim, arrays, meta)
        except (CheckpointError, KeyError, ValueError, TypeError) as exc:
            raise RunError(f"--resume: {checkpoint} cannot be restored ({exc}); start a new run") from None
        series = out / "timeseries.csv"
        if series.exists():
            rows = [r for r in read_time_series(series).to_dict("records") if r["time"] <= sim.time + 1e-12]
        for name in tables:
            if (out / name).exists():
                tables[name] = [r for r in read_table(out / name).to_dict("records") if r["time"] <= sim.time + 1e-12]
        snaps.entries = [tuple(e) for e in meta.get("snapshots", [])]
        wall_before = float(meta.get("wall_time", 0.0))
        log(f"resumed from {checkpoint} at t = {sim.time:.6g} s, {sim.store.count} droplets")
    missing = missing_submodels(case)
    if missing:
        log(f"settler full: note: the {' and '.join(missing)} submodel(s) are not in the engine yet; this run has "
            f"none ({', '.join(m + '.enabled' for m in missing)} ignored)")
    startup = {"grid_shape": list(sim.grid.shape), "cell_size": sim.grid.spacing, "fluid_step": sim.dt,
               "dem_step": sim.dem_step, "dem_substeps": sim.substeps, "contact_stiffness_ref": sim.stiffness_ref,
               "slag_viscosity": sim.viscosity, "submodels": [m.name for m in sim.submodels],
               "submodels_missing": missing,
               "numba_threads": numba.get_num_threads(), "numba_threading_layer": _threading_layer(),
               "coupling_kernel": case.fulldem.kernel, "case_fingerprint": case_fingerprint(case),
               "feed_on": bool(sim.feed_on), "command": command}
    write_run_metadata(out, case, "fulldem", **startup)
    log(f"fulldem: grid {sim.grid.shape} of {sim.grid.spacing * 1e3:g} mm, fluid step {sim.dt:g} s, "
        f"DEM step {sim.dem_step:.3g} s ({sim.substeps} per fluid step), contact stiffness {sim.stiffness_ref:.3g} N/m")

    wall_start = _time.perf_counter()

    def wall_time():
        return wall_before + _time.perf_counter() - wall_start

    def save_checkpoint_now():
        arrays, meta = checkpoint_state(sim)
        meta["snapshots"] = snaps.entries
        meta["wall_time"] = wall_time()
        save_checkpoint(checkpoint, arrays, meta)

    next_row = (math.floor(sim.time / fd.output_interval + 1e-9) + 1) * fd.output_interval
    next_snap = ((math.floor(sim.time / fd.snapshot_interval + 1e-9) + 1) * fd.snapshot_interval
                 if fd.snapshot_interval > 0 else math.inf)
    if not rows:
        rows.append(time_series_row(sim, wall_time()))
        if fd.snapshot_interval > 0:
            eps_faces, eps_cells = sim.void_fraction()
            snaps.write(sim.time, sim.store, sim.fluid, eps_cells)
            _write_snapshot_tables(sim, eps_faces, tables, out)
    good = checkpoint_state(sim)
    if progress:
        log("fulldem: the first step compiles the Numba kernels where no cache exists yet (up to a minute); "
            "Ctrl-C saves a checkpoint and stops (continue with --resume)")
    bar = Progress(sim.time, t_end, enabled=progress)
    last_checkpoint = _time.perf_counter()
    backlog_warned = False
    with _SignalCatcher() as signals:
        try:
            while sim.time < t_end - 1e-9:
                try:
                    sim.step()
                except FloatingPointError as exc:
                    arrays, meta = good
                    save_checkpoint(out / "last_good.npz", arrays, meta)
                    write_time_series(time_series_frame(rows), out / "timeseries.csv")
                    raise RunError(f"numerical blow-up: {exc}. The state at t = {meta['time']:.6g} s was saved to "
                                   f"{out / 'last_good.npz'}; try a smaller fulldem.fluid_step or fulldem.dem_step, "
                                   "or a larger fulldem.max_overlap") from None
                if sim.time >= next_row - 1e-9:
                    rows.append(time_series_row(sim, wall_time()))
                    write_time_series(time_series_frame(rows), out / "timeseries.csv")
                    good = checkpoint_state(sim)
                    next_row += fd.output_interval
                    backlog = rows[-1]["feed_backlog"]
                    if not backlog_warned and backlog > 0.01 * max(rows[-1]["mass_fed"], 1e-300):
                        backlog_warned = True
                        log(f"settler full: warning: the feed falls behind: {backlog:.3g} kg of matte due by "
                            f"t = {sim.time:.4g} s waits for room over the inlet ({100 * backlog / rows[-1]['mass_fed']:.3g} % "
                            "of the mass fed; column feed_backlog); the inlet layer cannot take feed.mass_rate = "
                            f"{case.feed.mass_rate:g} kg/s (widen fulldem.insertion_layer or lower the rate)")
                if sim.time >= next_snap - 1e-9:
                    eps_faces, eps_cells = sim.void_fraction()
                    snaps.write(sim.time, sim.store, sim.fluid, eps_cells)
                    _write_snapshot_tables(sim, eps_faces, tables, out)
                    next_snap += fd.snapshot_interval
                if signals.caught is not None:
                    write_time_series(time_series_frame(rows), out / "timeseries.csv")
                    save_checkpoint_now()
                    name = signal.Signals(signals.caught).name
                    raise RunInterrupted(f"interrupted by {name} at t = {sim.time:.6g} s; the state was saved to "
                                         f"{checkpoint}. Continue with the same command plus --resume (same case, "
                                         f"--out {out})", signals.caught)
                if _time.perf_counter() - last_checkpoint > fd.checkpoint_interval:
                    save_checkpoint_now()
                    last_checkpoint = _time.perf_counter()
                bar.update(sim.time, sim.store.count, _progress_extra(sim))
        finally:
            bar.close()
    if not rows or rows[-1]["time"] < sim.time - 1e-12:
        rows.append(time_series_row(sim, wall_time()))
    frame = time_series_frame(rows)
    write_time_series(frame, out / "timeseries.csv")
    save_checkpoint_now()
    from .io.plots import plot_droplets, plot_time_series

    n = sim.store.count
    plot_time_series(out, f"{case.case.name}: fulldem")
    plot_droplets(out / "droplets.png", sim.store.position[:n], sim.store.diameter[:n], sim.store.velocity[:n],
                  sim.lower, sim.upper, f"{case.case.name} at t = {sim.time:.3g} s: {n} droplets")
    if case.coalescence.enabled:
        write_table(size_table_frame(sim.counters.merges_by_size).to_dict("records"), MERGES_BY_SIZE,
                    out / "merges_by_size.csv")
    summary = {"end_time": sim.time, "steps": sim.steps, "droplets": sim.store.count, **sim.counters.totals(),
               "feed_backlog": sim.backlog_mass()}
    atomic_write_text(out / "summary.json", to_json(summary))
    log(f"done: t = {sim.time:.6g} s, {sim.store.count} droplets in the slag; outputs in {out} "
        f"(timeseries.csv and timeseries.png, droplets.png, snapshots.pvd for ParaView, checkpoint.npz)")
    return frame


def _write_snapshot_tables(sim, eps_faces, tables: dict[str, list[dict]], out: Path) -> None:
    """Append the channel profile's and the zone diagnostics' rows at the current time to ``tables`` (file name ->
    rows, :data:`settler.output.SNAPSHOT_TABLES`) and rewrite each file in ``out``."""
    new = {"channel_profile.csv": channel.profile_rows(sim), **zones.snapshot_tables(sim, eps_faces)}
    for name, columns in SNAPSHOT_TABLES.items():
        tables[name] += new[name]
        write_table(tables[name], columns, out / name)


def _progress_extra(sim) -> str:
    """The progress line's diagnostics: cell Reynolds and CFL numbers, largest overlap, feed backlog if any."""
    last = sim.last
    text = (f"Re_cell {last['max_cell_reynolds']:.3g}  CFL {last['max_cfl']:.2g}  "
            f"overlap {last['max_overlap_ratio']:.3g}")
    if len(sim.backlog):
        text += f"  backlog {sim.backlog_mass():.3g} kg"
    return text
