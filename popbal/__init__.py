"""popbal: the reduced population-balance settling model.

A sectional population balance in droplet volume along the height of the slag layer (1-D in z, a channel zone under
the inlet and an outer zone), with the droplet laws of :mod:`settler.physics` -- the same functions the CFD-DEM engine
calls. It answers in seconds how fast the fed matte settles, how large droplets grow by coalescence and how much
leaves with the slag.

Public API::

    model = popbal.setup("simple", popbal__end_time=30)   # a Model: arrays and parameters of a case
    result = popbal.run(model)                            # a Result: .timeseries (DataFrame), distribution arrays
    result.save("out/simple")                             # timeseries.csv, distribution.npz, case.toml, metadata.json

Layers (imports point one way): :mod:`popbal.kernels` (compiled kernels) <- :mod:`popbal.driver` (time loop) <-
:mod:`popbal.model` / :mod:`popbal.cli`. Verification helpers: :mod:`popbal.smoluchowski`; closures:
:mod:`popbal.closures`; NumPy twins of the kernels: :mod:`popbal.reference`.
"""

from settler.physics import COALESCENCE_RULES

from .closures import CLOUD_COEFFICIENT, steady_channel_velocity
from .driver import DISTRIBUTION_ARRAYS, Result, run
from .grid import SectionGrid, make_grid
from .model import ZONES, Model, feed_points, setup

__all__ = ["CLOUD_COEFFICIENT", "COALESCENCE_RULES", "DISTRIBUTION_ARRAYS", "Model", "Result", "SectionGrid", "ZONES",
           "feed_points", "make_grid", "run", "setup", "steady_channel_velocity"]
