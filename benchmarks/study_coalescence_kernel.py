"""Study (not a timed benchmark): merges in dilute bidisperse settling against the ballistic kernel.

    python benchmarks/study_coalescence_kernel.py                         # delayed, every contact: about 20 s
    python benchmarks/study_coalescence_kernel.py --mode instantaneous
    python benchmarks/study_coalescence_kernel.py --trigger first_contact --growth-rate 6

N_large droplets of 1.5 mm (default 800) start above z = 30 mm in a closed 60 x 60 x 80 mm box of the simple
case's slag (0.9 % of the volume they start in) and fall through N_small droplets of 0.5 mm (default 2060) spread
through it (4.7 mm/s apart; 5 mm cells, 2 ms fluid steps); every contact may merge (coalescence.threshold = 0, size
limit 5 mm). The expected number of large-small contacts is the ballistic kernel pi (a_l + a_s)^2 |dU| n_s N_l
integrated over the run with the counts, radii and velocities the run itself has at each step
(fulldem.cases.bidisperse.settle_against_ballistic_kernel: dU from the droplets' velocities relative to the slag
they feel, and, printed beside it, from their absolute velocities). A delayed merge completes its growth time after
the contact (0.314 s for this pair at growth_rate 2), so its merges at the end are compared with the contacts
expected by the end less that time. Prints the merges counted between the two size bins (merges_by_size), their
ratio to the expectation, the large-small merges by the end less the growth time (what a delayed run of the same
contacts would have completed), the pairs marked and still marked at the end, the most pairs waiting past their
growth time at any step and the longest a pair was marked. Issue 19's figures come from it; the default set-up is
tests/test_fulldem_coalescence.py's.
"""

from __future__ import annotations

import argparse
import time

from fulldem.cases.bidisperse import at_time, bidisperse_suspension, growth_time, settle_against_ballistic_kernel
from fulldem.droplets import COALESCING


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mode", choices=["delayed", "instantaneous"], default="delayed")
    parser.add_argument("--trigger", choices=["first_contact", "every_contact"], default="every_contact")
    parser.add_argument("--large", type=int, default=800, help="droplets of 1.5 mm")
    parser.add_argument("--small", type=int, default=2060, help="droplets of 0.5 mm")
    parser.add_argument("--end-time", type=float, default=4.0, help="simulated time [s]")
    parser.add_argument("--growth-rate", type=float, default=None,
                        help="coalescence.growth_rate [1/s] (default: the case's)")
    parser.add_argument("--box", type=float, nargs=3, default=(0.06, 0.06, 0.08), metavar=("X", "Y", "Z"),
                        help="closed box [m]")
    parser.add_argument("--large-bottom", type=float, default=0.03, help="lowest start of a large droplet [m]")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    box, d_l, d_s = tuple(args.box), 1.5e-3, 0.5e-3
    extra = [f"coalescence.mode={args.mode}", f"coalescence.trigger={args.trigger}"]
    if args.growth_rate is not None:
        extra.append(f"coalescence.growth_rate={args.growth_rate}")
    sim, (lo, hi) = bidisperse_suspension(args.large, args.small, box, large_bottom=args.large_bottom, large_diameter=d_l,
                                          small_diameter=d_s, seed=args.seed, extra=extra)
    case = sim.case
    n_large_placed = int((sim.store.diameter[: sim.store.count] == d_l).sum())
    n_small_placed = sim.store.count - n_large_placed
    start = time.perf_counter()
    result = settle_against_ballistic_kernel(sim, (lo, hi), args.end_time, large_diameter=d_l, small_diameter=d_s)
    lag = growth_time(case, d_l, d_s) if args.mode == "delayed" else 0.0
    got = int(result["merged"][-1])
    expected, absolute = (at_time(result, k, args.end_time - lag) for k in ("expected", "expected_absolute"))
    marked = int(((sim.store.flags[: sim.store.count] & COALESCING) != 0).sum()) // 2
    print(f"mode {args.mode}, trigger {args.trigger}, growth_rate {case.coalescence.growth_rate} 1/s, "
          f"{n_large_placed} x 1.5 mm through {n_small_placed} x 0.5 mm, {args.end_time:g} s: large-small merges {got}; "
          f"ballistic kernel to t - {lag:.3f} s (the growth time) {expected:.1f} ({got / expected - 1:+.1%}; with "
          f"absolute velocities {absolute:.1f}, {got / absolute - 1:+.1%}); large-small merges by t - "
          f"{growth_time(case, d_l, d_s):.3f} s {at_time(result, 'merged', args.end_time - growth_time(case, d_l, d_s))}; all merges {sim.counters.merges}, "
          f"pairs marked {sim.counters.marks}, still marked {marked}; most pairs waiting past their growth time "
          f"{result['waiting']}, longest marked {result['longest']:.3f} s; wall {time.perf_counter() - start:.0f} s")

if __name__ == "__main__":
    main()
