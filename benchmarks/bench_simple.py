"""Wall time per simulated second of the fed simple case itself, read from a real run.

Not a test: prints figures. Runs ``settler full simple`` (the seed paper's simple model: 0.2 m cube, stagnant slag,
0.0086 kg/s of matte fed over the 150 mm inlet) from t = 0 to ``--end-time`` and reads the run's ``wall_time``
column (settler.output.TIME_SERIES): the wall time per simulated second over windows of ``--window`` seconds, with
the droplet count at each window's start and end. The row that holds the paper's steady count (about 130 000
droplets in the simple model) is marked.

There is no steady state to measure yet: the paper's count is steady because droplets coalesce, which is not in the
engine yet, so the count here keeps rising at the feed rate (about 25 000 droplets/s) and nothing has settled by
t = 10 s. The window around 130 000 droplets is the run at the paper's steady count on its way up. Compilation
(first step) and the snapshot writes every simulated second are included, as a user would see them.

The machine is shared and noisy; the 1-minute load average is printed at the end.

    python benchmarks/bench_simple.py                          # to t = 5.5 s, about 6 minutes on 2 cores
    python benchmarks/bench_simple.py --end-time 7 --out runs/bench_simple
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

import numba

from fulldem.driver import run_case
from settler.cases import load_case
from settler.output import read_time_series

#: The paper's steady droplet count in the simple model (Jylha & Jokilaakso 2023, section 4.1).
PAPER_STEADY_COUNT = 130_000


def windows(frame, width):
    """(t0, t1, count0, count1, wall seconds per simulated second) over consecutive windows of ``width`` [s]."""
    rows = []
    t0 = float(frame["time"].iloc[0])
    end = float(frame["time"].iloc[-1])
    while t0 + width <= end + 1e-9:
        a = frame[(frame["time"] - t0).abs() < 1e-9]
        b = frame[(frame["time"] - (t0 + width)).abs() < 1e-9]
        if len(a) and len(b):
            a, b = a.iloc[0], b.iloc[0]
            rate = (b["wall_time"] - a["wall_time"]) / (b["time"] - a["time"])
            rows.append((a["time"], b["time"], int(a["droplet_count"]), int(b["droplet_count"]), rate))
        t0 += width
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--end-time", type=float, default=5.5, help="simulated time to run to [s] (default 5.5)")
    parser.add_argument("--window", type=float, default=0.5, help="width of the reported windows [s] (default 0.5)")
    parser.add_argument("--out", default=None, help="run folder (default: a temporary one, removed afterwards); a run already there "
                        "is resumed from its checkpoint")
    parser.add_argument("--case-override", action="append", default=[], help="KEY=VALUE for the simple case")
    args = parser.parse_args(argv)
    case = load_case("simple", args.case_override)  # time-series rows every 0.1 s (fulldem.output_interval)
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(args.out) if args.out else Path(scratch) / "simple"
        resume = (out / "checkpoint.npz").exists()
        run_case(case, out, end_time=args.end_time, resume=resume, progress=True, log=print)
        frame = read_time_series(out / "timeseries.csv")
    print(f"\nfed simple case, {numba.get_num_threads()} threads; wall time per simulated second by window "
          f"(compilation and snapshots included):")
    print(f"{'t from':>7} {'to':>6} {'droplets from':>14} {'to':>8} {'s per sim s':>12}")
    for t0, t1, c0, c1, rate in windows(frame, args.window):
        mark = "  <- the paper's steady count" if c0 <= PAPER_STEADY_COUNT <= c1 else ""
        print(f"{t0:7.2f} {t1:6.2f} {c0:14d} {c1:8d} {rate:12.1f}{mark}")
    print(f"load average (1 min) at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
