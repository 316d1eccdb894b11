"""Study (not a timed benchmark): merges in dilute bidisperse settling against the ballistic kernel.

    python benchmarks/study_coalescence_kernel.py --mode delayed --trigger first_contact
    python benchmarks/study_coalescence_kernel.py --mode instantaneous --end-time 6

N_large droplets of 1.5 mm start in the upper part of a closed 50 x 50 x 80 mm box of the simple case's slag and fall
through N_small droplets of 0.5 mm spread through it (5.5 mm/s apart; 5 mm cells, 2 ms fluid steps); every contact
may merge (coalescence.threshold = 0, size limit 5 mm). Each fluid step adds pi (a_l + a_s)^2 |U_l - U_s| n_s N_l dt
to the expected number of large-small merges, with the mean velocities and counts the run itself has at that step
and n_s the small droplets over the volume they fill. Prints the merges counted between the two size bins
(merges_by_size), their ratio to the expectation, the pairs marked and still marked at the end, the most pairs
waiting past their growth time at any step and the longest a pair was marked. Issue 19's figures come from it.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
from scipy.spatial import cKDTree

from fulldem.droplets import COALESCING, DropletStore
from fulldem.stepper import Simulation
from fulldem.submodels.coalescence import size_bin
from settler.cases import load_case


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mode", choices=["delayed", "instantaneous"], default="delayed")
    parser.add_argument("--trigger", choices=["first_contact", "every_contact"], default="first_contact")
    parser.add_argument("--large", type=int, default=300, help="droplets of 1.5 mm")
    parser.add_argument("--small", type=int, default=4000, help="droplets of 0.5 mm")
    parser.add_argument("--end-time", type=float, default=3.0, help="simulated time [s]")
    parser.add_argument("--growth-rate", type=float, default=None, help="coalescence.growth_rate [1/s] (default: the case's)")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    box, d_l, d_s, margin = (0.05, 0.05, 0.08), 1.5e-3, 0.5e-3, 2e-3
    overrides = ["feed.mass_rate=0", "fulldem.cell_size=0.005", "fulldem.fluid_step=0.002", "coalescence.threshold=0",
                 "coalescence.size_limit=5e-3", f"coalescence.mode={args.mode}", f"coalescence.trigger={args.trigger}"]
    if args.growth_rate is not None:
        overrides.append(f"coalescence.growth_rate={args.growth_rate}")
    case = load_case("simple", overrides)
    rng = np.random.default_rng(args.seed)
    lo, hi = np.array([margin, margin, 0.005]), np.array(box) - margin
    large = []
    for p in rng.uniform([margin, margin, 0.05], hi, size=(10 * args.large, 3)):
        if not large or np.min(np.linalg.norm(np.array(large) - p, axis=1)) > 1.05 * d_l:
            large.append(p)
        if len(large) == args.large:
            break
    small = rng.uniform(lo, hi, size=(3 * args.small, 3))
    small = small[[not cKDTree(large).query_ball_point(p, 1.05 * (d_l + d_s) / 2) for p in small]]
    crowded = {j for _, j in cKDTree(small).query_pairs(1.05 * d_s)}
    small = np.array([p for k, p in enumerate(small) if k not in crowded])[: args.small]
    store = DropletStore(2 * (len(large) + len(small)))
    store.add(np.vstack([large, small]), np.r_[np.full(len(large), d_l), np.full(len(small), d_s)], 5100.0)
    sim = Simulation(case, droplets=store, feed=False, box=(box, (0.0, 0.0, 0.0)))
    coalescence = next(m for m in sim.submodels if m.name == "coalescence")
    bin_l, bin_s = size_bin(d_l), size_bin(d_s)
    volume = float(np.prod(hi - lo))
    expected, waiting, longest = 0.0, 0, 0.0
    start = time.perf_counter()
    while sim.time < args.end_time - 1e-12:
        s, n = sim.store, sim.store.count
        bins = size_bin(s.diameter[:n])
        is_l, is_s = bins == bin_l, bins == bin_s
        if is_l.any() and is_s.any():
            du = abs(s.velocity[:n, 2][is_l].mean() - s.velocity[:n, 2][is_s].mean())
            a = 0.5 * (s.diameter[:n][is_l].mean() + s.diameter[:n][is_s].mean())
            expected += math.pi * a**2 * du * is_s.sum() / volume * is_l.sum() * sim.dt
        sim.step()
        columns = coalescence.columns(sim)
        waiting, longest = max(waiting, columns["pairs_waiting"]), max(longest, columns["longest_marked"])
    got = int(sim.counters.merges_by_size[min(bin_l, bin_s), max(bin_l, bin_s)])
    marked = int(((sim.store.flags[: sim.store.count] & COALESCING) != 0).sum()) // 2
    print(f"mode {args.mode}, trigger {args.trigger}, growth_rate {case.coalescence.growth_rate} 1/s, "
          f"{len(large)} x 1.5 mm through {len(small)} x 0.5 mm, {args.end_time:g} s: large-small merges {got}, "
          f"ballistic kernel {expected:.1f} ({got / expected - 1:+.1%}); all merges {sim.counters.merges}, pairs marked "
          f"{sim.counters.marks}, still marked {marked}; most pairs waiting past their growth time {waiting}, longest "
          f"marked {longest:.3f} s; wall {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
