"""Parameter sweeps of the reduced model (popbal) or of the full engine: matte loss, settled fraction and droplet
size over a grid or a sampled design of case keys, or over a set of named runs, executed on dask.distributed,
resumable point by point.

``settler sweep CASE key=v1,v2,... key2=a:b:n [--design grid|lhs|sobol|morris] [--samples N] [--out DIR]
[--workers N] [--scheduler ADDRESS] [--seed S] [--engine reduced|full]`` (see :func:`add_arguments`) and
:func:`sweep` from Python; ``settler sweep --set FILE [--only a,b] [--engine full]`` and :func:`sweep_set` for a run
set (:mod:`.runset`: named runs, each its own case, such as ``data/reference/design.toml``). With ``--engine full``
every point is a fulldem run in its point folder that checkpoints as it goes and resumes from its checkpoint when the
same command runs again.

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

Layout: :mod:`.axes` (parsing), :mod:`.designs` (grid and SALib samples), :mod:`.execution` (points, tasks,
outputs), :mod:`.results` (sensitivity, plots), :mod:`.furnace` (the furnace study), :mod:`.command` (the command
line). :func:`furnace_study` is the matte-loss study of the furnace preset (trends and global sensitivity) that the
trends report calls. Analysis above the engines: this module uses popbal's public API only (setup, run,
Result.save), imported in the tasks.
"""

from .axes import Axis, parse_axes, parse_axis
from .command import add_arguments, main
from .designs import DEFAULT_SAMPLES, DESIGNS, MORRIS_LEVELS, Design, build_design
from .execution import (DONE_FILE, ENGINES, ERROR_FILE, METRICS, POINTS, Executor, SweepResult, check_workers, point_hash,
                        read_done, run_point, summarize, sweep, warm_numba, write_netcdf)
from .furnace import (FURNACE_AXES, FURNACE_BASE, FURNACE_MORRIS_TRAJECTORIES, FURNACE_QUICK, FURNACE_SOBOL_SAMPLES,
                      TREND_POINTS, furnace_study, plot_study, ranking)
from .results import ANALYSED, PLOTTED, RESAMPLES, plot_sensitivity, plot_trends, sensitivity
from .runset import RunSet, SetResult, SetRun, load_run_set, sweep_set

__all__ = ["ANALYSED", "Axis", "DEFAULT_SAMPLES", "DESIGNS", "DONE_FILE", "Design", "ENGINES", "ERROR_FILE", "Executor",
           "RunSet", "SetResult", "SetRun", "load_run_set", "sweep_set",
           "FURNACE_AXES", "FURNACE_BASE", "FURNACE_MORRIS_TRAJECTORIES", "FURNACE_QUICK", "FURNACE_SOBOL_SAMPLES",
           "METRICS", "MORRIS_LEVELS", "PLOTTED", "POINTS", "RESAMPLES", "SweepResult", "TREND_POINTS",
           "add_arguments", "build_design", "check_workers", "furnace_study", "main", "parse_axes", "parse_axis",
           "plot_sensitivity", "plot_study", "plot_trends", "point_hash", "ranking", "read_done", "run_point",
           "sensitivity", "summarize", "sweep", "warm_numba", "write_netcdf"]
