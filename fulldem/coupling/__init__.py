"""The two-way coupling between droplets and the slag grid.

What belongs here: the smoothing kernels that deposit droplet quantities onto the grid and interpolate grid fields
back with the same weights (:mod:`.smoothing`, and the filtered form :mod:`.filtered`), the correction for a
droplet's own disturbance of the grid flow (:mod:`.mobility`), the drag law lifted onto all droplets (:mod:`.drag`)
and the per-droplet rows exchanged within one coupled step (:mod:`.exchange`). The order of the step is
:mod:`fulldem.stepper`'s.
"""
