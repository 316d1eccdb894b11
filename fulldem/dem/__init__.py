"""The droplets as soft spheres: everything that advances them between two fluid steps.

What belongs here: the records the kernels read (:mod:`.records`), the pointwise contact laws (:mod:`.laws`), the
loops that lift them onto the neighbour list's pairs (:mod:`.pairs`) and onto the walls (:mod:`.walls`), the
exponential velocity-Verlet integrator (:mod:`.integrators`), free flight (:mod:`.free_flight`), whole-store
diagnostics (:mod:`.diagnostics`), the neighbour list (:mod:`.neighbours`), the NumPy twins the tests compare the
kernels with (:mod:`.twins`) and :class:`~fulldem.dem.stepper.DemStepper`, which orchestrates them
(:mod:`.stepper`). Kernels here see arrays and records only: no case, no grid, no files. The slag enters as a
fluid velocity and a drag coefficient per droplet, passed in by :mod:`fulldem.stepper`.
"""
