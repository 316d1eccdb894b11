"""The ``settler sweep`` command (registered in :data:`settler.cli.TOOLS` as ``analysis.sweep``).
"""

from __future__ import annotations

import sys
from pathlib import Path

from settler.cases import CaseError, case_with_overrides

from .designs import DEFAULT_SAMPLES, DESIGNS
from .execution import ENGINES, ERROR_FILE, POINTS, sweep
from .runset import format_status, set_status, sweep_set


def add_arguments(parser):
    """Arguments of ``settler sweep`` (registered in settler.cli.TOOLS)."""
    from settler.cli import _case_help

    parser.add_argument("case", nargs="?", default=None,
                        help=_case_help() + " (not with --set, whose runs name their own cases)")
    # named 'overrides' so that settler.cli.parse collects axes given after the options as well
    parser.add_argument("overrides", nargs="*", metavar="section.key=VALUES",
                        help="an axis: section.key=v1,v2,... (a list), section.key=a:b:n (n values from a to b, "
                             "linear), section.key=a:b:n:log (log-spaced); one value: a fixed override of every "
                             "point. Sampled designs take ranges a:b (bounds; n unused)")
    parser.add_argument("--design", choices=DESIGNS, default="grid",
                        help="grid: every combination of the axes' values (default); lhs: Latin hypercube; sobol: "
                             "Saltelli sample with Sobol first- and total-order indices; morris: Morris elementary "
                             "effects (SALib, over the ranges a:b)")
    parser.add_argument("--samples", type=int, metavar="N", default=None,
                        help="sampled designs: lhs N points; sobol N base samples, N (D + 2) points, N a power of 2; "
                             "morris N trajectories, N (D + 1) points; D the swept keys (defaults: "
                             + ", ".join(f"{k} {v}" for k, v in DEFAULT_SAMPLES.items()) + ")")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="output folder (default sweep-CASE): sweep.csv, sweep.nc, sweep.json, sweep_KEY.png, "
                             "sensitivity.csv/.png, points/<hash>/; a rerun into it skips finished points")
    parser.add_argument("--workers", type=int, metavar="N", default=None,
                        help="worker processes of the LocalCluster, one thread and one Numba thread each (default: "
                             "the CPU count); 0 runs the points in this process without dask")
    parser.add_argument("--scheduler", metavar="ADDRESS", default=None,
                        help="run on the dask cluster of this scheduler (e.g. tcp://host:8786, from dask-jobqueue "
                             "or 'dask scheduler') instead of a LocalCluster; its workers need settler importable "
                             "and NUMBA_NUM_THREADS=1")
    parser.add_argument("--seed", type=int, default=0, help="seed of the sampled designs (default 0)")
    parser.add_argument("--distribution", action="store_true",
                        help="also save each point's size distribution (points/<hash>/distribution.npz, 6 MB and "
                             "0.5 s per furnace point at the preset's resolution; default: the time series only, "
                             "which is all sweep.csv needs)")
    parser.add_argument("--engine", choices=ENGINES, default="reduced",
                        help="reduced: popbal, seconds a point (default); full: the CFD-DEM engine, each point a "
                             "fulldem run in points/<hash>/ that checkpoints every fulldem.checkpoint_interval and "
                             "resumes when the same command runs again (its log in points/<hash>/run.log)")
    parser.add_argument("--set", metavar="FILE", default=None, dest="run_set",
                        help="run the named runs of a run-set TOML (each its own case and overrides, e.g. "
                             "data/reference/design.toml; see analysis.sweep.runset) instead of a design over CASE")
    parser.add_argument("--only", metavar="NAMES", default=None,
                        help="with --set: only these runs (comma-separated names)")
    parser.add_argument("--status", action="store_true",
                        help="with --set: run nothing; print where each run of the set stands in --out (done, "
                             "started: simulated time reached, wall time, recent pace and time still to go at it, "
                             "when its time series was last written; not started) and the total still to go "
                             "(spread over --workers if given)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main(args) -> int:
    """Run ``settler sweep``: 0 every point done, 3 some failed (how many and where on stderr); refused input
    raises CaseError / OutputError (exit 2 from settler.cli)."""
    if args.scheduler is not None and args.workers is not None:
        raise CaseError(f"--workers {args.workers} with --scheduler {args.scheduler}: allowed: one of them (the "
                        "cluster's workers are started with it)")
    if args.run_set is not None:
        return _main_set(args)
    if args.only is not None:
        raise CaseError(f"--only {args.only}: allowed only with --set")
    if args.status:
        raise CaseError("--status: allowed only with --set (a set's runs have their own folders to read)")
    if args.case is None:
        raise CaseError("no CASE: allowed: a preset name or a case TOML path, then the axes (or --set FILE)")
    base = case_with_overrides(args.case)
    out = args.out if args.out is not None else f"sweep-{base.case.name}"
    try:
        result = sweep(base, args.overrides, args.design, args.samples, out, args.workers, args.scheduler,
                       args.seed, progress=not args.quiet, command_line=getattr(args, "command_line", None),
                       distribution=args.distribution, engine=args.engine)
    except KeyboardInterrupt:
        print(f"settler sweep: interrupted; the finished points are kept in {Path(out) / POINTS}/ and the same "
              "command skips them", file=sys.stderr)
        return 130
    done = result.table[result.table["status"] == "done"]
    print(f"settler sweep {base.case.name}: {len(result.table)} points ({result.ran} run, {result.skipped} resumed) "
          f"in {result.wall_time:.1f} s; outputs in {result.out}/")
    if len(done):
        loss = done["matte_loss"]
        print(f"  matte loss {100 * loss.min():.4g} to {100 * loss.max():.4g} % of the matte fed; "
              f"mean wall time per point {done['wall_time'].mean():.2f} s")
    for note in result.notes:
        print(f"  note: {note}")
    if result.failed:
        print(f"settler sweep: error: {result.failed} of {len(result.table)} points failed; see the 'error' column "
              f"of {result.out / 'sweep.csv'} and {result.out / POINTS}/<hash>/{ERROR_FILE}", file=sys.stderr)
        return 3
    return 0


def _main_set(args) -> int:
    """``settler sweep --set FILE``: every run of the set (or --only some), exit 0 all done, 3 some failed."""
    if args.case is not None or args.overrides:
        given = " ".join([args.case or ""] + list(args.overrides)).strip()
        raise CaseError(f"--set {args.run_set} with {given!r}: allowed: --set alone (each run names its case and "
                        "overrides in the file)")
    out = args.out if args.out is not None else f"sweep-{Path(args.run_set).stem}"
    if args.status:
        print(format_status(set_status(args.run_set, args.engine, out, args.only), args.workers))
        return 0
    try:
        result = sweep_set(args.run_set, args.engine, out, args.workers, args.scheduler, args.only,
                           progress=not args.quiet, command_line=getattr(args, "command_line", None))
    except KeyboardInterrupt:
        print(f"settler sweep: interrupted; finished runs are kept in {Path(out) / POINTS}/, full runs keep their "
              "last checkpoint, and the same command continues them", file=sys.stderr)
        return 130
    print(f"settler sweep --set {args.run_set}: {len(result.table)} runs ({result.ran} run, {result.skipped} "
          f"resumed) in {result.wall_time:.1f} s; outputs in {result.out}/")
    if result.failed:
        print(f"settler sweep: error: {result.failed} of {len(result.table)} runs failed; see the 'error' column of "
              f"{result.out / 'sweep.csv'} and {result.out / POINTS}/<hash>/{ERROR_FILE}", file=sys.stderr)
        return 3
    return 0
