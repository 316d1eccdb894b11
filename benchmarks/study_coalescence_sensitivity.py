"""Study (not a timed benchmark): how the demo's merge rate depends on what the coalescence model chose.

    python benchmarks/study_coalescence_sensitivity.py --runs runs/sensitivity      # 9 runs, about 8 min each
    python benchmarks/study_coalescence_sensitivity.py --runs runs/sensitivity --only gr2_every gr20_every
    python benchmarks/study_coalescence_sensitivity.py --runs runs/sensitivity --summary   # table only

Runs the demo case to 25 s (``settler full demo --end-time 25``, one Numba thread each, one after the other: two
OpenMP runs on two cores slow each other about fivefold) at ``coalescence.growth_rate`` 2, 6 and 20 per second under
both triggers, a second feed seed of the default (the seed scatter the differences are judged against) and
``coalescence.mode = "instantaneous"``; a run whose folder already holds a time series to the end time is not rerun,
one that stopped is resumed (``--resume``). Then prints, per run, over the window 15-25 s (the count is within 1 %
of its 20-25 s mean there): the mean droplet count, merges per second, the mean diameter, the axis velocity of the
slag and the merges refused by the size limit per second, and writes the table to ``sensitivity.csv`` in the runs
folder. A run that stopped early (the instantaneous merge's runaway overlap, seed paper section 4.1) is reported to
where it got, beside the default's merges to the same time.

Measured at 4a017fb (2026-12-02, one thread each; the coalescence issue's figures; window 15-25 s):

    run               count   merges/s  mean d [mm]  axis [mm/s]
    gr2_every (def.)  22 397    4 263     0.555        60.7
    gr2_every seed 2  22 296    4 240     0.555        60.8
    gr6_every         21 451    4 349     0.556        60.5
    gr20_every        21 272    4 355     0.558        60.4
    gr2_first         24 349    4 085     0.554        60.8
    gr6_first         23 000    4 209     0.556        60.7
    gr20_first        22 450    4 262     0.556        60.6
    instantaneous     stopped at 1.86 s (runaway overlap 0.29 of a diameter; with fulldem.overlap_abort = 0.5
                      at 5.53 s: 12 357 merges to 5.5 s against the default's 11 817)

The steady count spans 14 % over the choices (seed scatter 0.5 %), 5 % over growth_rate 2-20 at every contact:
growth_rate is a bracketed parameter of the reference runs (data/properties/flash_smelting.toml).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

#: Run name -> case overrides (the demo otherwise at its defaults).
VARIANTS = {
    "gr2_every": ["coalescence.trigger=every_contact", "coalescence.growth_rate=2"],
    "gr2_every_seed2": ["coalescence.trigger=every_contact", "coalescence.growth_rate=2", "feed.seed=20231030"],
    "gr6_every": ["coalescence.trigger=every_contact", "coalescence.growth_rate=6"],
    "gr20_every": ["coalescence.trigger=every_contact", "coalescence.growth_rate=20"],
    "gr2_first": ["coalescence.trigger=first_contact", "coalescence.growth_rate=2"],
    "gr6_first": ["coalescence.trigger=first_contact", "coalescence.growth_rate=6"],
    "gr20_first": ["coalescence.trigger=first_contact", "coalescence.growth_rate=20"],
    "instantaneous": ["coalescence.mode=instantaneous"],
}
DEFAULT = "gr2_every"
WINDOW = (15.0, 25.0)  # s


def _read(folder: Path):
    import pandas as pd

    path = folder / "timeseries.csv"
    return pd.read_csv(path, comment="#") if path.exists() else None


def run_variant(folder: Path, overrides: list[str], end_time: float) -> int:
    """One demo run into ``folder`` (resumed if it has a checkpoint); its log beside it; returns the exit code."""
    command = [sys.executable, "-m", "settler", "full", "demo", "--out", str(folder), "--end-time", str(end_time),
               *overrides]
    if (folder / "checkpoint.npz").exists():
        command.append("--resume")
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", OMP_WAIT_POLICY="passive")
    print("$", " ".join(command), flush=True)
    with open(folder.with_suffix(".log"), "a") as log:
        return subprocess.call(command, stdout=log, stderr=subprocess.STDOUT, env=env)


def summary(runs: Path, names, end_time: float):
    """The table of the module docstring, one row per run found; a DataFrame indexed by run name."""
    import pandas as pd

    default = _read(runs / DEFAULT)
    rows = []
    for name in names:
        f = _read(runs / name)
        if f is None:
            continue
        reached = float(f["time"].iloc[-1])
        row = dict(run=name, reached_s=round(reached, 3))
        if reached >= end_time - 1e-6:
            w = f[(f.time > WINDOW[0] - 1e-9) & (f.time < WINDOW[1] + 1e-9)]
            span = float(w.time.iloc[-1] - w.time.iloc[0])
            row.update(count=w.droplet_count.mean(), merges_per_s=w.merges.iloc[1:].sum() / span,
                       mean_d_mm=1e3 * w.mean_diameter.mean(), axis_mm_s=1e3 * w.channel_velocity.mean(),
                       refused_per_s=(w["merges_refused_by_size"].iloc[1:].sum() / span
                                      if "merges_refused_by_size" in w else np.nan))
        else:  # stopped early: what it merged by then, beside the default
            row.update(merges_to_reached=float(f.merges.sum()), count_at_reached=float(f.droplet_count.iloc[-1]))
            if default is not None:
                d = default[default.time <= reached + 1e-9]
                row.update(default_merges_to_reached=float(d.merges.sum()))
        rows.append(row)
    return pd.DataFrame(rows).set_index("run") if rows else pd.DataFrame()


def write_table(runs: Path, names, end_time: float, csv_name: str):
    """The :func:`summary` of the runs found, written to ``runs / csv_name`` and printed; exits if there are none."""
    import pandas as pd

    table = summary(runs, names, end_time)
    if table.empty:
        sys.exit(f"no runs in {runs}")
    table.to_csv(runs / csv_name)
    with pd.option_context("display.width", 200):
        print(table.round(3).to_string())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True, help="folder of the runs, one sub-folder each")
    parser.add_argument("--only", nargs="+", choices=sorted(VARIANTS), help="these runs only")
    parser.add_argument("--end-time", type=float, default=25.0, help="simulated time of each run [s]")
    parser.add_argument("--summary", action="store_true", help="print the table of the runs found; run nothing")
    args = parser.parse_args(argv)
    names = args.only or list(VARIANTS)
    args.runs.mkdir(parents=True, exist_ok=True)
    if not args.summary:
        for name in names:
            f = _read(args.runs / name)
            if f is not None and f["time"].iloc[-1] >= args.end_time - 1e-6:
                continue
            rc = run_variant(args.runs / name, VARIANTS[name], args.end_time)
            if rc:
                print(f"{name}: stopped with exit code {rc} (see {args.runs / name}.log)", flush=True)
    write_table(args.runs, names, args.end_time, "sensitivity.csv")


if __name__ == "__main__":
    main()
