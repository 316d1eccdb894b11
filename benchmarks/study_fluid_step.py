"""Study (not a timed benchmark): the evidence for the fluid step and neighbour-list skin of the speed issue.

    python benchmarks/study_fluid_step.py --runs runs/fluid_step              # 4 runs, about 8 min each
    python benchmarks/study_fluid_step.py --runs runs/fluid_step --parallel 2 # two at a time (one thread each)
    python benchmarks/study_fluid_step.py --runs runs/fluid_step --summary    # table only

Runs the demo case to 25 s (``settler full demo --end-time 25``, one Numba thread each) at ``fulldem.fluid_step``
2 ms and 4 ms, each with two feed seeds (the seed scatter the difference is judged against), and prints the table of
:func:`study_coalescence_sensitivity.summary` over the window 15-25 s: the mean droplet count, merges per second,
the mean diameter, the slag's axis velocity and the merges refused by the size limit per second (written to
``fluid_step.csv`` in the runs folder). A run whose folder already holds a time series to the end time is not rerun;
one that stopped is resumed (``--resume``).

With ``--parallel 2`` two runs share the machine at one thread each (OMP_WAIT_POLICY=passive); their wall times are
then not a speed measurement (``benchmarks/bench_steady.py`` is).

Measured at the commit that made 4 ms the default (2026-12-03, two runs at a time, one thread each; window 15-25 s):

    run          count   merges/s  mean d [mm]  axis [mm/s]  refused/s  wall
    dt2         22 397    4 263      0.555        60.69        4 050    421 s
    dt2 seed 2  22 296    4 240      0.555        60.81        4 030    418 s
    dt4         22 414    4 257      0.555        60.42        2 100    337 s
    dt4 seed 2  21 954    4 254      0.555        60.54        1 758    335 s

At 2 ms the figures are those of the coalescence issue's runs at 4a017fb to the last digit printed (the skin's cap,
raised from 1 to 2 feed diameters with this change, is not reached in the demo). Over 2 -> 4 ms: the count's mean
moves -0.7 % (seed scatter 0.5 % at 2 ms, 2.1 % at 4 ms), merges per second -0.1 %, the mean diameter not at all,
the axis velocity -0.45 % (-0.27 mm/s, beyond the two seeds' 0.12 mm/s but a small part of any comparison the
runs serve). The merges refused by the size limit halve because a resting pair over the limit is refused, and
counted, at every fluid step (``coalescence.trigger = "every_contact"``): a count of evaluations, not of physics.
The verification report's checks set their own fluid steps (10 ms for the suspensions, 0.7 of the viscous limit
for the clouds) and do not change.
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from study_coalescence_sensitivity import _read, run_variant, write_table  # noqa: E402

SEED_2 = "feed.seed=20231030"
#: Run name -> case overrides (the demo otherwise at its defaults).
VARIANTS = {
    "dt2": ["fulldem.fluid_step=0.002"],
    "dt2_seed2": ["fulldem.fluid_step=0.002", SEED_2],
    "dt4": ["fulldem.fluid_step=0.004"],
    "dt4_seed2": ["fulldem.fluid_step=0.004", SEED_2],
}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True, help="folder of the runs, one sub-folder each")
    parser.add_argument("--only", nargs="+", choices=sorted(VARIANTS), help="these runs only")
    parser.add_argument("--end-time", type=float, default=25.0, help="simulated time of each run [s]")
    parser.add_argument("--parallel", type=int, default=1, help="runs at a time, one Numba thread each (default 1)")
    parser.add_argument("--summary", action="store_true", help="print the table of the runs found; run nothing")
    args = parser.parse_args(argv)
    names = args.only or list(VARIANTS)
    args.runs.mkdir(parents=True, exist_ok=True)
    if not args.summary:
        todo = [name for name in names
                if (f := _read(args.runs / name)) is None or f["time"].iloc[-1] < args.end_time - 1e-6]

        def one(name):
            rc = run_variant(args.runs / name, VARIANTS[name], args.end_time)
            if rc:
                print(f"{name}: stopped with exit code {rc} (see {args.runs / name}.log)", flush=True)

        with ThreadPoolExecutor(max(1, args.parallel)) as pool:
            list(pool.map(one, todo))
    write_table(args.runs, names, args.end_time, "fluid_step.csv")


if __name__ == "__main__":
    main()
