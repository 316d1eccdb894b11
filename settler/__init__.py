"""settler: matte-droplet settling in copper flash-smelting settlers.

Shared layer of the toolkit: droplet physics (:mod:`settler.physics`), case files (:mod:`settler.cases`),
thermochemistry (:mod:`settler.thermo`) and the ``settler`` command line. The engines live in :mod:`fulldem`
(CFD-DEM) and :mod:`popbal` (population balance); :mod:`analysis` compares them.
"""

__version__ = "0.1.0"
