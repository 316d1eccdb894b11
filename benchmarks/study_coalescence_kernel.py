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
from fulldem.cases.bidisperse import bidisperse_suspension
from fulldem.droplets import COALESCING
from fulldem.submodels.coalescence import size_bin


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
    box, d_l, d_s = (0.05, 0.05, 0.08), 1.5e-3, 0.5e-3
    extra = [f"coalescence.mode={args.mode}", f"coalescence.trigger={args.trigger}"]
    if args.growth_rate is not None:
        extra.append(f"coalescence.growth_rate={args.growth_rate}")
    sim, (lo, hi) = bidisperse_suspension(args.large, args.small, box, large_bottom=0.05, large_diameter=d_l,
                                          small_diameter=d_s, seed=args.seed, extra=extra)
    case = sim.case
    n_large_placed = int((sim.store.diameter[: sim.store.count] == d_l).sum())
    n_small_placed = sim.store.count - n_large_placed
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
          f"{n_large_placed} x 1.5 mm through {n_small_placed} x 0.5 mm, {args.end_time:g} s: large-small merges {got}, "
          f"ballistic kernel {expected:.1f} ({got / expected - 1:+.1%}); all merges {sim.counters.merges}, pairs marked "
          f"{sim.counters.marks}, still marked {marked}; most pairs waiting past their growth time {waiting}, longest "
          f"marked {longest:.3f} s; wall {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
