"""analysis: what is done with stored runs, apart from the engines.

What belongs here: reading run folders and stored reference runs, comparing, calibrating, sweeping, drawing and
reporting -- above both engines, through their public APIs (``fulldem``, ``popbal``) or their files only; neither
engine imports this package (tests/test_layout.py).

- :mod:`analysis.files`: the run-folder readers (snapshot list, droplet and slag snapshot files, JSON), importing
  no other analysis module;

- :mod:`analysis.runs`: :func:`load_run` reads a run folder of either engine (``settler full`` / ``settler
  reduced``) or a stored ``data/reference/<case>`` folder: time series, resolved case, metadata, merges by size,
  channel profile, snapshots on demand, and popbal's size distribution as an xarray Dataset (netCDF through
  h5netcdf).
- :mod:`analysis.compare`: ``analysis.compare.compare(full, reduced)`` compares a full run with a reduced run
  column by column (relative errors of the window means; ``settler compare FULL REDUCED --out DIR``).
- :mod:`analysis.figures`: the seed paper's figures (Jylhä & Jokilaakso, Heliyon 2023) drawn from a ``settler
  full`` run folder (``settler figures RUN``); it reads files only and imports no engine.
- :mod:`analysis.reference`: full runs stored small as ``data/reference/<case>/``.
- :mod:`analysis.calibrate`, :mod:`analysis.sweep` (a package: axes, designs, execution, results, the furnace
  study), :mod:`analysis.report`, :mod:`analysis.verification`: ``settler calibrate``, ``settler sweep``,
  ``settler report`` and the verification table.
"""

from .runs import Run, load_run

__all__ = ["Run", "load_run"]
