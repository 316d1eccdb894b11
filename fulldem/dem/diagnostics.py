"""Whole-store diagnostics of the DEM state: kinetic energy, largest speed, masses.
"""

from __future__ import annotations

import math

from numba import njit, prange


@njit(cache=True)
def kinetic_energy(velocity, mass, count):
    """Translational kinetic energy sum m v^2 / 2 [J]."""
    total = 0.0
    for p in range(count):
        total += 0.5 * mass[p] * (velocity[p, 0] ** 2 + velocity[p, 1] ** 2 + velocity[p, 2] ** 2)
    return total


@njit(cache=True, parallel=True)
def max_speed(velocity, count):
    """Largest |v| of the first ``count`` droplets [m/s] (0 for none)."""
    worst = 0.0
    for p in prange(count):  # a max reduction
        worst = max(worst, velocity[p, 0] ** 2 + velocity[p, 1] ** 2 + velocity[p, 2] ** 2)
    return math.sqrt(worst)


@njit(cache=True, parallel=True)
def droplet_masses(diameter, density, count, mass):
    """mass[p] = rho pi d^3 / 6 [kg] (written in place)."""
    for p in prange(count):
        mass[p] = density[p] * (math.pi / 6.0) * diameter[p] ** 3
