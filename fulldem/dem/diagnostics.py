"""Whole-store diagnostics of the DEM state: kinetic energy, largest speed, masses.
"""

from __future__ import annotations

import math

import numpy as np
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


def near_pairs(position, diameter):
    """Pairs (i, j) of centres closer than the largest diameter, with their distances [m] and overlaps (d_i + d_j)/2
    - distance [m] (negative where they do not touch): the candidates of every whole-store overlap check (a droplet
    list's validation, a failure's message). scipy's k-d tree: for checks, not for every step."""
    from scipy.spatial import cKDTree

    if len(position) < 2:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, np.zeros(0), np.zeros(0)
    pairs = cKDTree(position).query_pairs(r=float(diameter.max()), output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    distance = np.sqrt(((position[i] - position[j]) ** 2).sum(axis=1))
    return i, j, distance, 0.5 * (diameter[i] + diameter[j]) - distance


def deepest_pair(position, contact_diameter, partner, count):
    """(i, j, overlap / smaller contact diameter) of the most overlapping pair of touching droplets among the first
    ``count`` (mutual coalescence partners, which exert no contact force on each other, excepted); (-1, -1, 0.0) if
    none touch. For a failure's message (:func:`near_pairs`), not for every step."""
    d = contact_diameter[:count]
    i, j, _, overlap = near_pairs(position[:count], d)
    keep = partner[:count][i] != j
    i, j, overlap = i[keep], j[keep], overlap[keep]
    ratio = overlap / np.minimum(d[i], d[j])
    if ratio.size == 0 or ratio.max() <= 0.0:
        return -1, -1, 0.0
    k = int(ratio.argmax())
    return int(i[k]), int(j[k]), float(ratio[k])
