"""Wall seconds per simulated second of a fed case at steady state, with per-phase timers, in a few minutes.

Not a test: prints figures. Starts from the last stored snapshot of a reference run (``data/reference/<case>``: the
droplets' positions, velocities, sizes, densities, ages and merged flags, float32), with the run's own case, the
feed on and the preset's fluid step (``fulldem.fluid_step`` of ``data/cases/<case>.toml``, 4 ms; the stored runs were
made at 2 ms, which ``--override fulldem.fluid_step=0.002`` times), the slag at rest (pairs overlapping by more than 2 % marked again as coalescing partners: the snapshot
does not keep the marks); warms up until the slag's flow has built up again around the droplets (by default in
blocks of 100 fluid steps until the slag's mean squared velocity changes by less than ``--settle`` over a block:
about 600 steps, 2.4 s simulated, for simple; or a fixed ``--warmup``), then times ``--steps`` more. Prints the wall seconds per simulated second (the mean wall time of a
``Simulation.step`` over the fluid step dt), the droplet count, the share of droplets in free flight, the slag's
largest speed at the end of the warm-up and of the timed steps, the threads, the load average and the peak memory,
and a table of every phase of the step (``fulldem.tuning.PhaseTimes``: what runs between two laps in
``Simulation.step``) in ms per step; the phases sum to the measured step time (the difference is printed).

What is left out: the driver's output rows, progress bar, snapshots and checkpoints (a few ms per step; in a run
they come on top), and compilation (the first step compiles where no cache exists; it is in the warm-up).

    python benchmarks/bench_steady.py                      # simple, 2 threads: about 5 minutes on 2 cores
    python benchmarks/bench_steady.py --case deep --threads 2
    python benchmarks/bench_steady.py --warmup 300 --steps 50 --override coalescence.trigger=first_contact
    python benchmarks/bench_steady.py --warmup 350 --steps 150 --skin-max 1   # inside the fast window, the old skin

The machine is shared and noisy: compare figures of one sitting, and read the load average printed at the end.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import numba
import numpy as np
from scipy.spatial import cKDTree

import fulldem.tuning
from fulldem.droplets import COALESCING, MERGED, DropletStore
from fulldem.stepper import Simulation
from settler.cases import load_case

REFERENCE = Path(__file__).resolve().parents[1] / "data" / "reference"


def steady_simulation(name, overrides=()):
    """A Simulation of reference run ``name`` (a folder of data/reference) started from its last snapshot."""
    folder = REFERENCE / name
    case = load_case(str(folder / "case.toml"), list(overrides))
    with np.load(folder / "snapshots.npz") as z:
        key = f"t{len(z['times']) - 1}_"
        fields = {k[len(key):]: np.asarray(z[k], dtype=float) for k in z.files if k.startswith(key)}
        t_snapshot = float(z["times"][-1])
    n = fields["diameter"].size
    store = DropletStore(max(4096, 2 * n))
    store.add(fields["position"], fields["diameter"], fields["density"], velocity=fields["velocity"],
              age=fields["age"], flags=np.where(fields["merged"] > 0.5, MERGED, 0))
    # the snapshot does not keep the coalescence marks: pairs overlapping by more than 2 % of their contact distance
    # (none of the contacts' design overlap of 1 %) are the marked pairs, marked again so that they grow and merge
    # instead of pushing each other apart
    x, d = store.position[:n], store.diameter[:n]
    i, j = cKDTree(x).query_pairs(float(d.max()), output_type="ndarray").T
    marked = np.linalg.norm(x[i] - x[j], axis=1) < 0.98 * 0.5 * (d[i] + d[j])
    i, j = i[marked], j[marked]
    # a droplet in two such pairs (a dense bed) keeps its deepest one; the others push apart as unmarked contacts
    depth = np.linalg.norm(x[i] - x[j], axis=1) / (0.5 * (d[i] + d[j]))
    taken = np.zeros(n, dtype=bool)
    chosen = []
    for k in np.argsort(depth, kind="stable"):
        if not (taken[i[k]] or taken[j[k]]):
            taken[i[k]] = taken[j[k]] = True
            chosen.append(k)
    if len(chosen) < i.size:
        print(f"{name}: {i.size - len(chosen)} of {i.size} pairs overlapping by more than 2 % share a droplet with a "
              f"deeper one and are left unmarked")
    i, j = i[chosen], j[chosen]
    store.partner[i], store.partner[j] = j, i
    store.flags[i] |= COALESCING
    store.flags[j] |= COALESCING
    sim = Simulation(case, droplets=store)
    return sim, t_snapshot


def slag_speed(sim) -> float:
    """The slag's largest speed component on the grid [m/s]."""
    return max(float(np.abs(a).max()) for a in (sim.fluid.u, sim.fluid.v, sim.fluid.w))


def slag_energy(sim) -> float:
    """The slag's mean squared velocity over the faces [m^2/s^2] (a smoother measure of the flow than its peak)."""
    return float(sum(np.mean(a * a) for a in (sim.fluid.u, sim.fluid.v, sim.fluid.w)))


def warm_up(sim, steps, settle, most, block=100) -> int:
    """Step ``sim`` ``steps`` fluid steps, or, with ``steps`` = 0, in blocks of ``block`` until the slag's mean
    squared velocity changed by less than ``settle`` (relative) over the last block, at most ``most`` steps. Prints
    a line per block (steps, simulated time, slag flow, wall time per step, free-flight share); returns the steps."""
    done, energy = 0, slag_energy(sim)
    while True:
        size = min(block, steps - done) if steps else block
        t0 = time.perf_counter()
        for _ in range(size):
            sim.step()
        done += size
        now = slag_energy(sim)
        change = abs(now - energy) / max(now, 1e-300)
        print(f"  warm-up {done:5d} steps ({done * sim.dt:5.2f} s): slag rms speed {1e3 * np.sqrt(now / 3):6.1f} mm/s, "
              f"peak {1e3 * slag_speed(sim):6.1f} mm/s (energy {change:+.1%} over the block), "
              f"{1e3 * (time.perf_counter() - t0) / size:6.1f} ms/step, free flight {sim.last['free_fraction']:.0%}",
              flush=True)
        energy = now
        if (steps and done >= steps) or (not steps and (change < settle or done >= most)):
            return done


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="simple", help="reference run in data/reference (default simple)")
    parser.add_argument("--warmup", type=int, default=0,
                        help="fluid steps before timing (default 0: until the slag's flow has settled, --settle)")
    parser.add_argument("--settle", type=float, default=0.03,
                        help="the warm-up ends once the slag's mean squared velocity changes by less than this "
                             "(relative) over 100 steps (default 0.03)")
    parser.add_argument("--max-warmup", type=int, default=2000, help="most warm-up steps (default 2000)")
    parser.add_argument("--steps", type=int, default=150, help="timed fluid steps (default 150)")
    parser.add_argument("--threads", type=int, default=2, help="Numba threads (default 2)")
    parser.add_argument("--override", action="append", default=[], help="KEY=VALUE for the case (repeatable)")
    parser.add_argument("--skin-max", type=float, default=None,
                        help="what-if: the neighbour-list skin's cap in feed diameters (fulldem.tuning.SKIN_MAX, "
                             f"default {fulldem.tuning.SKIN_MAX:g}); changes results at round-off and free flight's "
                             "choices, so it is a measurement, not a setting")
    args = parser.parse_args(argv)
    if args.skin_max is not None:
        if not args.skin_max >= fulldem.tuning.SKIN_MIN:
            parser.error(f"--skin-max {args.skin_max}: must be at least SKIN_MIN = {fulldem.tuning.SKIN_MIN:g}")
        fulldem.tuning.SKIN_MAX = args.skin_max  # read by fulldem.tuning.skin_for at each sort
    numba.set_num_threads(min(args.threads, numba.config.NUMBA_NUM_THREADS))

    # the engine's fluid step, not the stored run's (the reference runs were made at 2 ms, the preset is 4 ms since
    # the speed issue's evidence, benchmarks/study_fluid_step.py): what a run of today's engine costs
    overrides = [f"fulldem.fluid_step={load_case(args.case).fulldem.fluid_step!r}", *args.override]
    sim, t_snapshot = steady_simulation(args.case, overrides)
    print(f"{args.case}: {sim.store.count} droplets from the snapshot at t = {t_snapshot:g} s, grid "
          f"{tuple(sim.grid.shape)}, dt {sim.dt:g} s, {sim.substeps} DEM sub-steps, {numba.get_num_threads()} threads, "
          f"skin cap {fulldem.tuning.SKIN_MAX:g} feed diameters")
    start = time.perf_counter()
    warm = warm_up(sim, args.warmup, args.settle, args.max_warmup)
    speed_warm = slag_speed(sim)
    print(f"warm-up: {warm} steps ({warm * sim.dt:g} s simulated) in {time.perf_counter() - start:.1f} s "
          f"(compilation included), slag speed up to {1e3 * speed_warm:.1f} mm/s")

    sim.phase_times.reset()
    count0, walls, free = sim.store.count, [], []
    for _ in range(args.steps):
        t0 = time.perf_counter()
        sim.step()
        walls.append(time.perf_counter() - t0)
        free.append(sim.last["free_fraction"])
    walls = np.array(walls)
    speed_end = slag_speed(sim)
    per_step = float(walls.mean())
    phases = sim.phase_times
    print(f"\ntimed: {args.steps} steps, droplets {count0} -> {sim.store.count}, free flight {np.mean(free):.1%} of "
          f"droplets, slag speed up to {1e3 * speed_end:.1f} mm/s")
    print(f"{'phase':<34}{'ms/step':>9}{'share':>8}")
    for name, seconds in sorted(phases.seconds.items(), key=lambda kv: -kv[1]):
        print(f"{name:<34}{1e3 * seconds / phases.steps:9.2f}{seconds / phases.steps / per_step:8.1%}")
    print(f"{'sum of phases':<34}{1e3 * phases.total() / phases.steps:9.2f}"
          f"{phases.total() / phases.steps / per_step:8.1%}")
    print(f"{'measured step':<34}{1e3 * per_step:9.2f}  (median {1e3 * np.median(walls):.2f}, "
          f"slowest {1e3 * walls.max():.2f})")
    print(f"\nwall time per simulated second: {per_step / sim.dt:.1f} s  ({args.case}, {numba.get_num_threads()} "
          f"threads, {sim.store.count} droplets; particle-steps per second "
          f"{0.5 * (count0 + sim.store.count) / per_step:.3g})")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory {peak:.0f} MiB; load average {os.getloadavg()[0]:.2f} (1 min) on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
