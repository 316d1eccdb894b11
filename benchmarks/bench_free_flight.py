"""Free flight (fulldem.dem, *Free flight*) against every droplet sub-stepped, from a run's checkpoint.

Not a test: prints figures. Two simulations are restored from the same checkpoint of a fulldem run folder (its
``case.toml`` and ``checkpoint.npz``), one with free flight (the default) and one with ``dem.free_flight = False``,
and stepped alternately, so that both see the same machine load: the median wall time of a fluid step and of its
DEM advance for each, their ratio, the fraction of droplets in free flight, and the free-flight counts (breaches,
redone advances). Then the two runs' droplet count, mean diameter, merges and exits after the steps: they agree if
free flight changes nothing but round-off, which the contacts then amplify (a chaotic many-body system), so the
two runs drift apart statistically, not systematically.

The machine is shared and noisy: compare the ratios, not absolute times; the 1-minute load average is printed.

    NUMBA_NUM_THREADS=1 python benchmarks/bench_free_flight.py runs/simple --steps 50
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from fulldem.driver import restore_state
from fulldem.io.checkpoint import load_checkpoint
from fulldem.stepper import Simulation
from settler.cases import load_case


def restored(folder: Path, free_flight: bool) -> Simulation:
    """A simulation of the run in ``folder`` at its checkpoint, with free flight on or off."""
    sim = Simulation(load_case(folder / "case.toml"))
    arrays, meta = load_checkpoint(folder / "checkpoint.npz")
    restore_state(sim, arrays, meta)
    sim.dem.free_flight = free_flight
    return sim


def timed_dem(sim: Simulation) -> list:
    """Wrap ``sim.dem.advance`` so that each call's wall time [s] is appended to the returned list."""
    times = []
    advance = sim.dem.advance

    def timed(*args):
        start = time.perf_counter()
        try:
            return advance(*args)
        finally:
            times.append(time.perf_counter() - start)

    sim.dem.advance = timed
    return times


def summary(sim: Simulation) -> dict:
    """Droplet count, mean diameter [mm], merges, settled and lost droplets of a simulation now."""
    s, n = sim.store, sim.store.count
    c = sim.counters
    return {"droplets": n, "mean_diameter_mm": float(np.mean(s.diameter[:n])) * 1e3, "merges": c.merges,
            "settled": c.settled, "lost": c.lost, "fed": c.fed}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a fulldem run folder holding case.toml and checkpoint.npz")
    parser.add_argument("--steps", type=int, default=20, help="fluid steps each simulation takes (default 20)")
    parser.add_argument("--warm-up", type=int, default=2,
                        help="fluid steps each takes first, not timed (compilation, list set-up; default 2)")
    args = parser.parse_args(argv)
    sims = {"free flight": restored(args.run, True), "sub-stepped": restored(args.run, False)}
    first = next(iter(sims.values()))
    print(f"{args.run}: t = {first.time:.3f} s, {first.store.count} droplets, dt = {first.dt} s, "
          f"{first.substeps} DEM sub-steps")
    for _ in range(args.warm_up):
        for sim in sims.values():
            sim.step()
    step_times = {name: [] for name in sims}
    dem_times = {name: timed_dem(sim) for name, sim in sims.items()}
    fractions = []
    for _ in range(args.steps):  # alternately, so both see the same load
        for name, sim in sims.items():
            start = time.perf_counter()
            sim.step()
            step_times[name].append(time.perf_counter() - start)
        fractions.append(sims["free flight"].last["free_fraction"])
    median = {name: (statistics.median(step_times[name]), statistics.median(dem_times[name])) for name in sims}
    print(f"{'':>12} {'step [s]':>9} {'DEM [s]':>8}   (medians over {args.steps} fluid steps)")
    for name, (step, dem) in median.items():
        print(f"{name:>12} {step:9.3f} {dem:8.3f}")
    (step_free, dem_free), (step_sub, dem_sub) = median.values()
    print(f"ratio sub-stepped / free flight: step {step_sub / step_free:.2f}, DEM advance {dem_sub / dem_free:.2f}")
    print(f"free fraction: mean {np.mean(fractions):.3f}, min {np.min(fractions):.3f}")
    print(f"free-flight counts: {sims['free flight'].dem.free_flight_counts.as_dict()}")
    print(f"after {args.steps + args.warm_up} steps (t = {first.time:.3f} s):")
    for name, sim in sims.items():
        print(f"  {name:>12}: {summary(sim)}")
    print(f"load average (1 min) at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
