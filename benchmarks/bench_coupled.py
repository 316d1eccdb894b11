"""Coupled CFD-DEM throughput: particle-steps per second, wall time per simulated second, memory.

Not a test: prints figures. The set-up is the seed paper's simple model (0.2 m cube, 5 mm grid, 150 mm inlet)
with N droplets of the feed distribution placed without overlap in the cylinder under the inlet (the channel
region where the paper's droplets are), the feed switched off so N stays fixed, and the case's default fluid and
DEM steps. Throughput = N x DEM sub-steps / wall time of the coupled loop (fluid step, coupling and DEM together;
set-up, compilation and the first step excluded). Wall time per simulated second = loop time / simulated time:
at N = 130 000 (the paper's steady count in the simple model) it stands in for the steady-state cost of the
simple case. It is an optimistic stand-in: a fed run also inserts droplets, re-sorts them and rebuilds the
neighbour list every step; ``benchmarks/bench_simple.py`` measures the fed case itself.

The machine is shared and noisy: compare ratios within one run, not absolute times across runs; the minimum and
median fluid-step times and the 1-minute load average are printed for that reason.

    python benchmarks/bench_coupled.py                 # 10 000 and 130 000 droplets, both coupling kernels
    python benchmarks/bench_coupled.py --n 20000 --steps 10 --case-override fulldem.contact_steps=20

The direct kernel runs with ``fulldem.near_wall = "interior"`` (its only form); the filtered kernel with the case's
``near_wall`` ("wall", the default since d16308b, interpolates the walls' zero normal velocity in a second pass;
``--case-override fulldem.near_wall=interior`` times both kernels alike).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import time

import numpy as np

from fulldem.droplets import DropletStore
from fulldem.stepper import Simulation
from settler.cases import load_case
from settler.physics import sample_scale_factors


def place_in_channel(n, case, rng):
    """n non-overlapping droplets of the feed distribution, uniform in the cylinder under the inlet."""
    g, f = case.geometry, case.feed
    diameters = f.mean_diameter * sample_scale_factors(rng, n, f.scale_std, f.scale_min, f.scale_max)
    cx, cy = case.inlet_center
    radius = 0.5 * g.inlet_diameter - 1e-3
    cell = 1.05 * diameters.max()
    grid = {}
    out = np.empty((n, 3))
    placed = 0
    while placed < n:
        r = radius * np.sqrt(rng.uniform())
        t = rng.uniform(0, 2 * np.pi)
        p = np.array([cx + r * np.cos(t), cy + r * np.sin(t), rng.uniform(0.01, g.height - 0.005)])
        key = tuple((p // cell).astype(int))
        ok = True
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    for q in grid.get((key[0] + dx, key[1] + dy, key[2] + dz), ()):
                        if np.sum((out[q] - p) ** 2) < (0.5 * (diameters[q] + diameters[placed]) * 1.01) ** 2:
                            ok = False
        if ok:
            out[placed] = p
            grid.setdefault(key, []).append(placed)
            placed += 1
    return out, diameters


def bench(n, steps, overrides):
    case = load_case("simple", ["feed.mass_rate=0", "coalescence.enabled=false", *overrides])
    rng = np.random.default_rng(1)
    t0 = time.perf_counter()
    pos, diam = place_in_channel(n, case, rng)
    store = DropletStore(2 * n)
    store.add(pos, diam, case.matte.density)
    sim = Simulation(case, droplets=store, feed=False)
    sim.step()  # compilation and first neighbour build
    setup = time.perf_counter() - t0
    per_step = []
    for _ in range(steps):
        t1 = time.perf_counter()
        sim.step()
        per_step.append(time.perf_counter() - t1)
    loop = sum(per_step)
    count = sim.store.count
    dem_steps = steps * sim.substeps
    return {
        "n": n, "remaining": count, "substeps": sim.substeps, "dem_step": sim.dem_step, "fluid_step": sim.dt,
        "loop": loop, "setup": setup,
        "throughput": count * dem_steps / loop,
        "wall_per_sim_second": loop / (steps * sim.dt),
        "ms_per_fluid_step": 1e3 * loop / steps,
        "ms_min": 1e3 * min(per_step), "ms_median": 1e3 * float(np.median(per_step)),
        "load": os.getloadavg()[0],
        "overlap": sim.last["max_overlap_ratio"],
        "rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, nargs="*", default=[10_000, 130_000], help="droplet counts")
    parser.add_argument("--steps", type=int, default=10, help="timed fluid steps per size")
    parser.add_argument("--kernels", nargs="*", default=["filtered", "direct"], choices=["filtered", "direct"],
                        help="coupling kernels to time, each at every size, in this run (fulldem.kernel)")
    parser.add_argument("--case-override", nargs="*", default=[], metavar="section.key=value",
                        help="overrides of the simple case (e.g. fulldem.contact_steps=20)")
    args = parser.parse_args()
    print(f"coupled CFD-DEM benchmark on {platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}; shared machine: compare ratios within this run")
    print(f"{'kernel':>8} {'droplets':>9} {'substeps':>8} {'DEM step':>9} {'ms/fluid step':>13} {'(min, median)':>15} "
          f"{'particle-steps/s':>17} {'wall s / sim s':>14} {'max overlap':>11} {'peak RSS':>9} {'load':>5}")
    for n, kernel in [(n, k) for n in args.n for k in args.kernels]:
        # the direct kernel reads interior faces only near walls (its one form); the filtered kernel takes the case's
        # fulldem.near_wall ("wall" by default since d16308b; --case-override fulldem.near_wall=interior to match)
        walls = ["fulldem.near_wall=interior"] if kernel == "direct" else []
        r = bench(n, args.steps, [f"fulldem.kernel={kernel}", *walls, *args.case_override])
        print(f"{kernel:>8} {r['remaining']:>9d} {r['substeps']:>8d} {r['dem_step']:>9.3g} "
              f"{r['ms_per_fluid_step']:>13.1f} "
              f"{'(%.0f, %.0f)' % (r['ms_min'], r['ms_median']):>15} {r['throughput']:>17.3g} "
              f"{r['wall_per_sim_second']:>14.1f} {r['overlap']:>11.3g} {r['rss_gib']:>7.2f} GiB {r['load']:>5.2f}",
              flush=True)
    print("targets (issue): >= 2e7 particle-steps/s at 130 000 droplets; <= 100 s wall per simulated second of the "
          "simple case at steady state (measured on the fed case by benchmarks/bench_simple.py); DEM step >= 5e-5 s")


if __name__ == "__main__":
    main()
