"""Sections in droplet volume: the geometric pivot grid, and number/volume-conserving assignment onto it.

The internal coordinate is the *original* droplet volume v0 [m^3] -- the volume the droplet had at the feed
composition. The reaction removes FeS only and keeps Cu2S (settler.physics.matte), so v0 is proportional to the
Cu2S a droplet carries: it never changes by reaction and is exactly additive on coalescence. The reaction
therefore moves no droplet between sections (no negative-growth term, no numerical diffusion from it); it changes
the droplet's *actual* size d = d0 * relative_diameter_at_age(age) and density, which the stepper evaluates per
section from the section's age (see :mod:`popbal.driver`).

Grid (Kumar et al. 2006, Chem. Eng. Sci. 61, 3327, cell-average technique): pivots x_i geometric with ratio r, cell
edges b_i = 2 x_i / (1 + r) so that each pivot is the arithmetic midpoint of its cell. The top pivot is placed
exactly at the largest volume a coalescence may create (coalescence.size_limit), so every allowed birth has a
volume <= x_top and the cell-average assignment never has to push mass off the grid.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from settler.physics import sphere_volume


class SectionGrid(NamedTuple):
    """Pivot grid in original droplet volume. K sections.

    - pivots (K,) [m^3]: pivot volumes x_i, geometric, ratio ``ratio``.
    - edges (K+1,) [m^3]: cell edges b_i, pivot x_i is the midpoint of [b_i, b_{i+1}).
    - diameters (K,) [m]: original diameters of the pivots, (6 x_i / pi)^(1/3).
    - target (K, K) int64: cell receiving the merger of sections j and k (x_j + x_k in [b_i, b_{i+1})), or -1 where
      x_j + x_k exceeds the volume limit (no coalescence beyond it).
    - loss_weight (K, K): fraction of a droplet of section i that a merger with a k-droplet actually moves out of
      pivot i -- 1 unless the merger lands back in i's own cell, where the cell-average assignment returns all
      but x_k / (x_{i+1} - x_i) of it. Only used to bound the stiffness of the coalescence rates (sub-steps):
      a large droplet sweeping many small ones has a huge gross death rate but a small net one.
    - ratio: pivot ratio r [-]. volume_limit [m^3]: largest volume a merger may create (= top pivot).
    """

    pivots: np.ndarray
    edges: np.ndarray
    diameters: np.ndarray
    target: np.ndarray
    loss_weight: np.ndarray
    ratio: float
    volume_limit: float

    @property
    def size(self) -> int:
        return self.pivots.size


def volume_of(diameter):
    """Sphere volume pi d^3 / 6 [m^3] of a diameter [m]."""
    return sphere_volume(np.asarray(diameter, dtype=float))


def diameter_of(volume):
    """Sphere diameter (6 v / pi)^(1/3) [m] of a volume [m^3]."""
    return np.cbrt(6.0 / math.pi * np.asarray(volume, dtype=float))


def section_count(volume_min: float, volume_top: float, sections_per_doubling: int) -> int:
    """Sections K of :func:`make_grid`'s grid from volume_min to volume_top [m^3], without building it.

    The size checks (:mod:`popbal.limits`) call it before anything (K, K) is allocated.
    """
    ratio = 2.0 ** (1.0 / sections_per_doubling)
    # the small tolerance keeps a volume_min that sits on a pivot from adding a needless section below it
    return max(0, math.ceil(math.log(volume_top / volume_min) / math.log(ratio) - 1e-9)) + 1


def make_grid(volume_min: float, volume_top: float, sections_per_doubling: int) -> SectionGrid:
    """Geometric pivots x_i = volume_top r^-(K-1-i), r = 2^(1/sections_per_doubling), down to x_0 <= volume_min.

    volume_top [m^3] is the top pivot and the largest volume a merger may create; volume_min [m^3] the smallest
    volume that must be represented (the smallest fed droplet).
    """
    if not (0.0 < volume_min <= volume_top):
        raise ValueError(f"make_grid: need 0 < volume_min ({volume_min:g}) <= volume_top ({volume_top:g}) m^3")
    if sections_per_doubling < 1:
        raise ValueError(f"make_grid: sections_per_doubling = {sections_per_doubling}, allowed >= 1")
    ratio = 2.0 ** (1.0 / sections_per_doubling)
    below = section_count(volume_min, volume_top, sections_per_doubling) - 1
    pivots = volume_top * ratio ** -np.arange(below, -1, -1, dtype=float)
    pivots[-1] = volume_top
    edges = np.append(2.0 * pivots / (1.0 + ratio), 2.0 * ratio * pivots[-1] / (1.0 + ratio))
    sums = pivots[:, None] + pivots[None, :]
    target = np.searchsorted(edges, sums, side="right") - 1
    target[sums > volume_top * (1.0 + 1e-12)] = -1
    own = target == np.arange(pivots.size)[:, None]
    gap = np.append(np.diff(pivots), np.inf)
    loss_weight = np.where(own, np.minimum(1.0, pivots[None, :] / gap[:, None]), 1.0)
    return SectionGrid(pivots, edges, diameter_of(pivots), target.astype(np.int64), loss_weight, ratio,
                       float(volume_top))


def split_to_pivots(volumes, numbers, pivots) -> np.ndarray:
    """Assign droplets of the given volumes onto the pivots, conserving number and volume.

    A number n at volume v between pivots x_i <= v <= x_{i+1} goes a = (x_{i+1} - v)/(x_{i+1} - x_i) to x_i and
    1 - a to x_{i+1} (the fixed-pivot split of Kumar & Ramkrishna 1996). Outside the grid the whole volume goes to
    the end pivot (volume kept, number not); callers keep the grid wide enough that this does not happen.
    volumes [m^3], numbers [any unit] -> numbers per pivot (K,) [same unit].
    """
    volumes = np.atleast_1d(np.asarray(volumes, dtype=float))
    numbers = np.atleast_1d(np.asarray(numbers, dtype=float))
    out = np.zeros(pivots.size)
    low = volumes <= pivots[0]
    high = volumes >= pivots[-1]
    out[0] += np.sum(numbers[low] * volumes[low]) / pivots[0]
    out[-1] += np.sum(numbers[high & ~low] * volumes[high & ~low]) / pivots[-1]
    inside = ~(low | high)
    v, n = volumes[inside], numbers[inside]
    i = np.searchsorted(pivots, v, side="right") - 1
    a = (pivots[i + 1] - v) / (pivots[i + 1] - pivots[i])
    np.add.at(out, i, a * n)
    np.add.at(out, i + 1, (1.0 - a) * n)
    return out


def exponential_sections(grid: SectionGrid, total_number: float, mean_volume: float,
                         points_per_section: int = 64) -> np.ndarray:
    """Sectional number densities of n0(v) = (N0/v0) exp(-v/v0) (the verification initial condition).

    The density is integrated by Gauss-Legendre quadrature over every cell (and from 0 to the first edge) and each
    quadrature point is split onto the pivots, so the zeroth and first moments are those of the continuous
    distribution on [0, top edge] to quadrature accuracy. total_number N0 [1/m^3], mean_volume v0 [m^3].
    """
    nodes, weights = np.polynomial.legendre.leggauss(points_per_section)
    edges = np.concatenate([[0.0], grid.edges])
    lo, hi = edges[:-1, None], edges[1:, None]
    v = 0.5 * (hi - lo) * nodes[None, :] + 0.5 * (hi + lo)
    w = 0.5 * (hi - lo) * weights[None, :]
    dens = total_number / mean_volume * np.exp(-v / mean_volume)
    return split_to_pivots(v.ravel(), (dens * w).ravel(), grid.pivots)
