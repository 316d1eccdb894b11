"""The slag: a volume-averaged incompressible fluid on a staggered (MAC) grid.

What belongs here: the grid (:mod:`.grid`), momentum advection and diffusion (:mod:`.advection`), the walls, inlet
and outlet of the fluid (:mod:`.walls`), the pressure projection (:mod:`.pressure`), the step that ties them
together (:mod:`.solver`) and the NumPy twins of the kernels (:mod:`.twins`). The droplets enter only as fields on
the grid (void fraction, volume flux, face forces), deposited by :mod:`fulldem.coupling`.
"""
