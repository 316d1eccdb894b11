"""Run sets: named runs of different cases in one command, ``settler sweep --set FILE [--engine full]``.

A grid or a sample varies keys of one case; a run set lists whole runs, each its own case and overrides: the seed
paper's cases and a designed set of families that vary one controlling group at a time (``data/reference/
design.toml``). The file is TOML::

    [set]
    description = "what the set is for"          # optional

    [runs.feed_half]                              # the run's name: letters, digits, '_' and '-'
    case = "demo"                                 # a preset, or a case TOML path relative to this file
    overrides = { "feed.mass_rate" = 0.001 }      # optional: section.key = value, as on the command line
    family = "feed"                               # optional: a label the table keeps
    purpose = "the plume velocity's square-root law"   # optional
    droplets = "kernel_droplets.csv"              # optional (full engine): an initial droplet list, relative to
                                                  # this file (fulldem.io.droplet_list)
    snapshots = 1                                 # optional: droplet snapshots its stored reference keeps (0 =
                                                  # none; python -m analysis.reference_set); not part of the run

Each run is a point of the sweep machinery (:mod:`analysis.sweep.execution`): a folder ``OUT/points/<hash>/`` keyed
by its resolved case, its engine and its droplet list, ``done.json`` written last; with ``--engine full`` a point is
a fulldem run that checkpoints every ``fulldem.checkpoint_interval`` seconds of wall time and resumes from there when
the same command runs again after an interruption. ``--only a,b`` runs some of the set. Outputs in OUT:
``sweep.csv`` (one row per run: name, family, hash, the metrics of :data:`~analysis.sweep.execution.METRICS`,
status, error), ``sweep.nc`` (the same over the dimension ``name``), ``sweep.json`` (the set, the engine, the source
commit and engine trees, counts).
"""

from __future__ import annotations

import math
import re
import sys
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from settler.cases import Case, CaseError, case_with_overrides
from settler.output import atomic_write_text, prepare_output_folder, source_commit, to_json

from .execution import (METRICS, POINTS, Executor, check_engine, check_workers, point_hash, read_done, warm_numba,
                        write_dataset)

#: Keys of a run's table in a run-set file; ``case`` is required.
RUN_KEYS = ("case", "overrides", "family", "purpose", "droplets", "snapshots")
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]*$")


@dataclass
class SetRun:
    """One run of a set: its name, resolved case, family and purpose, initial droplet list (a path or None)."""

    name: str
    case: Case
    family: str = ""
    purpose: str = ""
    droplets: str | None = None
    overrides: dict = field(default_factory=dict)
    snapshots: int | None = None  # droplet snapshots its stored reference keeps (None: the store command's default)


@dataclass
class RunSet:
    """A run-set file read by :func:`load_run_set`: its path, description and runs in file order."""

    path: Path
    description: str
    runs: list[SetRun]


def load_run_set(path) -> RunSet:
    """Read and validate a run-set file (module docstring). Raises CaseError naming the run, the key and what is
    allowed."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CaseError(f"--set {path}: cannot be read ({exc.strerror or exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"--set {path}: not valid TOML ({exc})") from None
    unknown = sorted(set(data) - {"set", "runs"})
    if unknown:
        raise CaseError(f"--set {path}: unknown table(s) {', '.join(unknown)}; allowed: [set], [runs.NAME]")
    runs = data.get("runs")
    if not isinstance(runs, dict) or not runs:
        raise CaseError(f"--set {path}: no [runs.NAME] tables; a run set lists at least one run")
    listed = []
    for name, entry in runs.items():
        where = f"--set {path}: run {name!r}"
        if not NAME.match(name):
            raise CaseError(f"{where}: the name must be letters, digits, '_' or '-'")
        if not isinstance(entry, dict):
            raise CaseError(f"{where}: must be a table with the keys {', '.join(RUN_KEYS)}")
        bad = sorted(set(entry) - set(RUN_KEYS))
        if bad:
            raise CaseError(f"{where}: unknown key(s) {', '.join(bad)}; allowed: {', '.join(RUN_KEYS)}")
        if not isinstance(entry.get("case"), str) or not entry["case"]:
            raise CaseError(f"{where}: case = {entry.get('case')!r}: allowed: a preset name or a case TOML path")
        overrides = entry.get("overrides", {})
        if not isinstance(overrides, dict):
            raise CaseError(f"{where}: overrides = {overrides!r}: allowed: a table of section.key = value")
        source = entry["case"]
        if source.endswith(".toml") and not Path(source).is_absolute():
            source = str(path.parent / source)
        try:
            case = case_with_overrides(source, dict(overrides)) if overrides else case_with_overrides(source)
        except CaseError as exc:
            raise CaseError(f"{where}: {exc}") from None
        droplets = entry.get("droplets")
        if droplets is not None:
            resolved = Path(droplets) if Path(droplets).is_absolute() else path.parent / droplets
            if not resolved.is_file():
                raise CaseError(f"{where}: droplets = {droplets!r}: no such file next to {path}")
            droplets = str(resolved)
        snapshots = entry.get("snapshots")
        if snapshots is not None and (isinstance(snapshots, bool) or not isinstance(snapshots, int) or snapshots < 0):
            raise CaseError(f"{where}: snapshots = {snapshots!r}: allowed: a whole number >= 0 (the droplet "
                            "snapshots its stored reference keeps; 0 = none)")
        listed.append(SetRun(name, case, str(entry.get("family", "")), str(entry.get("purpose", "")), droplets,
                             dict(overrides), snapshots))
    return RunSet(path, str(data.get("set", {}).get("description", "")), listed)


@dataclass
class SetResult:
    """A finished run set: ``table`` (one row per run, the columns of sweep.csv), ``out``, counts, wall time [s]."""

    table: pd.DataFrame
    out: Path
    ran: int = 0
    skipped: int = 0
    failed: int = 0
    wall_time: float = 0.0
    files: list[Path] = field(default_factory=list)


def chosen_runs(run_set: RunSet, only=None) -> list[SetRun]:
    """The runs of ``run_set`` named in ``only`` (comma-separated text or a list; all if empty), in file order.
    Raises CaseError naming the names the set lacks and those it has."""
    runs = run_set.runs
    if not only:
        return runs
    wanted = [w for w in (only.split(",") if isinstance(only, str) else only) if w]
    names = {r.name for r in runs}
    missing = [w for w in wanted if w not in names]
    if missing:
        raise CaseError(f"--only {','.join(missing)}: not in {run_set.path}; allowed: {', '.join(sorted(names))}")
    return [r for r in runs if r.name in wanted]


def run_hash(run: SetRun, engine: str) -> str:
    """The point folder's name of ``run`` with ``engine`` (:func:`analysis.sweep.execution.point_hash`; a full
    point's droplet list counts)."""
    return point_hash(run.case, engine, run.droplets if engine == "full" else None)


def sweep_set(path, engine: str = "full", out="sweep-set", workers: int | None = None, scheduler: str | None = None,
              only=None, progress: bool = True, command_line: str | None = None, client=None) -> SetResult:
    """Run every run of the set file ``path`` (or those named in ``only``) with ``engine`` and write the table into
    ``out`` (module docstring). Finished runs are read back, interrupted full runs resume. Raises CaseError /
    OutputError for refused input; failed runs are in the table."""
    started = time.perf_counter()
    check_workers(workers)
    check_engine(engine)
    run_set = load_run_set(path)
    runs = chosen_runs(run_set, only)
    out = prepare_output_folder(out, resume=True)
    points = out / POINTS
    hashes = [run_hash(r, engine) for r in runs]
    records, tasks = {}, {}
    for run, digest in zip(runs, hashes):
        if digest in records or digest in tasks:
            continue
        done = read_done(points / digest)
        if done is not None:
            records[digest] = {**done, "resumed": True}
        else:
            tasks[digest] = (run.case.to_dict(), str(points / digest), run.case.source, False, engine,
                             run.droplets if engine == "full" else None,
                             f"{command_line or 'analysis.sweep.sweep_set'} (run {run.name}, point {digest})")
    with Executor(workers if tasks else 0, scheduler if tasks else None, client) as executor:
        if progress:
            print(f"sweep --set {path}: {len(runs)} runs, {len(records)} already done, {len(tasks)} to run with the "
                  f"{engine} engine on {executor.describe()}", file=sys.stderr)
        if tasks and not executor.local:  # one process fills the Numba cache; several at once must not
            seen, warm = set(), []
            for run, digest in zip(runs, hashes):
                key = (run.case.case.name, run.case.coalescence.enabled, run.case.reaction.enabled)
                if digest in tasks and key not in seen:
                    seen.add(key)
                    warm.append(run.case.to_dict())
            warm_numba(warm, engine)
            executor.warm_workers(warm, engine)
        for record in executor.map(list(tasks.values()), progress):
            records[record["hash"]] = {**record, "resumed": False}
    rows = []
    for run, digest in zip(runs, hashes):
        record = records.get(digest, {})
        rows.append({"name": run.name, "family": run.family, "hash": digest,
                     **{m: record.get(m, math.nan) for m in METRICS}, "status": record.get("status", "failed"),
                     "resumed": bool(record.get("resumed", False)), "error": record.get("error", "") or ""})
    table = pd.DataFrame(rows)
    for m in METRICS:
        table[m] = table[m].astype(float)
    result = SetResult(table, out, ran=len(tasks), skipped=len(set(records) - set(tasks)),
                       failed=int((table["status"] != "done").sum()))
    units = "# units: " + ", ".join(f"{m} [{u}]" for m, (u, _) in METRICS.items()) + "\n"
    atomic_write_text(out / "sweep.csv", units + table.to_csv(index=False))
    result.files.append(out / "sweep.csv")
    result.files.append(_write_set_netcdf(table, out / "sweep.nc", engine, path))
    meta = {"set": str(path), "description": run_set.description, "engine": engine, "only": only,
            "runs": {r.name: {"case": r.case.case.name, "case_source": r.case.source, "overrides": r.overrides,
                              "family": r.family, "purpose": r.purpose, "droplets": r.droplets, "hash": h}
                     for r, h in zip(runs, hashes)},
            "ran": result.ran, "skipped": result.skipped, "failed": result.failed, "points_folder": str(points),
            "metrics": {m: {"unit": u, "meaning": d} for m, (u, d) in METRICS.items()},
            "command_line": command_line, **source_commit()}
    atomic_write_text(out / "sweep.json", to_json(meta))
    result.files.append(out / "sweep.json")
    result.wall_time = time.perf_counter() - started
    return result


#: Time-series rows at the end of a full point over which :func:`set_status` measures its recent pace [-].
PACE_ROWS = 20


def set_status(path, engine: str = "full", out="sweep-set", only=None, now: float | None = None) -> pd.DataFrame:
    """Where each run of the set file ``path`` (or those in ``only``) stands in the sweep folder ``out``, read from
    its point folder without running anything: one row per run with ``name``, ``state`` ("done", "failed",
    "started": a point with a time series but no done.json, running or interrupted; "not started"),
    ``time`` and ``end_time`` [s] (simulated, reached and to reach), ``wall_time`` [s] (the run's own wall clock so
    far), ``pace`` [s/s] (wall seconds per simulated second over its last :data:`PACE_ROWS` rows), ``remaining``
    [s] (wall time still to go at that pace), ``updated`` [s] (since its time series was last written: a large value
    means it is not running). Raises CaseError for a set file or ``only`` it refuses (as :func:`sweep_set`)."""
    from settler.output import read_time_series

    check_engine(engine)
    runs = chosen_runs(load_run_set(path), only)
    now = time.time() if now is None else now
    rows = []
    for run in runs:
        digest = run_hash(run, engine)
        folder = Path(out) / POINTS / digest
        end = float(run.case.fulldem.end_time if engine == "full" else run.case.popbal.end_time)
        row = {"name": run.name, "hash": digest, "state": "not started", "time": math.nan, "end_time": end,
               "wall_time": math.nan, "pace": math.nan, "remaining": math.nan, "updated": math.nan}
        done = read_done(folder)
        series_path = folder / "timeseries.csv"
        if series_path.is_file():
            try:
                series = read_time_series(series_path)
            except (OSError, ValueError):
                series = None
            if series is not None and len(series):
                row.update(state="started", time=float(series["time"].iloc[-1]),
                           updated=max(0.0, now - series_path.stat().st_mtime))
                if "wall_time" in series:
                    row["wall_time"] = float(series["wall_time"].iloc[-1])
                    tail = series.iloc[-PACE_ROWS:]
                    span = float(tail["time"].iloc[-1] - tail["time"].iloc[0])
                    if span > 0.0:
                        row["pace"] = float(tail["wall_time"].iloc[-1] - tail["wall_time"].iloc[0]) / span
                        row["remaining"] = max(0.0, end - row["time"]) * row["pace"]
        if done is not None:
            row["state"] = "done" if done.get("status") == "done" else "failed"
            row["remaining"] = 0.0 if row["state"] == "done" else math.nan
        rows.append(row)
    return pd.DataFrame(rows)


def format_status(table: pd.DataFrame, workers: int | None = None) -> str:
    """:func:`set_status`'s table as text, with totals: runs done, wall time still to go (one core) and, for
    ``workers`` > 1, that time spread over them (a lower bound: the longest run may take longer alone)."""
    def hours(x):
        return "-" if not math.isfinite(x) else (f"{x / 3600:.1f} h" if x >= 3600 else f"{x / 60:.0f} min")

    lines = [f"{'run':28s} {'state':12s} {'simulated [s]':>15s} {'wall':>8s} {'pace [s/s]':>10s} {'to go':>8s} "
             f"{'written':>10s}"]
    for r in table.itertuples():
        reached = f"{r.time:.4g} / {r.end_time:.4g}" if math.isfinite(r.time) else f"- / {r.end_time:.4g}"
        written = f"{hours(r.updated)} ago" if math.isfinite(r.updated) else "-"
        pace = f"{r.pace:.4g}" if math.isfinite(r.pace) else "-"
        lines.append(f"{r.name:28s} {r.state:12s} {reached:>15s} {hours(r.wall_time):>8s} {pace:>10s} "
                     f"{hours(r.remaining):>8s} {written:>10s}")
    known = table["remaining"].dropna()
    unknown = int(table["remaining"].isna().sum())
    total = float(known.sum())
    text = (f"{int((table['state'] == 'done').sum())} of {len(table)} runs done; at least {hours(total)} of one core "
            f"still to go for the runs with a pace")
    if unknown:
        text += f" (and {unknown} runs not started or without a pace yet)"
    if workers and workers > 1:
        text += f"; about {hours(max(total / workers, float(known.max()) if len(known) else 0.0))} on {workers} workers"
    return "\n".join(lines + [text])


def _write_set_netcdf(table: pd.DataFrame, path: Path, engine: str, source) -> Path:
    """sweep.nc of a run set: the table over the dimension ``name`` (h5netcdf), units in the attrs."""
    import xarray as xr

    dataset = xr.Dataset.from_dataframe(table.set_index("name")[["family", "hash", *METRICS, "status", "error"]])
    for name, (unit, meaning) in METRICS.items():
        dataset[name].attrs.update(units=unit, long_name=meaning)
    dataset.attrs.update(run_set=str(source), engine=engine)
    return write_dataset(dataset, path)


__all__ = ["RUN_KEYS", "RunSet", "SetResult", "SetRun", "format_status", "load_run_set", "set_status", "sweep_set"]
