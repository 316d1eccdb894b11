"""settler: matte-droplet settling in copper flash-smelting settlers.

Shared layer of the toolkit: droplet physics (:mod:`settler.physics`), case files (:mod:`settler.cases`),
thermochemistry (:mod:`settler.thermo`) and the ``settler`` command line. The engines live in :mod:`fulldem`
(CFD-DEM) and :mod:`popbal` (population balance); :mod:`analysis` compares them.
"""

__version__ = "0.1.0"

# Numba's cache in a folder per source version (kernels that inline other files' functions are otherwise not
# recompiled when those change); before any kernel of settler, fulldem or popbal is compiled.
from .numba_cache import configure as _configure_numba_cache  # noqa: E402

_configure_numba_cache()
