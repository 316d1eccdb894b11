"""Parameter sweeps of the reduced model (popbal): matte loss, settled fraction and droplet size over a grid or a
sampled design of case keys, executed on dask.distributed, resumable point by point.

``settler sweep CASE key=v1,v2,... key2=a:b:n [--design grid|lhs|sobol|morris] [--samples N] [--out DIR]
[--workers N] [--scheduler ADDRESS] [--seed S]`` (see :func:`add_arguments`) and :func:`sweep` from Python.

Axes (:func:`parse_axis`): ``section.key`` is a key of :data:`settler.cases.SCHEMA`; its values are

* ``v1,v2,...`` -- a list (numbers, ``true``/``false``, names; a list-valued key takes ``[a, b],[c, d]``);
* ``a:b:n`` -- n values evenly spaced on a *linear* scale from a to b inclusive; ``a:b:n:log`` -- evenly spaced on
  a logarithmic scale (a, b > 0). Integer keys must land on integers;
* a single value -- not swept: a fixed override of every point.

Every value and every point goes through :func:`settler.cases.case_with_overrides`, so each point is a validated
case. Designs: ``grid`` is the full factorial of the axes; ``lhs`` (Latin hypercube), ``sobol`` (Saltelli/Sobol'
sequence, first- and total-order indices) and ``morris`` (elementary effects, ``MORRIS_LEVELS`` levels) sample the
ranges ``a:b`` with SALib (bounds a and b; n is not used; ``:log`` samples log10 of the value uniformly). Points per
design from ``--samples N``: lhs N, sobol N (D + 2) (N a power of 2), morris N (D + 1), for D swept keys.

Each point is a task keyed by a hash of its resolved case (:func:`point_hash`): ``OUT/points/<hash>/`` holds
popbal's own output (:meth:`popbal.Result.save`; time series, case and metadata, and distribution.npz only with
``distribution=True`` / ``--distribution``) and, written last and atomically, ``done.json`` with the point's
numbers; a rerun skips every point that has it. A point that fails writes ``error.json`` instead and is retried by
the next run; the sweep goes on, records the error in the table and :func:`main` exits 3 saying how many failed.

What is measured per point (:data:`METRICS`; at the run's last output, popbal's time series):

* ``matte_loss`` = mass_lost / mass_fed: the matte that left with the slag over the matte fed [-];
* ``settled_fraction`` = mass_settled / mass_fed and ``suspended_fraction`` = mass_in_slag / mass_fed [-];
* ``mean_diameter``, ``sauter_diameter`` [m]: number-mean and d32 of the droplets in the slag at the last output
  that still holds droplets (``size_time`` [s]; with horizontal slag flow the column is emptied into the loss at the
  tap hole, so this is the output before it);
* ``slag_viscosity`` [Pa s] and ``residence_time`` [s] of the point's case (derived), ``wall_time`` [s] of the task.

Outputs in OUT: ``sweep.csv`` (one row per design point: point, hash, the swept keys, the metrics, status, error;
a ``# units:`` first line), ``sweep.nc`` (the same as an xarray Dataset, h5netcdf; a grid has one dimension per swept
key, a sampled design the dimension ``point``), ``sweep.json`` (design, axes, fixed overrides, counts, timing),
``sweep_<key>.png`` (loss, settled fraction and mean size against each swept key), and for sobol/morris
``sensitivity.csv`` and ``sensitivity.png`` (SALib's indices of loss, settled fraction and mean diameter).

Execution: a :class:`distributed.LocalCluster` of ``--workers`` processes with one thread each and
``NUMBA_NUM_THREADS=1`` in their environment (set by the nanny before the worker process starts, so before Numba is
imported there), or the cluster at ``--scheduler ADDRESS`` (dask-jobqueue, ``dask scheduler``), or ``--workers 0``:
in this process, no dask. The Numba cache is filled once in this process before fanning out (a tiny run of each
distinct combination of non-numeric values): several processes filling it at once crash Numba. On an external
cluster each worker is warmed in turn as well (its cache folder may not be this machine's).

:func:`furnace_study` is the matte-loss study of the furnace preset (trends and global sensitivity) that the
trends report calls. Analysis above the engines: this module uses popbal's public API only (setup, run,
Result.save), imported in the tasks.
"""

from __future__ import annotations

import hashlib
import io
import itertools
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

from settler.cases import SCHEMA, Case, CaseError, case_with_overrides, parse_override, resolve
from settler.output import OutputError, atomic_write_text, prepare_output_folder, source_commit, to_json

DESIGNS = ("grid", "lhs", "sobol", "morris")
#: --samples when not given: LHS points, Sobol base samples N (N (D + 2) points), Morris trajectories (N (D + 1)).
DEFAULT_SAMPLES = {"lhs": 32, "sobol": 16, "morris": 10}
#: Levels of the Morris grid (SALib's default; elementary-effect step 2/3 of the range).
MORRIS_LEVELS = 4
#: Bootstrap resamples of SALib's confidence intervals (95 %).
RESAMPLES = 200

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
#: Metrics plotted against each swept key and analysed for sensitivity: name -> (axis label, scale to the label).
PLOTTED = {"matte_loss": ("matte loss [%]", 100.0), "settled_fraction": ("settled fraction [%]", 100.0),
           "mean_diameter": ("mean diameter at size_time [um]", 1e6)}
#: Outputs whose sensitivity indices are computed: name -> title. log10_matte_loss ranks relative (factor) changes:
#: where the loss spans decades over the box, the variance of the loss itself is set by the few points with the
#: largest loss (analysed only when every loss is > 0).
ANALYSED = {"matte_loss": "matte loss", "log10_matte_loss": "log10 of the matte loss",
            "settled_fraction": "settled fraction", "mean_diameter": "mean diameter"}
DONE_FILE = "done.json"
ERROR_FILE = "error.json"
POINTS = "points"
#: Resolution of the PNGs [dots per inch].
DPI = 120
#: Lines drawn per panel of a grid's trend plot (one per combination of the other axes); more are summarised.
MAX_LINES = 8


# ------------------------------------------------------------------------------------------------------------ axes
@dataclass(frozen=True)
class Axis:
    """One swept case key. ``values``: the listed or spaced values (None for a bare range ``a:b``); ``low``,
    ``high``: the range of ``a:b[:n]`` (None for a list); ``log``: spaced / sampled on a log scale."""

    key: str
    spec: str
    values: tuple | None
    low: float | None = None
    high: float | None = None
    log: bool = False

    @property
    def unit(self) -> str:
        section, name = self.key.split(".")
        return SCHEMA[section][name].unit

    @property
    def fixed(self) -> bool:
        """A single value: a fixed override, not a swept axis."""
        return self.values is not None and len(self.values) == 1

    @property
    def is_range(self) -> bool:
        return self.low is not None


def _field(key: str):
    """The schema field of ``section.key``; CaseError naming the key and the allowed keys otherwise."""
    section, dot, name = key.partition(".")
    if not dot or section not in SCHEMA:
        raise CaseError(f"sweep axis {key!r}: not a section.key of the case; allowed sections: " + ", ".join(SCHEMA))
    if name not in SCHEMA[section]:
        raise CaseError(f"sweep axis {key!r}: unknown key {key}; allowed keys in [{section}]: "
                        + ", ".join(SCHEMA[section]))
    return SCHEMA[section][name]


def _number(key: str, text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise CaseError(f"sweep axis {key}: {what} {text!r} is not a number; allowed: a:b:n or a:b:n:log with "
                        "numbers a, b and an integer n >= 1") from None
    if not math.isfinite(value):
        raise CaseError(f"sweep axis {key}: {what} {text!r}: allowed: a finite number")
    return value


def _spaced(key: str, spec: str, kind: type) -> tuple[tuple | None, float, float, bool]:
    """(values, a, b, log) of ``a:b[:n[:lin|log]]``; values None without n."""
    parts = spec.split(":")
    scale = "lin"
    if len(parts) == 4:
        scale = parts.pop().strip().lower()
        if scale not in ("lin", "log"):
            raise CaseError(f"sweep axis {key} = {spec!r}: scale {scale!r}; allowed: lin or log (a:b:n:log)")
    if len(parts) not in (2, 3):
        raise CaseError(f"sweep axis {key} = {spec!r}: allowed: a:b:n (n values from a to b, linear), "
                        "a:b:n:log (logarithmic) or v1,v2,...")
    low, high = _number(key, parts[0], "a"), _number(key, parts[1], "b")
    log = scale == "log"
    if log and not (low > 0.0 and high > 0.0):
        raise CaseError(f"sweep axis {key} = {spec!r}: a log scale needs a > 0 and b > 0")
    if len(parts) == 2:
        return None, low, high, log
    try:
        count = int(parts[2])
    except ValueError:
        count = 0
    if count < 1:
        raise CaseError(f"sweep axis {key} = {spec!r}: n = {parts[2]!r}; allowed: an integer >= 1")
    values = np.geomspace(low, high, count) if log else np.linspace(low, high, count)
    if kind is int:
        rounded = np.round(values)
        if np.any(np.abs(values - rounded) > 1e-9 * np.maximum(1.0, np.abs(values))):
            raise CaseError(f"sweep axis {key} = {spec!r}: {key} takes integers, and these values are not "
                            f"({', '.join(f'{v:g}' for v in values)}); choose n so that they are, or list them")
        return tuple(int(v) for v in rounded), low, high, log
    return tuple(float(v) for v in values), low, high, log


def _listed(key: str, spec: str) -> tuple:
    """The values of ``v1,v2,...``: read as a TOML array (numbers, booleans, lists), else split at commas and each
    read as an override value (settler.cases.parse_override: TOML, else a string)."""
    import tomllib

    try:
        values = tomllib.loads(f"v = [{spec}]")["v"]
    except tomllib.TOMLDecodeError:
        values = [parse_override(f"{key}={item}")[1] for item in spec.split(",")]
    if not values or any(v == "" for v in values):
        raise CaseError(f"sweep axis {key} = {spec!r}: an empty value; allowed: v1,v2,... or a:b:n")
    return tuple(values)


def parse_axis(text: str, base: Case | None = None) -> Axis:
    """An :class:`Axis` from ``section.key=SPEC`` (see the module docstring). With ``base``, every value is
    validated on it (CaseError naming the key, the value and what is allowed)."""
    key, eq, spec = (t.strip() for t in text.partition("="))
    if not eq or not spec:
        raise CaseError(f"sweep axis {text!r}: allowed: section.key=v1,v2,... or section.key=a:b:n[:log]")
    spec_field = _field(key)
    if ":" in spec and not spec.lstrip().startswith(("[", '"', "'")):
        if spec_field.kind not in (float, int):
            raise CaseError(f"sweep axis {key} = {spec!r}: a range a:b:n needs a numeric key; {key} takes "
                            f"{spec_field.allowed()}: list its values v1,v2,...")
        values, low, high, log = _spaced(key, spec, spec_field.kind)
        axis = Axis(key, spec, values, low, high, log)
    else:
        values = _listed(key, spec)
        if len(set(map(repr, values))) != len(values):
            raise CaseError(f"sweep axis {key} = {spec!r}: a value is listed twice; allowed: distinct values")
        axis = Axis(key, spec, values)
    if base is not None:
        for value in axis.values or (axis.low, axis.high):
            if spec_field.kind is int and isinstance(value, float):
                value = round(value)
            try:
                case_with_overrides(base, {key: value})
            except CaseError as exc:
                raise CaseError(f"sweep axis {key}: {exc}") from None
    return axis


def parse_axes(axes, base: Case | None = None) -> list[Axis]:
    """Axes from a list of ``section.key=SPEC`` strings, or a dict key -> SPEC string or list of values."""
    if isinstance(axes, dict):
        texts = [f"{k}={v}" if isinstance(v, str) else f"{k}={','.join(_toml_item(x) for x in v)}"
                 for k, v in axes.items()]
    else:
        texts = list(axes)
    parsed = [parse_axis(t, base) for t in texts]
    keys = [a.key for a in parsed]
    repeated = sorted({k for k in keys if keys.count(k) > 1})
    if repeated:
        raise CaseError(f"sweep axis {repeated[0]}: given more than once; allowed: one axis per key")
    return parsed


def _toml_item(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_item(v) for v in value) + "]"
    return repr(float(value)) if isinstance(value, float) else repr(value)


# ---------------------------------------------------------------------------------------------------------- design
@dataclass
class Design:
    """The points of a design: ``table`` one row per point, one column per swept key (values as given to the
    case); ``problem`` and ``samples`` (the SALib problem and its sample matrix, in log10 for log axes) for
    sampled designs."""

    name: str
    swept: list[Axis]
    fixed: dict
    table: pd.DataFrame
    problem: dict | None = None
    samples: np.ndarray | None = None


def _salib_name(axis: Axis) -> str:
    return f"log10({axis.key})" if axis.log else axis.key


def build_design(axes: list[Axis], design: str = "grid", samples: int | None = None, seed: int = 0) -> Design:
    """The design's points (see the module docstring). CaseError for a design that the axes cannot make."""
    if design not in DESIGNS:
        raise CaseError(f"--design {design!r}: allowed: " + ", ".join(DESIGNS))
    fixed = {a.key: a.values[0] for a in axes if a.fixed}
    swept = [a for a in axes if not a.fixed]
    if design == "grid":
        if samples is not None:
            raise CaseError(f"--samples {samples}: allowed only with --design lhs, sobol or morris (a grid has the "
                            "points of its axes)")
        bare = [a for a in swept if a.values is None]
        if bare:
            raise CaseError(f"sweep axis {bare[0].key} = {bare[0].spec!r}: a grid needs the number of values: a:b:n")
        rows = list(itertools.product(*(a.values for a in swept)))
        table = pd.DataFrame(rows if swept else [()], columns=[a.key for a in swept])
        return Design(design, swept, fixed, table)
    not_range = [a for a in swept if not a.is_range]
    if not swept:
        raise CaseError(f"--design {design}: needs at least one range axis section.key=a:b")
    if not_range:
        raise CaseError(f"sweep axis {not_range[0].key} = {not_range[0].spec!r}: --design {design} samples ranges; "
                        "allowed: a:b (or a:b:n, n unused; a:b:n:log for a log scale)")
    n = DEFAULT_SAMPLES[design] if samples is None else samples
    if isinstance(n, bool) or not isinstance(n, int) or n < (1 if design == "lhs" else 2):
        raise CaseError(f"--samples {n!r}: allowed: an integer >= {1 if design == 'lhs' else 2}")
    if design == "sobol" and n & (n - 1):
        raise CaseError(f"--samples {n}: allowed: a power of 2 for --design sobol (Sobol' sequences are balanced at "
                        "2^k points)")
    problem = {"num_vars": len(swept), "names": [_salib_name(a) for a in swept],
               "bounds": [[math.log10(a.low), math.log10(a.high)] if a.log else [a.low, a.high] for a in swept]}
    x = _sample(design, problem, n, seed)
    table = pd.DataFrame({a.key: _from_sample(a, x[:, i]) for i, a in enumerate(swept)})
    return Design(design, swept, fixed, table, problem, x)


def _sample(design: str, problem: dict, n: int, seed: int) -> np.ndarray:
    """SALib's sample matrix (points x keys) of a sampled design."""
    from SALib.sample import latin, morris, sobol

    if design == "lhs":
        return latin.sample(problem, n, seed=seed)
    if design == "sobol":
        return sobol.sample(problem, n, calc_second_order=False, seed=seed)
    return morris.sample(problem, n, num_levels=MORRIS_LEVELS, seed=seed)


def _from_sample(axis: Axis, column: np.ndarray) -> list:
    values = 10.0**column if axis.log else column
    if _field(axis.key).kind is int:
        return [int(round(v)) for v in values]
    return [float(v) for v in values]


# ---------------------------------------------------------------------------------------------------------- points
def point_hash(case: Case) -> str:
    """16 hex digits of the SHA-256 of the resolved case (every key, sorted, as JSON): equal cases share a folder,
    however their values were given."""
    text = json.dumps(case.to_dict(), sort_keys=True, separators=(",", ":"))
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


def run_point(case_dict: dict, folder: str, source: str = "", distribution: bool = False) -> dict:
    """Run one point (the task a worker executes): popbal on the resolved case ``case_dict``, its output saved into
    ``folder`` (popbal's Result.save; distribution.npz only if ``distribution``, as the table needs only the time
    series), then ``done.json`` with :data:`METRICS` written last, atomically. An error is recorded in
    ``error.json`` and returned (status 'failed'), not raised."""
    if "numba" not in sys.modules:  # a fresh worker process: one Numba thread. Never once Numba is loaded: Numba
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # re-reads the variable and refuses a change (in-process runs)
    import popbal

    started = time.perf_counter()
    folder = Path(folder)
    record = {"hash": folder.name}
    try:
        case = resolve(case_dict, None, source)
        result = popbal.run(popbal.setup(case), progress=False)
        result.save(folder, distribution=distribution)
        record.update(summarize(result.timeseries), slag_viscosity=case.slag_viscosity,
                      residence_time=result.model.residence_time, status="done", error="",
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


def warm_numba(case_dicts: list[dict]) -> None:
    """Fill (or load) the Numba cache with a tiny run of each case: 4 cells, one section per doubling, three time
    steps. Errors are left to the points themselves."""
    import popbal

    for case_dict in case_dicts:
        try:
            tiny = resolve(case_dict).replace(popbal__height_cells=4, popbal__sections_per_doubling=1)
            model = popbal.setup(tiny)
            span = min(3.0 * tiny.popbal.time_step, model.stop_time)
            popbal.run(model, end_time=span, output_interval=span, progress=False)
        except Exception:  # noqa: BLE001 -- the same error is recorded when the point runs
            continue


# ----------------------------------------------------------------------------------------------------- execution
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

    def warm_workers(self, case_dicts: list[dict]) -> None:
        """On an external cluster, warm each worker's Numba cache in turn (never two at once)."""
        if self.local or not self.external:
            return
        for address in sorted(self.client.scheduler_info()["workers"]):
            self.client.run(warm_numba, case_dicts, workers=[address])

    def map(self, tasks: list[tuple[dict, str, str, bool]], progress: bool):
        """Yield the record of each task (case_dict, folder, source, distribution) as it finishes, with a tqdm
        bar."""
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


# ---------------------------------------------------------------------------------------------------------- sweep
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
          plots: bool = True, command_line: str | None = None, distribution: bool = False) -> SweepResult:
    """Run popbal over a design of case keys and write the table, netCDF, plots (and sensitivity) into ``out``.

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
    base = case if isinstance(case, Case) else case_with_overrides(case)
    parsed = parse_axes(axes, base)
    plan = build_design(parsed, design, samples, seed)
    out = prepare_output_folder(out, resume=True)
    points = Path(points_dir) if points_dir is not None else out / POINTS
    fixed_base = case_with_overrides(base, plan.fixed) if plan.fixed else base
    cases, errors = _point_cases(fixed_base, plan)
    hashes = [point_hash(c) if c is not None else "" for c in cases]
    records, tasks = {}, {}
    for case_, digest in zip(cases, hashes):
        if case_ is None or digest in records or digest in tasks:
            continue
        done = read_done(points / digest)
        if done is not None:
            records[digest] = {**done, "resumed": True}
        else:
            tasks[digest] = (case_.to_dict(), str(points / digest), base.source, distribution)
    # no cluster is started when every point is done
    with Executor(workers if tasks else 0, scheduler if tasks else None, client) as executor:
        if progress:
            print(f"sweep {base.case.name}: {len(plan.table)} design points, {len(records)} already done, "
                  f"{len(tasks)} to run on {executor.describe()}", file=sys.stderr)
        if tasks and not executor.local:  # one process fills the cache as it goes; several must not
            warm = [c.to_dict() for c in _warm_cases([c if h in tasks else None for c, h in zip(cases, hashes)],
                                                      plan)]
            warm_numba(warm)
            executor.warm_workers(warm)
        for record in executor.map(list(tasks.values()), progress):
            records[record["hash"]] = {**record, "resumed": False}
    table = _table(plan, hashes, records, errors)
    result = SweepResult(table, plan, out, ran=len(tasks), skipped=len(set(records) - set(tasks)),
                         failed=int(sum(r.get("status") != "done" for r in records.values())) + len(errors))
    _write_outputs(result, base, points, command_line, plots, seed)
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


def _write_outputs(result: SweepResult, base: Case, points: Path, command_line, plots: bool, seed: int) -> None:
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
    meta = {"case": base.case.name, "case_source": base.source, "design": plan.name, "seed": seed,
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
                         matte_loss="mass_lost / mass_fed at the last output (popbal time series)")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        dataset.to_netcdf(tmp, engine="h5netcdf")
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


# ----------------------------------------------------------------------------------------------------- sensitivity
def sensitivity(table: pd.DataFrame, plan: Design, seed: int = 0) -> tuple[pd.DataFrame | None, str]:
    """SALib's indices of each :data:`ANALYSED` output over the swept keys: Sobol S1, ST (with 95 % confidence
    half-widths) or Morris mu*, mu, sigma (mu* in the output's unit per full range of the key; on log10 for log
    axes); ``rank`` 1 for the largest ST or mu* per output. (None, reason) when a point failed (the estimators need
    every point); an output that is not finite at every point (log10 of a zero loss) gets NaN indices."""
    from SALib.analyze import morris, sobol

    failed = int((table["status"] != "done").sum())
    if failed:
        return None, f"no sensitivity indices: {failed} point(s) failed, and SALib needs every point"
    rows = []
    for metric in ANALYSED:
        if metric == "log10_matte_loss":
            with np.errstate(divide="ignore", invalid="ignore"):
                y = np.log10(table["matte_loss"].to_numpy(dtype=float))
        else:
            y = table[metric].to_numpy(dtype=float)
        if not np.all(np.isfinite(y)):
            rows += [{"metric": metric, "parameter": a.key} for a in plan.swept]
            continue
        if plan.name == "sobol":
            s = sobol.analyze(plan.problem, y, calc_second_order=False, num_resamples=RESAMPLES, seed=seed)
            values = {"S1": s["S1"], "S1_conf": s["S1_conf"], "ST": s["ST"], "ST_conf": s["ST_conf"]}
        else:
            s = morris.analyze(plan.problem, plan.samples, y, num_resamples=RESAMPLES, num_levels=MORRIS_LEVELS,
                               seed=seed)
            values = {"mu_star": s["mu_star"], "mu_star_conf": s["mu_star_conf"], "mu": s["mu"],
                      "sigma": s["sigma"]}
        for i, axis in enumerate(plan.swept):
            rows.append({"metric": metric, "parameter": axis.key, "scale": "log10" if axis.log else "linear",
                         **{k: float(v[i]) for k, v in values.items()}})
    frame = pd.DataFrame(rows)
    score = "ST" if plan.name == "sobol" else "mu_star"
    if score in frame:
        frame["rank"] = frame.groupby("metric")[score].rank(ascending=False, method="min")
    return frame, ""


# ---------------------------------------------------------------------------------------------------------- plots
def _save_png(fig, path: Path) -> Path:
    from settler.output import atomic_write_bytes

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    fig.clear()
    atomic_write_bytes(path, buffer.getvalue())
    return path


def _axis_label(key: str) -> str:
    unit = _field(key).unit
    return f"{key} [{unit}]" if unit and unit != "-" else key


def _style(ax, key: str, metric: str, values) -> None:
    """Axis label and grid; scientific x ticks for small numbers (diameters in m); a log y axis for the loss when
    it spans more than two decades (all > 0)."""
    ax.set_xlabel(_axis_label(key))
    if _field(key).kind in (float, int):
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
    y = np.asarray(values, dtype=float)
    y = y[np.isfinite(y)]
    if metric == "matte_loss" and y.size and y.min() > 0.0 and y.max() > 100.0 * y.min():
        ax.set_yscale("log")
    ax.grid(alpha=0.3)


def _positions(values: pd.Series):
    """x positions of a column: numbers as they are, anything else as categories (positions, tick labels)."""
    if pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values):
        return values.astype(float).to_numpy(), None
    labels = list(dict.fromkeys(map(str, values)))
    return np.array([labels.index(str(v)) for v in values], dtype=float), labels


def plot_trends(table: pd.DataFrame, plan: Design, key: str, title: str = ""):
    """Loss, settled fraction and mean diameter (:data:`PLOTTED`) against one swept key: a grid draws a line per
    combination of the other keys (at most MAX_LINES, else the median over them with its range); a sampled design
    a scatter. Failed points are left out."""
    from matplotlib.figure import Figure

    ok = table[table["status"] == "done"]
    others = [a.key for a in plan.swept if a.key != key]
    fig = Figure(figsize=(12, 3.6), layout="constrained")
    axes = fig.subplots(1, len(PLOTTED))
    for ax, (metric, (label, scale)) in zip(axes, PLOTTED.items()):
        labels = None
        if plan.name != "grid":
            x, labels = _positions(ok[key])
            ax.scatter(x, ok[metric] * scale, s=12, alpha=0.7)
        else:
            groups = list(ok.groupby(others, sort=True)) if others else [((), ok)]
            if len(groups) <= MAX_LINES:
                for name, group in groups:
                    group = group.sort_values(key)
                    x, labels = _positions(group[key])
                    text = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                                     for k, v in zip(others, name if isinstance(name, tuple) else (name,)))
                    ax.plot(x, group[metric] * scale, "o-", ms=3, label=text or None)
            else:
                summary = ok.groupby(key, sort=True)[metric].agg(["median", "min", "max"]).reset_index()
                x, labels = _positions(summary[key])
                ax.plot(x, summary["median"] * scale, "o-", ms=3, label=f"median over {len(groups)} others")
                ax.fill_between(x, summary["min"] * scale, summary["max"] * scale, alpha=0.25, label="range")
        if labels is not None:
            ax.set_xticks(range(len(labels)), labels)
            ax.set_xlabel(_axis_label(key))
            ax.grid(alpha=0.3)
        else:
            _style(ax, key, metric, ok[metric])
        ax.set_ylabel(label)
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(fontsize=7)
    fig.suptitle(f"{title}: {plan.name} sweep over {key}" if title else f"{plan.name} sweep over {key}")
    return fig


def plot_sensitivity(frame: pd.DataFrame, design: str, title: str = ""):
    """Bar chart of the sensitivity indices: one panel per metric, one bar (group) per swept key, with the 95 %
    confidence half-widths: Sobol S1 and ST, or Morris mu* (normalised by its largest value, so the panels share a
    scale)."""
    from matplotlib.figure import Figure

    metrics = [m for m in dict.fromkeys(frame["metric"])
               if frame.loc[frame["metric"] == m].notna().all(axis=None)]
    fig = Figure(figsize=(4.2 * len(metrics), 0.5 * frame["parameter"].nunique() + 2.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(metrics), sharey=True))
    for ax, metric in zip(axes, metrics):
        part = frame[frame["metric"] == metric]
        y = np.arange(len(part))
        if design == "sobol":
            ax.barh(y - 0.2, part["S1"], 0.4, xerr=part["S1_conf"], label="first order S1")
            ax.barh(y + 0.2, part["ST"], 0.4, xerr=part["ST_conf"], label="total order ST")
            ax.set_xlabel("Sobol index")
        else:
            top = float(part["mu_star"].max()) or 1.0
            ax.barh(y, part["mu_star"] / top, 0.6, xerr=part["mu_star_conf"] / top, label="mu* / max mu*")
            ax.set_xlabel("Morris mu* (relative)")
        ax.set_yticks(y, part["parameter"])
        ax.set_title(ANALYSED[metric])
        ax.grid(alpha=0.3, axis="x")
        ax.legend(fontsize=7)
    fig.suptitle(f"{title}: {design} sensitivity" if title else f"{design} sensitivity")
    return fig


# --------------------------------------------------------------------------------------------- the furnace study
#: Baseline of the furnace study: the furnace preset with these overrides. The feed is a truncated normal, the only
#: feed distribution whose mean size and width are case keys, matched to the preset's table: mean 200 um with scale
#: std 0.3 on [0.1, 1.9] has a mass-mean diameter of 245 um [derived], the table's (Jylha et al. 2020, Table 2) is
#: 247 um. end_time 1e6 s so that every run stops at its own residence time (a deeper bath or a lower throughput
#: keeps the slag longer). Resolution: the preset's own (100 cells, 30 s steps, 3 sections per doubling). A coarser
#: study resolution (50 cells, 60 s, 2 per doubling) biased the baseline loss 5 % low (and 12 % low against 200
#: cells, 15 s, 4 per doubling; measured 2026-12-02 on the table feed: 8.84e-4, 9.34e-4, 1.01e-3; upwind diffusion
#: in z); it was used only for speed, until popbal's pair-list coalescence halved a point's cost: 100 points at the
#: preset's resolution took 110 s on the 2-core machine with 2 workers (load average 2.9-4.8; 168 s at 5.7-6.1),
#: benchmarks/bench_sweep.py --resolution preset, 2026-12-02. The tap hole's height, unused by the plug-flow
#: column, is lowered to 0.2 m [chosen] so that it lies inside the thinnest slag layer of the study (0.5 m).
FURNACE_BASE = {
    "feed.distribution": "normal", "feed.mean_diameter": 200e-6, "feed.scale_std": 0.3, "feed.scale_min": 0.1,
    "feed.scale_max": 1.9, "popbal.end_time": 1.0e6, "geometry.outlet_height": 0.2,
}
#: Coarser for quick=True (report CI: numbers that run in seconds, not results).
FURNACE_QUICK = {"popbal.height_cells": 20, "popbal.time_step": 120.0, "popbal.output_interval": 1800.0,
                 "popbal.sections_per_doubling": 2}
#: The study's axes: key -> (low, high, source). The one-at-a-time trends take TREND_POINTS values over each range
#: (linear; the baseline value is one of them), the others at the baseline; the global designs sample the same box.
FURNACE_AXES = {
    "slag.temperature": (1493.15, 1593.15, "[lit] 1220-1320 C, the settler slag temperatures of the seed paper "
                                           "(section 1); viscosity 0.86-0.25 Pa s by the Arrhenius law of the "
                                           "property set (0.45 Pa s at 1270 C)"),
    "feed.mean_diameter": (100e-6, 400e-6, "[chosen] around the 200 um baseline (table's mass-mean 247 um, "
                                           "Jylha et al. 2020)"),
    "feed.scale_std": (0.1, 0.4, "[chosen] narrow (0.1, the seed paper's Table 3) to wide (0.4 of the mean; the "
                                 "truncation at 0.1-1.9 is then 2.25 std)"),
    "geometry.height": (0.5, 1.5, "[chosen] slag depth around the preset's 1 m; at a fixed slag feed the residence "
                                  "time grows with it (3-9 h)"),
    "slag.feed_rate": (10.208333333333334, 40.833333333333336, "[chosen] slag throughput 0.5 to 2 times the "
                       "preset's 20.4 kg/s (derived there from a 6 h residence): residence 12 h to 3 h at 1 m"),
    "popbal.collision_efficiency": (0.0, 3.0, "[chosen] 0 (no coalescence) to 3; the calibration layer "
                                              "data/calibration/paper.toml (simple + cubic, 2026-12-02) gives 0.09 "
                                              "+- 0.25, not determined by its data (first fit, simple only: 1.60 +- "
                                              "1.35); the baseline keeps the furnace preset's uncalibrated 1, as "
                                              "the preset does not apply that layer"),
}
TREND_POINTS = 7
#: Global designs of the full study: Sobol N (points N (D + 2)), Morris trajectories (points r (D + 1)).
FURNACE_SOBOL_SAMPLES = 64
FURNACE_MORRIS_TRAJECTORIES = 20


def furnace_study(out, quick: bool = False, workers: int | None = None, scheduler: str | None = None,
                  progress: bool = True, seed: int = 0) -> dict:
    """The matte-loss study of the furnace preset (reduced model, horizontal plug flow) into ``out``.

    Trends: loss, settled fraction and mean size against each key of :data:`FURNACE_AXES` alone
    (``out/trends/<key>/``, TREND_POINTS values, the others at :data:`FURNACE_BASE`), and ``out/trends.png``.
    Global sensitivity over the whole box: Sobol (``out/sobol/``, N = FURNACE_SOBOL_SAMPLES) and Morris
    (``out/morris/``, FURNACE_MORRIS_TRAJECTORIES trajectories), each with sensitivity.csv and .png. All sweeps
    share ``out/points`` and one cluster, so a rerun or a point repeated between designs is not run again.
    quick=True: 3 values per key, Morris with 2 trajectories, no Sobol, at FURNACE_QUICK resolution, in this
    process unless ``workers`` is given, without the per-trend PNGs (seconds; for report CI). Writes
    ``ranking.csv`` (:func:`ranking`) and ``study.json`` (baseline, axes with sources). Returns {"trends": {key:
    SweepResult}, "sobol", "morris": SweepResult or None, "figure": Path, "ranking": DataFrame}. From a script,
    call it under ``if __name__ == "__main__":`` (see :func:`sweep`).
    """
    out = prepare_output_folder(out, resume=True)
    base = case_with_overrides("furnace", {**FURNACE_BASE, **(FURNACE_QUICK if quick else {})})
    points = out / POINTS
    count = 3 if quick else TREND_POINTS
    options = dict(points_dir=points, progress=progress, seed=seed)
    results: dict = {"trends": {}, "sobol": None, "morris": None}
    with Executor(0 if quick and workers is None and scheduler is None else workers, scheduler) as executor:
        options["client"] = executor.client
        options["workers"] = 0 if executor.local else None
        for key, (low, high, _) in FURNACE_AXES.items():
            results["trends"][key] = sweep(base, [f"{key}={low}:{high}:{count}"], "grid",
                                           out=out / "trends" / key, plots=not quick, **options)
        box = [f"{key}={low}:{high}" for key, (low, high, _) in FURNACE_AXES.items()]
        if not quick:
            results["sobol"] = sweep(base, box, "sobol", FURNACE_SOBOL_SAMPLES, out=out / "sobol", **options)
        results["morris"] = sweep(base, box, "morris", 2 if quick else FURNACE_MORRIS_TRAJECTORIES,
                                  out=out / "morris", **options)
    results["figure"] = _save_png(plot_study(results["trends"]), out / "trends.png")
    results["ranking"] = ranking(results)
    atomic_write_text(out / "ranking.csv", results["ranking"].to_csv(index=False))
    atomic_write_text(out / "study.json", to_json({
        "base_case": "furnace", "overrides": {**FURNACE_BASE, **(FURNACE_QUICK if quick else {})}, "quick": quick,
        "axes": {k: {"low": lo, "high": hi, "source": src} for k, (lo, hi, src) in FURNACE_AXES.items()},
        "trend_points": count, **source_commit()}))
    return results


def ranking(results: dict) -> pd.DataFrame:
    """What changes the matte loss most, one row per key of FURNACE_AXES: the one-at-a-time range of the loss
    (``trend_loss_min``, ``_max``, ``_range``) and, for each global design run, its indices of the loss and of its
    log10 (``sobol_<output>_ST``, ``_ST_conf``, ``_S1``, ``_S1_conf``; ``morris_<output>_mu_star``,
    ``_mu_star_conf``). Ordered by the first present of Morris mu* of log10 loss, Sobol ST of log10 loss, the trend
    range: relative changes, since the loss spans decades over the box."""
    rows = {key: {"parameter": key} for key in FURNACE_AXES}
    for key, trend in results["trends"].items():
        loss = trend.table["matte_loss"]
        rows[key].update(trend_loss_min=float(loss.min()), trend_loss_max=float(loss.max()),
                         trend_loss_range=float(loss.max() - loss.min()))
    indices = {"sobol": ("ST", "ST_conf", "S1", "S1_conf"), "morris": ("mu_star", "mu_star_conf")}
    for design, columns in indices.items():
        frame = results[design].sensitivity if results.get(design) is not None else None
        if frame is None:
            continue
        for _, row in frame[frame["metric"].isin(["matte_loss", "log10_matte_loss"])].iterrows():
            rows[row["parameter"]].update({f"{design}_{row['metric']}_{c}": row.get(c) for c in columns})
    table = pd.DataFrame(list(rows.values()))
    order = next((c for c in ("morris_log10_matte_loss_mu_star", "sobol_log10_matte_loss_ST", "trend_loss_range")
                  if c in table and table[c].notna().all()), None)
    return table.sort_values(order, ascending=False).reset_index(drop=True) if order else table


def plot_study(trends: dict):
    """Matte loss against each key of the one-at-a-time trends, one panel each (loss in %)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 6.5), layout="constrained")
    axes = fig.subplots(2, math.ceil(len(trends) / 2)).ravel()
    for ax, (key, trend) in zip(axes, trends.items()):
        ok = trend.table[trend.table["status"] == "done"].sort_values(key)
        ax.plot(ok[key], ok["matte_loss"] * 100.0, "o-", ms=3)
        _style(ax, key, "matte_loss", ok["matte_loss"])
        ax.set_ylabel("matte loss [%]")
    fig.suptitle("furnace: matte lost with the slag, one key at a time (others at the study baseline)")
    return fig


# ---------------------------------------------------------------------------------------------------------- command
def add_arguments(parser):
    """Arguments of ``settler sweep`` (registered in settler.cli.TOOLS)."""
    from settler.cli import _case_help

    parser.add_argument("case", help=_case_help())
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
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main(args) -> int:
    """Run ``settler sweep``: 0 every point done, 3 some failed (how many and where on stderr); refused input
    raises CaseError / OutputError (exit 2 from settler.cli)."""
    if args.scheduler is not None and args.workers is not None:
        raise CaseError(f"--workers {args.workers} with --scheduler {args.scheduler}: allowed: one of them (the "
                        "cluster's workers are started with it)")
    base = case_with_overrides(args.case)
    out = args.out if args.out is not None else f"sweep-{base.case.name}"
    try:
        result = sweep(base, args.overrides, args.design, args.samples, out, args.workers, args.scheduler,
                       args.seed, progress=not args.quiet, command_line=getattr(args, "command_line", None),
                       distribution=args.distribution)
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
