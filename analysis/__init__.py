"""analysis: what is done with stored runs, apart from the engines.

- :mod:`analysis.runs`: :func:`load_run` reads a run folder of either engine (``settler full`` / ``settler
  reduced``) or a stored ``data/reference/<case>`` folder: time series, resolved case, metadata, merges by size,
  channel profile, snapshots on demand, and popbal's size distribution as an xarray Dataset (netCDF through
  h5netcdf).
- :mod:`analysis.compare`: ``analysis.compare.compare(full, reduced)`` compares a full run with a reduced run
  column by column (relative errors of the window means; ``settler compare FULL REDUCED --out DIR``).
- :mod:`analysis.figures`: the seed paper's figures (Jylhä & Jokilaakso, Heliyon 2023) drawn from a ``settler
  full`` run folder (``settler figures RUN``); it reads files only and imports no engine.
- :mod:`analysis.reference`: full runs stored small as ``data/reference/<case>/``.
"""

from .runs import Run, load_run

__all__ = ["Run", "load_run"]
