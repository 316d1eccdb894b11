"""Speed of the reduced model (popbal): wall time of a 60 s simple-case run and of a full-size settler run.

    python benchmarks/bench_popbal.py [--repeat N]

The first run of each case pays Numba's compilation (or cache load); the figures are the best of N runs after it.
Targets from the issue: simple case, 60 simulated seconds, under 1 s; furnace (one 6 h slag residence), under 10 s.
A figure, not a timed test: the machine is shared, so the numbers vary from run to run.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import popbal

CASES = [
    ("simple", {}, "simple case, 60 s simulated", 1.0),
    ("cubic", {}, "cubic case, 60 s simulated", None),
    ("deep", {}, "deep case (coalescence + reaction), 60 s simulated", None),
    ("furnace", {}, "full-size settler, one slag residence time (6 h)", 10.0),
]


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per case (best is reported)")
    args = parser.parse_args(argv)
    print(f"popbal benchmark on {_cpu()}, {os.cpu_count()} logical CPUs, Python {platform.python_version()}")
    print(f"{'case':<52s} {'first run':>10s} {'best run':>10s} {'steps':>7s} {'target':>8s}")
    for name, overrides, label, target in CASES:
        model = popbal.setup(name, overrides)
        started = time.perf_counter()
        popbal.run(model, progress=False)
        first = time.perf_counter() - started
        best, result = min(((r.wall_time, r) for r in (popbal.run(model, progress=False)
                                                         for _ in range(args.repeat))), key=lambda x: x[0])
        verdict = "" if target is None else (f"< {target:g} s" + ("" if best < target else " MISSED"))
        print(f"{label:<52s} {first:>9.2f}s {best:>9.2f}s {result.steps:>7d} {verdict:>8s}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
