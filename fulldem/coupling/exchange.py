"""The exchange between droplets and grid within one coupled step: the rows deposited at x^n (volume, volume flux),
the forcing each droplet receives from the interpolated fields, its drift with the fluid, and the drag reaction
owed to the fluid (the step's order: :mod:`fulldem.stepper`).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from settler.physics import sphere_volume


#: Quantities deposited at x^n before the fluid step, by array: volume on the three face arrays and the cells, then
#: the volume flux on the faces (one stencil computation per droplet for all seven).
DEPOSIT_COMPONENTS = np.array([0, 1, 2, 3, 0, 1, 2], dtype=np.int64)
#: Fields interpolated at x^n after the fluid step: fluid velocity and pressure force on the faces, volume fraction
#: at the cells.
INTERPOLATE_COMPONENTS = np.array([0, 1, 2, 0, 1, 2, 3], dtype=np.int64)


@njit(cache=True, parallel=True)
def start_rows(position, diameter, velocity, count, inv_cell_volume, start_position, volume, values):
    """Per droplet at x^n: start_position = position [m], volume [m^3], and the deposit rows (DEPOSIT_COMPONENTS):
    volume / cell volume on the three face arrays and the cells, times the velocity for the flux rows."""
    for p in prange(count):
        vol = sphere_volume(diameter[p])
        volume[p] = vol
        share = vol * inv_cell_volume
        for r in range(4):
            values[r, p] = share
        for a in range(3):
            values[4 + a, p] = share * velocity[p, a]
            start_position[p, a] = position[p, a]


@njit(cache=True, parallel=True)
def forcing_rows(seen, own, volume, mass, fluid_density, gravity, inv_cell_volume, count, fluid_velocity, external,
                 eps_around):
    """From the interpolated rows (INTERPOLATE_COMPONENTS): fluid velocity [m/s]; external force [N] = volume x
    pressure-force density + buoyant weight (m - rho_f V) g; void fraction around the droplet, its own volume
    share (``own``, the weight at its centre) removed, clipped to [0, 1]."""
    for p in prange(count):
        vol = volume[p]
        buoyant = mass[p] - fluid_density * vol
        for a in range(3):
            fluid_velocity[p, a] = seen[a, p]
            external[p, a] = vol * seen[3 + a, p] + buoyant * gravity[a]
        eps = 1.0 - (seen[6, p] - own[p] * vol * inv_cell_volume)
        eps_around[p] = min(max(eps, 0.0), 1.0)


@njit(cache=True, parallel=True)
def drift_rows(fluid_velocity, external, beta, count, drift_velocity, impulse):
    """drift velocity u + F/beta [m/s] (what the DEM sub-steps see) and a zeroed impulse accumulator [N s]."""
    for p in prange(count):
        for a in range(3):
            drift_velocity[p, a] = fluid_velocity[p, a] + external[p, a] / beta[p]
            impulse[p, a] = 0.0


@njit(cache=True, parallel=True)
def owed_rows(impulse, external, duration, count, scale, values):
    """Drag impulse J = DEM impulse - F duration [N s] (the external force was folded into the drift velocity), and
    the rows ``values[a] = scale J_a`` the fluid is owed."""
    for p in prange(count):
        for a in range(3):
            j = impulse[p, a] - external[p, a] * duration
            impulse[p, a] = j
            values[a, p] = scale * j
