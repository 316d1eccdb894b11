"""Executing a sweep: one task per design point keyed by its case's hash, run in this process or on a
dask.distributed cluster, resumable point by point; the table, netCDF and JSON written at the end.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from settler.cases import Case, CaseError, case_with_overrides, resolve
from settler.output import OutputError, atomic_write_text, prepare_output_folder, source_commit, to_json

from .axes import _field, parse_axes
from .designs import Design, build_design
from .results import _save_png, plot_sensitivity, plot_trends, sensitivity


#: What is measured per point: name -> (unit, meaning). See the module docstring.
METRICS: dict[str, tuple[str, str]] = {
    "matte_loss": ("-", "mass_lost / mass_fed at the last output: matte lost with the slag over matte fed"),
    "settled_fraction": ("-", "mass_settled / mass_fed at the last output"),
    "suspended_fraction": ("-", "mass_in_slag / mass_fed at the last output"),
    "mean_diameter": ("m", "number-mean droplet diameter in the slag at size_time"),
    "sauter_diameter": ("m", "Sauter mean diameter d32 in the slag at size_time"),
    "size_time": ("s", "last output time with droplets in the slag (where the diameters are taken)"),
    "end_time": ("s", "simulated time of the last output"),
    "slag_viscosity": ("Pa s", "slag viscosity of the point's case (Arrhenius at slag.temperature)"),
    "residence_time": ("s", "slag residence time: slag volume / slag volume feed (NaN without slag feed)"),
    "wall_time": ("s", "wall time of the point's task (setup, run, save) in its worker"),
}


DONE_FILE = "done.json"
ERROR_FILE = "error.json"
POINTS = "points"


#: Engines a sweep runs: ``reduced`` (popbal, seconds a point) or ``full`` (fulldem, minutes to hours a point).
ENGINES = ("reduced", "full")
#: Log of a full point's run (its progress lines: the grid, resumes, warnings), in the point's folder.
RUN_LOG = "run.log"


def check_engine(engine) -> None:
    """CaseError unless ``engine`` is one of :data:`ENGINES`."""
    if engine not in ENGINES:
        raise CaseError(f"--engine {engine!r}: allowed: {', '.join(ENGINES)}")


def point_hash(case: Case, engine: str = "reduced", droplets: str | None = None) -> str:
    """16 hex digits of the SHA-256 of the resolved case (every key, sorted, as JSON), with the engine and the
    initial droplet list's contents for full points: equal points share a folder, however their values were
    given."""
    text = json.dumps(case.to_dict(), sort_keys=True, separators=(",", ":"))
    if engine != "reduced":  # reduced points keep the hashes of the sweeps made before the full engine was offered
        text = f"{engine}:" + text
    if droplets:
        text += ":droplets:" + hashlib.sha256(Path(droplets).read_bytes()).hexdigest()
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def summarize(timeseries: pd.DataFrame) -> dict[str, float]:
    """The time-series part of :data:`METRICS` from a popbal time series (NaN where nothing was fed)."""
    last = timeseries.iloc[-1]
    fed = float(last["mass_fed"])
    share = (lambda m: float(m) / fed) if fed > 0.0 else (lambda m: math.nan)
    holding = timeseries[timeseries["droplet_count"] > 0.0]
    size = holding.iloc[-1] if len(holding) else None
    return {"matte_loss": share(last["mass_lost"]), "settled_fraction": share(last["mass_settled"]),
            "suspended_fraction": share(last["mass_in_slag"]),
            "mean_diameter": float(size["mean_diameter"]) if size is not None else math.nan,
            "sauter_diameter": float(size["sauter_diameter"]) if size is not None else math.nan,
            "size_time": float(size["time"]) if size is not None else math.nan, "end_time": float(last["time"])}


def read_done(folder) -> dict | None:
    """The record of a finished point (its done.json), or None if the point has not finished."""
    try:
        return json.loads((Path(folder) / DONE_FILE).read_text())
    except (OSError, ValueError):
        return None


def _full_point(case: Case, folder: Path, droplets: str | None, command: str | None) -> tuple[pd.DataFrame, float]:
    """Run the full engine on ``case`` into ``folder``, resuming from its checkpoint if an earlier task left one;
    returns (time series, slag residence time [s], NaN without slag feed). Its log lines go to ``folder/run.log``."""
    from fulldem.driver import run_case
    from settler.output import read_time_series

    folder.mkdir(parents=True, exist_ok=True)
    log_path = folder / RUN_LOG

    def log(text):
        with open(log_path, "a", encoding="utf-8") as handle:
            handle.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {text}\n")

    end = case.fulldem.end_time
    series_path = folder / "timeseries.csv"
    finished = ((folder / "summary.json").is_file() and series_path.is_file()
                and float(read_time_series(series_path)["time"].iloc[-1]) >= end - 1e-9)
    if finished:  # the run ended but its task did not write done.json (killed in between)
        frame = read_time_series(series_path)
    else:
        resume = (folder / "checkpoint.npz").is_file()
        frame = run_case(case, folder, resume=resume, droplets=None if resume else droplets, progress=False,
                         log=log, overwrite=not resume, command=command)
    slag_flow = case.slag.feed_rate / case.slag.density  # m^3/s
    volume = case.geometry.width * case.geometry.depth * case.geometry.height
    return frame, (volume / slag_flow if slag_flow > 0.0 else math.nan)


def run_point(case_dict: dict, folder: str, source: str = "", distribution: bool = False, engine: str = "reduced",
              droplets: str | None = None, command: str | None = None) -> dict:
    """Run one point (the task a worker executes) on the resolved case ``case_dict`` into ``folder``, then write
    ``done.json`` with :data:`METRICS` last, atomically. ``engine`` 'reduced': popbal, its output saved by
    Result.save (distribution.npz only if ``distribution``, as the table needs only the time series); 'full': a
    fulldem run (``droplets``: an initial droplet list; ``command``: recorded in its metadata.json) that resumes
    from the folder's checkpoint when an earlier task was interrupted. An error is recorded in ``error.json`` and
    returned (status 'failed'), not raised."""
    if "numba" not in sys.modules:  # a fresh worker process: one Numba thread. Never once Numba is loaded: Numba
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # re-reads the variable and refuses a change (in-process runs)

    started = time.perf_counter()
    folder = Path(folder)
    record = {"hash": folder.name, "engine": engine}
    try:
        case = resolve(case_dict, None, source)
        if engine == "full":
            frame, residence = _full_point(case, folder, droplets, command)
        else:
            import popbal

            result = popbal.run(popbal.setup(case), progress=False)
            result.save(folder, distribution=distribution)
            frame, residence = result.timeseries, result.model.residence_time
        record.update(summarize(frame), slag_viscosity=case.slag_viscosity,
                      residence_time=residence, status="done", error="",
                      wall_time=time.perf_counter() - started)
        text = to_json(record)
        atomic_write_text(folder / DONE_FILE, text)
        (folder / ERROR_FILE).unlink(missing_ok=True)
        record = json.loads(text)  # what a rerun reads back (JSON has no inf or NaN: both become NaN in the table)
    except Exception as exc:  # recorded, not fatal: the sweep goes on and reports it
        record.update(status="failed", error=f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                      wall_time=time.perf_counter() - started)
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(folder / ERROR_FILE, to_json({**record, "traceback": traceback.format_exc()}))
    return record


def _warm_cases(cases: list[Case], design: Design) -> list[Case]:
    """One case per distinct combination of the non-numeric swept values (the kernels each may compile)."""
    seen, picked = set(), []
    numeric = [a.key for a in design.swept if _field(a.key).kind in (float, int)]
    for case, (_, row) in zip(cases, design.table.iterrows()):
        if case is None:
            continue
        signature = tuple((k, repr(v)) for k, v in row.items() if k not in numeric)
        if signature not in seen:
            seen.add(signature)
            picked.append(case)
    return picked


def warm_numba(case_dicts: list[dict], engine: str = "reduced") -> None:
    """Fill (or load) the Numba cache with a tiny run of each case: popbal on 4 cells, one section per doubling,
    three time steps; fulldem for two fluid steps (feed, coalescence, reaction and exits as the case has them) in a
    temporary folder. Errors are left to the points themselves."""
    if engine == "full":
        import tempfile

        from fulldem.driver import run_case

        for case_dict in case_dicts:
            try:
                case = resolve(case_dict)
                tiny = case.replace(fulldem__end_time=2.0 * case.fulldem.fluid_step, fulldem__snapshot_interval=0.0,
                                    fulldem__output_interval=case.fulldem.fluid_step)
                with tempfile.TemporaryDirectory(prefix="settler-warm-") as tmp:
                    run_case(tiny, Path(tmp) / "run", progress=False, log=lambda text: None)
            except Exception:  # noqa: BLE001 -- the same error is recorded when the point runs
                continue
        return
    import popbal

    for case_dict in case_dicts:
        try:
            tiny = resolve(case_dict).replace(popbal__height_cells=4, popbal__sections_per_doubling=1)
            model = popbal.setup(tiny)
            span = min(3.0 * tiny.popbal.time_step, model.stop_time)
            popbal.run(model, end_time=span, output_interval=span, progress=False)
        except Exception:  # noqa: BLE001 -- the same error is recorded when the point runs
            continue


def _worker_environment() -> dict[str, str]:
    """Environment of LocalCluster workers: one Numba thread, this process's Numba cache folder and import path."""
    env = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
           "OPENBLAS_NUM_THREADS": "1"}
    for name in ("NUMBA_CACHE_DIR", "SETTLER_NUMBA_CACHE_BASE", "SETTLER_DATA"):
        if os.environ.get(name):
            env[name] = os.environ[name]
    root = str(Path(__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def check_workers(workers) -> None:
    """CaseError unless ``workers`` is None or an integer >= 0."""
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 0):
        raise CaseError(f"--workers {workers!r}: allowed: an integer >= 0 (0: run in this process)")


class Executor:
    """Where the points run: ``workers`` = 0 in this process; else a dask Client of a LocalCluster of ``workers``
    processes (default: the CPU count), or of the scheduler at ``scheduler``. A context manager."""

    def __init__(self, workers: int | None = None, scheduler: str | None = None, client=None):
        check_workers(workers)
        self.workers = (os.cpu_count() or 1) if workers is None else workers
        self.scheduler = scheduler
        self.client = client
        self._owned = []
        self.external = scheduler is not None or client is not None

    def __enter__(self):
        if self.client is not None or (self.workers == 0 and self.scheduler is None):
            return self
        from ..extras import require

        require("distributed")
        from distributed import Client, LocalCluster

        if self.scheduler is not None:
            try:
                self.client = Client(self.scheduler, timeout="20s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise OutputError(f"--scheduler {self.scheduler}: cannot connect ({exc}); allowed: the address of "
                                  "a running dask scheduler, e.g. tcp://host:8786") from None
        else:
            cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                   env=_worker_environment(), dashboard_address=None, silence_logs=logging.ERROR)
            self._owned.append(cluster)
            self.client = Client(cluster)
        self._owned.insert(0, self.client)
        return self

    def __exit__(self, *exc):
        for thing in self._owned:
            thing.close()
        self._owned.clear()
        return False

    @property
    def local(self) -> bool:
        return self.client is None

    def describe(self) -> str:
        if self.local:
            return "this process (--workers 0)"
        if self.scheduler is not None or self._owned == []:
            return f"dask cluster {self.client.scheduler.address}"
        return f"LocalCluster of {self.workers} worker processes, 1 thread each"

    def warm_workers(self, case_dicts: list[dict], engine: str = "reduced") -> None:
        """On an external cluster, warm each worker's Numba cache in turn (never two at once)."""
        if self.local or not self.external:
            return
        for address in sorted(self.client.scheduler_info()["workers"]):
            self.client.run(warm_numba, case_dicts, engine, workers=[address])

    def map(self, tasks: list[tuple], progress: bool):
        """Yield the record of each task (the arguments of :func:`run_point`: case_dict, folder, source,
        distribution[, engine, droplets, command]) as it finishes, with a tqdm bar."""
        from tqdm.auto import tqdm

        with tqdm(total=len(tasks), desc="sweep", unit="point", disable=not progress or not tasks) as bar:
            if self.local:
                for task in tasks:
                    record = run_point(*task)
                    bar.update()
                    yield record
                return
            from distributed import as_completed

            futures = {self.client.submit(run_point, *task, pure=False): task for task in tasks}
            failed = 0
            for future in as_completed(futures):
                try:
                    record = future.result()
                except Exception as exc:  # a worker died (KilledWorker) or the task could not run
                    record = {"hash": Path(futures[future][1]).name, "status": "failed",
                              "error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
                failed += record.get("status") != "done"
                bar.update()
                if failed:
                    bar.set_postfix(failed=failed)
                yield record


@dataclass
class SweepResult:
    """A finished sweep: ``table`` (one row per design point, the columns of sweep.csv), ``sensitivity`` (sobol /
    morris: one row per metric and swept key, else None), ``out`` its folder, ``files`` what was written,
    ``ran`` / ``skipped`` / ``failed`` point counts (distinct points), ``wall_time`` [s]."""

    table: pd.DataFrame
    design: Design
    out: Path
    sensitivity: pd.DataFrame | None = None
    files: list[Path] = field(default_factory=list)
    ran: int = 0
    skipped: int = 0
    failed: int = 0
    wall_time: float = 0.0
    notes: list[str] = field(default_factory=list)


def sweep(case, axes, design: str = "grid", samples: int | None = None, out="sweep", workers: int | None = None,
          scheduler: str | None = None, seed: int = 0, points_dir=None, client=None, progress: bool = True,
          plots: bool = True, command_line: str | None = None, distribution: bool = False,
          engine: str = "reduced") -> SweepResult:
    """Run popbal (``engine`` 'reduced', the default) or the full engine ('full': each point a resumable fulldem
    run) over a design of case keys and write the table, netCDF, plots (and sensitivity) into ``out``.

    case: a preset name, a TOML path or a :class:`settler.cases.Case`. axes: ``["section.key=SPEC", ...]`` or
    ``{"section.key": SPEC or [values]}`` (:func:`parse_axis`). design, samples, seed: see the module docstring.
    workers, scheduler, client: where the points run (:class:`Executor`; ``client`` an open dask Client to reuse).
    points_dir: the folder of point folders (default ``out/points``; several sweeps may share one). Finished points
    are read back, not rerun. distribution: also save each point's distribution.npz (off: the time series are all
    the table needs, and saving the distribution is the slowest part of saving a point). Raises CaseError /
    OutputError for refused input; failed points are in the table.
    A script that calls it with workers > 0 needs the ``if __name__ == "__main__":`` guard (the LocalCluster's
    worker processes are spawned and import the script's module); notebooks do not.
    """
    started = time.perf_counter()
    check_workers(workers)
    check_engine(engine)
    base = case if isinstance(case, Case) else case_with_overrides(case)
    parsed = parse_axes(axes, base)
    plan = build_design(parsed, design, samples, seed)
    out = prepare_output_folder(out, resume=True)
    points = Path(points_dir) if points_dir is not None else out / POINTS
    fixed_base = case_with_overrides(base, plan.fixed) if plan.fixed else base
    cases, errors = _point_cases(fixed_base, plan)
    hashes = [point_hash(c, engine) if c is not None else "" for c in cases]
    records, tasks = {}, {}
    for case_, digest in zip(cases, hashes):
        if case_ is None or digest in records or digest in tasks:
            continue
        done = read_done(points / digest)
        if done is not None:
            records[digest] = {**done, "resumed": True}
        else:
            tasks[digest] = (case_.to_dict(), str(points / digest), base.source, distribution, engine, None,
                             f"{command_line or 'analysis.sweep.sweep'} (point {digest})")
    # no cluster is started when every point is done
    with Executor(workers if tasks else 0, scheduler if tasks else None, client) as executor:
        if progress:
            print(f"sweep {base.case.name}: {len(plan.table)} design points, {len(records)} already done, "
                  f"{len(tasks)} to run on {executor.describe()}", file=sys.stderr)
        if tasks and not executor.local:  # one process fills the cache as it goes; several must not
            warm = [c.to_dict() for c in _warm_cases([c if h in tasks else None for c, h in zip(cases, hashes)],
                                                      plan)]
            warm_numba(warm, engine)
            executor.warm_workers(warm, engine)
        for record in executor.map(list(tasks.values()), progress):
            records[record["hash"]] = {**record, "resumed": False}
    table = _table(plan, hashes, records, errors)
    result = SweepResult(table, plan, out, ran=len(tasks), skipped=len(set(records) - set(tasks)),
                         failed=int(sum(r.get("status") != "done" for r in records.values())) + len(errors))
    _write_outputs(result, base, points, command_line, plots, seed, engine)
    result.wall_time = time.perf_counter() - started
    return result


def _point_cases(base: Case, plan: Design) -> tuple[list[Case | None], dict[int, str]]:
    """The validated case of each design point; a combination that the case refuses is None, its error kept."""
    cases, errors = [], {}
    for n, row in enumerate(plan.table.to_dict("records")):
        try:
            cases.append(case_with_overrides(base, row) if row else base)
        except CaseError as exc:
            cases.append(None)
            errors[n] = f"CaseError: {exc}"
    return cases, errors


def _table(plan: Design, hashes: list[str], records: dict, errors: dict[int, str]) -> pd.DataFrame:
    """sweep.csv's rows: point, hash, swept keys, metrics, status, resumed, error."""
    rows = []
    for n, (values, digest) in enumerate(zip(plan.table.to_dict("records"), hashes)):
        record = records.get(digest, {}) if digest else {}
        row = {"point": n, "hash": digest, **values}
        row.update({m: record.get(m, math.nan) for m in METRICS})
        if n in errors:
            row.update(status="failed", resumed=False, error=errors[n])
        else:
            row.update(status=record.get("status", "failed"), resumed=bool(record.get("resumed", False)),
                       error=record.get("error", "") or "")
        rows.append(row)
    frame = pd.DataFrame(rows)
    for m in METRICS:
        frame[m] = frame[m].astype(float)
    return frame


def _units_line(plan: Design) -> str:
    units = [f"{a.key} [{a.unit or '-'}]" for a in plan.swept] + [f"{m} [{u}]" for m, (u, _) in METRICS.items()]
    return "# units: " + ", ".join(units) + "\n"


def _write_outputs(result: SweepResult, base: Case, points: Path, command_line, plots: bool, seed: int,
                   engine: str = "reduced") -> None:
    out, plan, table = result.out, result.design, result.table
    atomic_write_text(out / "sweep.csv", _units_line(plan) + table.to_csv(index=False))
    result.files.append(out / "sweep.csv")
    result.files.append(write_netcdf(table, plan, out / "sweep.nc", base))
    if plan.problem is not None and plan.name in ("sobol", "morris"):
        result.sensitivity, note = sensitivity(table, plan, seed)
        if note:
            result.notes.append(note)
        if result.sensitivity is not None:
            atomic_write_text(out / "sensitivity.csv", result.sensitivity.to_csv(index=False))
            result.files.append(out / "sensitivity.csv")
            if plots:
                result.files.append(_save_png(plot_sensitivity(result.sensitivity, plan.name, base.case.name),
                                              out / "sensitivity.png"))
    if plots:
        for axis in plan.swept:
            path = out / f"sweep_{axis.key}.png"
            result.files.append(_save_png(plot_trends(table, plan, axis.key, base.case.name), path))
    meta = {"case": base.case.name, "case_source": base.source, "engine": engine, "design": plan.name, "seed": seed,
            "axes": {a.key: {"spec": a.spec, "unit": a.unit, "values": a.values, "low": a.low, "high": a.high,
                             "log": a.log} for a in plan.swept},
            "fixed": plan.fixed, "points": len(table), "distinct_points": int(table["hash"].replace("", np.nan)
                                                                             .nunique()),
            "ran": result.ran, "skipped": result.skipped, "failed_points": int((table["status"] != "done").sum()),
            "points_folder": str(points), "metrics": {m: {"unit": u, "meaning": d} for m, (u, d) in METRICS.items()},
            "salib_problem": plan.problem, "command_line": command_line, **source_commit(), "notes": result.notes}
    atomic_write_text(out / "sweep.json", to_json(meta))
    result.files.append(out / "sweep.json")


def write_netcdf(table: pd.DataFrame, plan: Design, path: Path, base: Case) -> Path:
    """sweep.nc: the table as an xarray Dataset (h5netcdf), gridded over the swept keys for a grid, over ``point``
    for a sampled design; units in each variable's attrs. Written to a temporary file, then renamed."""
    import xarray as xr

    keys = [a.key for a in plan.swept]
    columns = ["hash", *METRICS, "status", "error"]
    if plan.name == "grid" and keys:
        frame = table.set_index(keys)[columns]
    else:
        frame = table.set_index("point")[keys + columns]
    dataset = xr.Dataset.from_dataframe(frame)
    for name, (unit, meaning) in METRICS.items():
        dataset[name].attrs.update(units=unit, long_name=meaning)
    for axis in plan.swept:
        dataset[axis.key].attrs.update(units=axis.unit or "-", sweep_spec=axis.spec)
    dataset.attrs.update(case=base.case.name, design=plan.name, fixed_overrides=json.dumps(plan.fixed),
                         matte_loss="mass_lost / mass_fed at the last output (popbal time series)",
                         settler_case=base.to_toml())
    return write_dataset(dataset, path)


def write_dataset(dataset, path: Path) -> Path:
    """Write an xarray Dataset as netCDF (h5netcdf) with CF-1.10 attributes (:func:`analysis.cf.apply`) to a
    temporary file beside ``path``, then rename it."""
    from ..cf import apply

    dataset = apply(dataset.copy(deep=False), title=f"settler sweep {dataset.attrs.get('case', '')}".strip(),
                    case_toml=dataset.attrs.get("settler_case"))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        dataset.to_netcdf(tmp, engine="h5netcdf")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
