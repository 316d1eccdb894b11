"""Running a case with the coupled engine: ``settler full CASE [overrides] --out DIR``.

Outputs in DIR (all written atomically):

* ``case.toml`` (the resolved case) and ``metadata.json`` (engine, units, grid, steps, start-up numbers);
* ``timeseries.csv`` with the columns of :data:`settler.output.TIME_SERIES`, a row every
  ``fulldem.output_interval`` of simulated time;
* ``snapshots.pvd`` with ``droplets_NNNNN.vtu`` / ``fluid_NNNNN.vtu`` every ``fulldem.snapshot_interval`` (open the
  .pvd in ParaView);
* ``timeseries.png`` and ``droplets.png`` (side and top views coloured by settling velocity) at the end;
* ``checkpoint.npz`` every ``fulldem.checkpoint_interval`` seconds of wall time and at the end: ``--resume``
  continues from it and loses nothing;
* on a numerical blow-up (non-finite values, runaway overlap) the run stops with a message and writes
  ``last_good.npz``, the state at the last time-series row before the failure (same format as a checkpoint).

A run can start from a droplet list (CSV with columns x, y, z, diameter and optionally density; SI units; header
line required) with the feed off: ``--droplets FILE --no-feed``.
"""

from __future__ import annotations

import json
import math
import time as _time
from pathlib import Path

import numba
import numpy as np
import pandas as pd

from settler.output import (atomic_write_text, mass_balance_error, read_time_series, time_series_frame, write_run_metadata,
                            write_time_series)

from . import fluid as fl
from .droplets import DropletStore
from .io import Progress, SnapshotWriter, load_checkpoint, save_checkpoint
from .stepper import Counters, Simulation


class RunError(RuntimeError):
    """A run that cannot start or continue; the message says why."""


def _threading_layer():
    """Numba's threading layer in use, or "not started" before the first parallel kernel ran."""
    try:
        return numba.threading_layer()
    except ValueError:
        return "not started"


def read_droplet_list(path, default_density):
    """Droplets from a CSV file with columns x, y, z, diameter [, density] (SI) -> DropletStore."""
    try:
        table = pd.read_csv(path, comment="#")
    except (OSError, pd.errors.ParserError) as exc:
        raise RunError(f"droplet list {path}: cannot read it as CSV ({exc})") from None
    missing = [c for c in ("x", "y", "z", "diameter") if c not in table.columns]
    if missing:
        raise RunError(f"droplet list {path}: missing columns {missing}; required: x, y, z, diameter "
                       "[, density] in SI units, with a header line")
    if (table["diameter"] <= 0).any() or not np.isfinite(table[["x", "y", "z", "diameter"]].to_numpy()).all():
        raise RunError(f"droplet list {path}: diameters must be positive and all values finite")
    density = table["density"].to_numpy(float) if "density" in table else default_density
    store = DropletStore(max(1024, 2 * len(table)))
    if len(table):
        store.add(table[["x", "y", "z"]].to_numpy(float), table["diameter"].to_numpy(float), density)
    return store


def time_series_row(sim: Simulation, wall_time=math.nan) -> dict:
    """One row of the shared time-series schema from the simulation's current state (``wall_time`` [s]: the run's
    wall-clock time so far)."""
    s, n, c = sim.store, sim.store.count, sim.counters
    d = s.diameter[:n]
    down = -s.velocity[:n, 2]
    g = sim.case.geometry
    cx, cy = sim.case.inlet_center
    mid = sim.lower[2] + 0.5 * sim.grid.size[2]
    near_axis = ((s.position[:n, 0] - cx) ** 2 + (s.position[:n, 1] - cy) ** 2 <= (0.5 * g.inlet_diameter) ** 2) \
        & (np.abs(s.position[:n, 2] - mid) <= 0.1 * sim.grid.size[2])
    in_slag = sim.mass_in_slag()
    fed = c.mass_fed + sim.initial_mass
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
        "max_cell_reynolds": sim.last.get("max_cell_reynolds", math.nan),
        "max_cfl": sim.last.get("max_cfl", math.nan),
        "max_overlap_ratio": sim.last.get("max_overlap_ratio", math.nan),
        "wall_time": wall_time,
    }


# ------------------------------------------------------------------------------------------------ checkpoints
def checkpoint_state(sim: Simulation):
    """(arrays, meta) that restore ``sim`` exactly (droplets, fluid, owed impulse, counters, random states)."""
    arrays = {f"droplet_{k}": v for k, v in sim.store.state().items() if k != "next_ident"}
    arrays.update(u=sim.fluid.u, v=sim.fluid.v, w=sim.fluid.w, p=sim.fluid.p, backlog=sim.backlog,
                  feed_pending=sim.schedule._pending)
    for a in range(3):
        arrays[f"owed_{a}"] = sim.owed_force[a]
        if sim.eps_old is not None:
            arrays[f"eps_old_{a}"] = sim.eps_old[a]
    meta = {"time": sim.time, "steps": sim.steps, "next_ident": sim.store.next_ident,
            "counters": vars(sim.counters), "initial_mass": sim.initial_mass,
            "schedule": {"fed_mass": sim.schedule.fed_mass, "time": sim.schedule.time,
                         "rng": sim.schedule._rng.bit_generator.state},
            "rng": sim.rng.bit_generator.state}
    return arrays, meta


def restore_state(sim: Simulation, arrays, meta):
    state = {k[len("droplet_"):]: v for k, v in arrays.items() if k.startswith("droplet_")}
    state["next_ident"] = meta["next_ident"]
    restored = DropletStore.from_state(state)
    store = sim.store
    store.reserve(restored.capacity)
    for name in ("position", "velocity", "diameter", "density", "original_diameter", "age", "flags", "partner",
                 "ident"):
        getattr(store, name)[: restored.count] = getattr(restored, name)[: restored.count]
    store.count, store.next_ident = restored.count, restored.next_ident
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
    sim.dem.droplets_changed()


# ------------------------------------------------------------------------------------------------ the run
def run_case(case, out_dir, *, end_time=None, resume=False, droplets=None, feed=None, progress=True, log=print):
    """Run ``case`` into ``out_dir``; returns the time series (pandas DataFrame).

    end_time [s] overrides fulldem.end_time; resume continues from out_dir/checkpoint.npz; droplets: a CSV path
    (see :func:`read_droplet_list`) for the initial droplets; feed: force the feed on/off.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fd = case.fulldem
    t_end = fd.end_time if end_time is None else float(end_time)
    store = read_droplet_list(droplets, case.matte.density) if droplets else None
    sim = Simulation(case, droplets=store, feed=feed)
    sim.initial_mass = sim.mass_in_slag()
    rows = []
    wall_before = 0.0  # wall-clock seconds spent before this process (by the runs this one resumes)
    snaps = SnapshotWriter(out, sim.grid)
    checkpoint = out / "checkpoint.npz"
    if resume:
        if not checkpoint.exists():
            raise RunError(f"--resume: no checkpoint in {out}; start without --resume")
        arrays, meta = load_checkpoint(checkpoint)
        restore_state(sim, arrays, meta)
        series = out / "timeseries.csv"
        if series.exists():
            rows = [r for r in read_time_series(series).to_dict("records") if r["time"] <= sim.time + 1e-12]
        snaps.entries = [tuple(e) for e in meta.get("snapshots", [])]
        wall_before = float(meta.get("wall_time", 0.0))
        log(f"resumed from {checkpoint} at t = {sim.time:.6g} s, {sim.store.count} droplets")
    if case.coalescence.enabled or case.reaction.enabled:
        log("settler full: note: the coalescence and reaction submodels are not in the engine yet; this run has "
            "neither (coalescence.enabled / reaction.enabled are ignored)")
    startup = {"grid_shape": list(sim.grid.shape), "cell_size": sim.grid.spacing, "fluid_step": sim.dt,
               "dem_step": sim.h, "dem_substeps": sim.substeps, "contact_stiffness_ref": sim.stiffness_ref,
               "slag_viscosity": sim.viscosity, "submodels_missing": ["coalescence", "reaction"],
               "numba_threads": numba.get_num_threads(), "numba_threading_layer": _threading_layer(),
               "coupling_kernel": case.fulldem.kernel}
    write_run_metadata(out, case, "fulldem", **startup)
    log(f"fulldem: grid {sim.grid.shape} of {sim.grid.spacing * 1e3:g} mm, fluid step {sim.dt:g} s, "
        f"DEM step {sim.h:.3g} s ({sim.substeps} per fluid step), contact stiffness {sim.stiffness_ref:.3g} N/m")

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
            snaps.write(sim.time, sim.store, sim.fluid, np.ones(sim.grid.shape))
    good = checkpoint_state(sim)
    if progress:
        log("fulldem: the first step compiles the Numba kernels where no cache exists yet (up to a minute)")
    bar = Progress(sim.time, t_end, enabled=progress)
    last_checkpoint = _time.perf_counter()
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
            if sim.time >= next_snap - 1e-9:
                _, eps_cells = sim.void_fraction()
                snaps.write(sim.time, sim.store, sim.fluid, eps_cells)
                next_snap += fd.snapshot_interval
            if _time.perf_counter() - last_checkpoint > fd.checkpoint_interval:
                save_checkpoint_now()
                last_checkpoint = _time.perf_counter()
            bar.update(sim.time, sim.store.count,
                       f"Re_cell {sim.last['max_cell_reynolds']:.3g}  CFL {sim.last['max_cfl']:.2g}  "
                       f"overlap {sim.last['max_overlap_ratio']:.3g}")
    finally:
        bar.close()
    if not rows or rows[-1]["time"] < sim.time - 1e-12:
        rows.append(time_series_row(sim, wall_time()))
    frame = time_series_frame(rows)
    write_time_series(frame, out / "timeseries.csv")
    save_checkpoint_now()
    from .plots import plot_droplets, plot_time_series

    n = sim.store.count
    plot_time_series(out, f"{case.case.name}: fulldem")
    plot_droplets(out / "droplets.png", sim.store.position[:n], sim.store.diameter[:n], sim.store.velocity[:n],
                  sim.lower, sim.upper, f"{case.case.name} at t = {sim.time:.3g} s: {n} droplets")
    summary = {"end_time": sim.time, "steps": sim.steps, "droplets": sim.store.count, **vars(sim.counters)}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1))
    log(f"done: t = {sim.time:.6g} s, {sim.store.count} droplets in the slag; outputs in {out} "
        f"(timeseries.csv and timeseries.png, droplets.png, snapshots.pvd for ParaView, checkpoint.npz)")
    return frame
