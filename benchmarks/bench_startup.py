"""Seconds to a first answer: the wall time of the commands a new user types first, each a fresh process.

    python benchmarks/bench_startup.py [--repeat N]

Rows: ``settler --help``, ``settler full --help`` (loads the engine's arguments), ``settler info demo`` (loads
the case layer and Numba), ``settler figures data/reference/simple`` (draws every figure of a stored run) and
``settler reduced demo`` (60 s of the demo with popbal). Each is run N times after one untimed run (which fills
Numba's cache if needed); the median and the fastest are printed, with the load average before and after. A figure,
not a timed test: the machine is shared, so compare within one sitting. Target: ``settler --help`` under 1 s.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def commands(work: Path) -> list[tuple[str, list[str]]]:
    settler = [sys.executable, "-m", "settler"]
    return [
        ("settler --help", settler + ["--help"]),
        ("settler full --help", settler + ["full", "--help"]),
        ("settler info demo", settler + ["info", "demo"]),
        ("settler figures data/reference/simple", settler + ["figures", str(ROOT / "data/reference/simple"),
                                                             "--out", str(work / "figures")]),
        ("settler reduced demo", settler + ["reduced", "demo", "--out", str(work / "reduced"), "--overwrite",
                                            "--quiet"]),
    ]


def timed(argv: list[str]) -> float:
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)}: exit {done.returncode}: {done.stderr.strip()[-500:]}")
    return elapsed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed runs of each command (default 5)")
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}, {os.cpu_count()} CPUs, "
          f"Python {sys.version.split()[0]}")
    with tempfile.TemporaryDirectory(prefix="settler-startup-") as tmp:
        for name, argv in commands(Path(tmp)):
            timed(argv)  # untimed: Numba's cache filled or loaded, files in the page cache
            times = [timed(argv) for _ in range(args.repeat)]
            print(f"{name:<42s} median {statistics.median(times):6.2f} s   fastest {min(times):6.2f} s   "
                  f"({args.repeat} runs)")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
