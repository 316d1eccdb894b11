"""Speed of a parameter sweep of the reduced model: N furnace points on a dask LocalCluster (analysis.sweep).

    python benchmarks/bench_sweep.py [--points 100] [--workers 2] [--resolution study|preset] [--out DIR]

Runs a Latin-hypercube design of ``--points`` points over the furnace study's box (analysis.sweep.FURNACE_AXES) from
the study's baseline (analysis.sweep.FURNACE_BASE, which since popbal's pair lists (b43d4c6) runs at the furnace
preset's own resolution; ``--resolution preset`` sets the preset's 100 cells, 30 s steps and 3 sections per doubling
explicitly, the same points today) into a fresh folder, so no point is resumed, and prints the wall time of
the whole sweep (cluster start, Numba warm-up, points, outputs), points per second, and the mean, median and
largest wall time of one point in its worker. Target from issue 13: 100 furnace points in under 2 minutes on the
project's 2-core machine. A figure, not a test: the machine is shared, so the load average before and after is
printed with it.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import tempfile
import time

from analysis.sweep import FURNACE_AXES, FURNACE_BASE, sweep
from settler.cases import case_with_overrides

#: The preset's own resolution (data/cases/furnace.toml and the property set), for --resolution preset.
PRESET_RESOLUTION = {"popbal.height_cells": 100, "popbal.time_step": 30.0, "popbal.sections_per_doubling": 3}
TARGET_SECONDS = 120.0


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"{one:.2f} {five:.2f} {fifteen:.2f}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100, help="design points (Latin hypercube), default 100")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="LocalCluster worker processes (default: the CPU count); 0: in this process")
    parser.add_argument("--resolution", choices=("study", "preset"), default="study",
                        help="study: the furnace study's baseline (analysis.sweep.FURNACE_BASE, default: since b43d4c6 "
                             "at the preset's resolution); preset: the furnace preset's 100 cells, 30 s, 3 sections "
                             "per doubling set explicitly (the same today)")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="sweep folder, which must not exist yet (default: a temporary folder, deleted after)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the design (default 1)")
    args = parser.parse_args(argv)
    if args.out is not None and os.path.exists(args.out):
        parser.error(f"--out {args.out}: exists; give a new folder, so that no point is resumed")
    overrides = {**FURNACE_BASE, **(PRESET_RESOLUTION if args.resolution == "preset" else {})}
    base = case_with_overrides("furnace", overrides)
    box = [f"{key}={low}:{high}" for key, (low, high, _) in FURNACE_AXES.items()]
    folder = args.out or tempfile.mkdtemp(prefix="bench_sweep_")
    print(f"sweep benchmark on {platform.processor() or platform.machine()}, {os.cpu_count()} logical CPUs, "
          f"Python {platform.python_version()}; load average before {_load()}")
    print(f"{args.points} furnace points ({args.resolution} resolution), {args.workers} workers, into {folder}")
    try:
        started = time.perf_counter()
        result = sweep(base, box, "lhs", args.points, out=folder, workers=args.workers, seed=args.seed)
        wall = time.perf_counter() - started
    finally:
        if args.out is None:
            shutil.rmtree(folder, ignore_errors=True)
    per_point = result.table["wall_time"]
    print(f"load average after {_load()}")
    print(f"wall time {wall:.1f} s for {len(result.table)} points ({result.failed} failed): "
          f"{len(result.table) / wall:.2f} points/s; target {TARGET_SECONDS:g} s for 100 points: "
          + ("met" if wall * 100 / len(result.table) < TARGET_SECONDS else "MISSED"))
    print(f"per point in its worker: mean {per_point.mean():.2f} s, median {per_point.median():.2f} s, "
          f"max {per_point.max():.2f} s (sum {per_point.sum():.1f} s over {args.workers or 1} process(es))")
    return 0 if not result.failed else 3


if __name__ == "__main__":
    raise SystemExit(main())
