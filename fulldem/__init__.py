"""fulldem: the coupled CFD-DEM engine (slag on a grid, every matte droplet a soft sphere).

Python API (:mod:`fulldem.api`)::

    setup = fulldem.setup("demo", fulldem__end_time=2.0)    # a validated case; overrides as section__key=value
    result = fulldem.run(setup, out="runs/demo")            # runs it into a folder; result.timeseries, .droplets()
    result = fulldem.load("runs/demo")                      # a finished (or stopped) run's results

The droplet laws it uses live in :mod:`settler.physics`.

Threading layer. Numba's default order is TBB, then OpenMP, then its own workqueue. With the TBB library of
Debian 12 (libtbb12 2021.8, installed for example with the ``liggghts`` package) the cost of launching a parallel
region grows the longer a process runs: a 16 x 16 x 48 loop went from 0.05 to 0.3 ms per call over 10 000 calls,
and a coupled step (3 600 droplets) from 29 to 230 ms over 300 steps, while with OpenMP it stays at 0.004 ms and
7-14 ms (measured 2026-11-22, numba 0.68.1, 2 cores). An engine that launches tens of parallel regions per step
therefore prefers OpenMP, then workqueue, then TBB. Setting ``NUMBA_THREADING_LAYER`` or
``NUMBA_THREADING_LAYER_PRIORITY`` in the environment overrides this choice.

OpenMP's threads spin while they wait. Two processes on 2 cores then slow each other down about fivefold; give each
``OMP_WAIT_POLICY=passive`` or ``NUMBA_NUM_THREADS=1`` (README, speed). A process alone runs 15-30 % faster spinning,
so spinning is left on.
"""

import os

import numba

import settler  # noqa: F401 (first: it points Numba's cache at this source version, see settler.numba_cache)

#: The threading layers fulldem asks numba for, best first (see the module docstring).
THREADING_LAYER_PRIORITY = ("omp", "workqueue", "tbb")

if "NUMBA_THREADING_LAYER" not in os.environ and "NUMBA_THREADING_LAYER_PRIORITY" not in os.environ:
    # the environment variable survives numba's config reloads (done at each compilation) and reaches child
    # processes; the config attribute takes effect even when every kernel comes from the cache
    os.environ["NUMBA_THREADING_LAYER_PRIORITY"] = " ".join(THREADING_LAYER_PRIORITY)
    numba.config.THREADING_LAYER_PRIORITY = list(THREADING_LAYER_PRIORITY)

# The Python API (see fulldem.api): setup a case, run it into a folder, load a run's results.
from .api import Result, Setup, load, run, setup  # noqa: E402 (after the threading layer is chosen)
from .driver import RunError, RunInterrupted, RunRefused  # noqa: E402

__all__ = ["Result", "RunError", "RunInterrupted", "RunRefused", "Setup", "THREADING_LAYER_PRIORITY", "load", "run", "setup"]
