"""The rule for "steady" in a run's time series, shared by the evidence, the calibration and the collision
measures (:mod:`analysis.evidence` re-exports it): the means of consecutive blocks one burst cycle long
(:data:`CYCLE`, 5 s: the plume's bursts in simple and cubic), counted back from the run's end, all lie within
±:data:`STEADY_TOLERANCE` (2 %) of their common mean, over at least :data:`STEADY_CYCLES` (3) blocks; the window with
the most blocks that passes. Cycle means, not single rows: the count swings ±6-7 % within a burst and ±1-2 % between
cycles. Times in s.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

#: Burst cycle of the plume in simple and cubic [s] (measured on the old stored runs: 5-s bursts).
CYCLE = 5.0
#: Cycle means within this relative distance of their common mean [-].
STEADY_TOLERANCE = 0.02
#: Whole cycles the steady window must hold [-].
STEADY_CYCLES = 3


def steady_window(timeseries: pd.DataFrame, column: str = "droplet_count", cycle: float = CYCLE,
                  tolerance: float = STEADY_TOLERANCE, cycles: int = STEADY_CYCLES) -> dict:
    """The earliest steady start of ``column`` (module docstring), in whole cycles back from the run's last output:
    {"start": t0 [s] or NaN if no window of ``cycles`` blocks is steady, "cycles": blocks in the window, "mean": the
    mean of the block means, "block_means", "spread": max abs(block mean / mean - 1)}."""
    t = timeseries["time"].to_numpy(dtype=float)
    y = timeseries[column].to_numpy(dtype=float)
    end = t[-1]
    most = int(math.floor((end - t[0]) / cycle + 1e-9))
    for blocks in range(most, cycles - 1, -1):
        edges = end - cycle * np.arange(blocks, -1, -1)
        means = []
        for low, high in zip(edges[:-1], edges[1:]):
            inside = (t > low + 1e-9) & (t <= high + 1e-9)
            means.append(float(y[inside].mean()) if inside.any() else math.nan)
        means = np.array(means)
        if not np.isfinite(means).all():
            continue
        mean = float(means.mean())
        spread = float(np.max(np.abs(means / mean - 1.0)))
        if spread <= tolerance:
            return {"start": float(edges[0]), "cycles": blocks, "mean": mean, "block_means": means.tolist(),
                    "spread": spread}
    return {"start": math.nan, "cycles": 0, "mean": math.nan, "block_means": [], "spread": math.nan}


def window_of(series: pd.DataFrame) -> tuple[tuple[float, float], bool]:
    """((start, end) [s], steady?) of a time series: its steady window (:func:`steady_window`), else its last
    third (``steady`` False)."""
    end = float(series["time"].iloc[-1])
    found = steady_window(series)
    if math.isfinite(found["start"]):
        return (float(found["start"]), end), True
    return (end * 2.0 / 3.0, end), False


def window_snapshots(run, window: tuple[float, float] | None = None) -> tuple[tuple[float, float], list[float]]:
    """(the window [s], the times [s] of ``run``'s snapshots within it): ``window`` (default: :func:`window_of`
    the run's time series, its steady window else its last third). ``run`` is an :class:`analysis.Run`."""
    window = window or window_of(run.timeseries)[0]
    times = [float(t) for t in run.snapshot_times() if window[0] - 1e-9 <= t <= window[1] + 1e-9]
    return (float(window[0]), float(window[1])), times


def parse_window(text: str) -> tuple[float, float]:
    """The ``--window START:END`` of a command line as (start, end) [s]; ValueError naming the value and what is
    allowed (START:END in seconds, START < END)."""
    try:
        window = tuple(float(x) for x in text.split(":"))
    except ValueError:
        window = ()
    if len(window) != 2 or not window[0] < window[1]:
        raise ValueError(f"--window {text!r}: allowed START:END in seconds, START < END")
    return window


def window_measure_main(argv, prog: str, description: str, runs_help: str, measure, report) -> int:
    """The command line of a measure taken over each run's steady window (``python -m analysis.floor_layer``,
    ``analysis.floor_lift``, ``analysis.plume_zones``): ``RUN... [--window START:END]``. ``measure(folder, window)``
    returns (table, meta), ``report(folder, table, meta)`` prints them. Exit 0, or 2 with one line naming the bad
    window or the run whose measure failed (no traceback)."""
    import argparse
    import sys

    from .files import NoData, OutputError

    parser = argparse.ArgumentParser(prog=prog, description=description)
    parser.add_argument("runs", nargs="+", help=runs_help)
    parser.add_argument("--window", help="START:END [s]; default each run's steady window, else its last third")
    args = parser.parse_args(argv)
    try:
        window = parse_window(args.window) if args.window else None
    except ValueError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    for folder in args.runs:
        try:
            table, meta = measure(folder, window)
        except (OutputError, ValueError, OSError, NoData) as exc:
            text = str(exc)  # the measures name the run themselves (analysis.plume_zones.axis_window)
            print(f"{prog}: {text if text.startswith(str(Path(folder))) else f'{folder}: {text}'}", file=sys.stderr)
            return 2
        report(folder, table, meta)
    return 0
