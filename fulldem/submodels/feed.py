"""The feed's placement: droplets inserted over the inlet disk without overlaps (matte mass counted exactly at
every insertion; the feed submodel is :class:`fulldem.submodels.base.Feed`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _cell_of(x, y, z, lower, cell, dims):
    i = min(max(int((x - lower[0]) / cell), 0), dims[0] - 1)
    j = min(max(int((y - lower[1]) / cell), 0), dims[1] - 1)
    k = min(max(int((z - lower[2]) / cell), 0), dims[2] - 1)
    return (i * dims[1] + j) * dims[2] + k


@njit(cache=True)
def place_without_overlap(candidates, new_diameter, old_position, old_diameter, n_old, lower, upper, cell,
                          chosen):
    """Pick, for each new droplet, the first candidate position that overlaps nobody; chosen[m] = -1 if none.

    candidates: (m, tries, 3) random positions drawn by the caller; new_diameter (m,); old_position/old_diameter:
    droplets already present (only those inside [lower, upper] matter). A cell hash of side ``cell`` (at least the
    largest diameter involved) holds old and accepted new droplets. Returns the number placed.
    """
    dims = np.empty(3, dtype=np.int64)
    for a in range(3):
        dims[a] = max(1, int(math.ceil((upper[a] - lower[a]) / cell)))
    n_cells = dims[0] * dims[1] * dims[2]
    m, tries = candidates.shape[0], candidates.shape[1]
    head = np.full(n_cells, -1, dtype=np.int64)
    nxt = np.full(n_old + m, -1, dtype=np.int64)
    px = np.empty((n_old + m, 3))
    pd = np.empty(n_old + m)
    n = 0
    for p in range(n_old):
        x, y, z = old_position[p, 0], old_position[p, 1], old_position[p, 2]
        if lower[0] - cell <= x <= upper[0] + cell and lower[1] - cell <= y <= upper[1] + cell \
                and lower[2] - cell <= z <= upper[2] + cell:
            px[n, 0], px[n, 1], px[n, 2] = x, y, z
            pd[n] = old_diameter[p]
            c = _cell_of(x, y, z, lower, cell, dims)
            nxt[n] = head[c]
            head[c] = n
            n += 1
    placed = 0
    for q in range(m):
        chosen[q] = -1
        for t in range(tries):
            x, y, z = candidates[q, t, 0], candidates[q, t, 1], candidates[q, t, 2]
            i0 = min(max(int((x - lower[0]) / cell), 0), dims[0] - 1)
            j0 = min(max(int((y - lower[1]) / cell), 0), dims[1] - 1)
            k0 = min(max(int((z - lower[2]) / cell), 0), dims[2] - 1)
            free = True
            for i in range(max(i0 - 1, 0), min(i0 + 2, dims[0])):
                for j in range(max(j0 - 1, 0), min(j0 + 2, dims[1])):
                    for k in range(max(k0 - 1, 0), min(k0 + 2, dims[2])):
                        o = head[(i * dims[1] + j) * dims[2] + k]
                        while o >= 0 and free:
                            dx, dy, dz = px[o, 0] - x, px[o, 1] - y, px[o, 2] - z
                            reach = 0.5 * (pd[o] + new_diameter[q])
                            if dx * dx + dy * dy + dz * dz < reach * reach:
                                free = False
                            o = nxt[o]
            if free:
                chosen[q] = t
                px[n, 0], px[n, 1], px[n, 2] = x, y, z
                pd[n] = new_diameter[q]
                c = _cell_of(x, y, z, lower, cell, dims)
                nxt[n] = head[c]
                head[c] = n
                n += 1
                placed += 1
                break
    return placed


def draw_inlet_candidates(rng, diameters, center, radius, top, layer, tries):
    """Random candidate centres (m, tries, 3) over the inlet disk, each droplet fully inside the disk and below the
    top surface, in a layer of thickness ``layer`` [m] under it."""
    m = len(diameters)
    r_allowed = np.maximum(radius - 0.5 * diameters, 0.0)[:, None]
    rho = r_allowed * np.sqrt(rng.uniform(size=(m, tries)))
    theta = rng.uniform(0.0, 2.0 * np.pi, size=(m, tries))
    z = top - 0.5 * diameters[:, None] - rng.uniform(0.0, layer, size=(m, tries))
    out = np.empty((m, tries, 3))
    out[..., 0] = center[0] + rho * np.cos(theta)
    out[..., 1] = center[1] + rho * np.sin(theta)
    out[..., 2] = z
    return out


def draw_slot_candidates(rng, diameters, center, half_extent, top, layer, tries):
    """Random candidate centres (m, tries, 3) over a rectangular inlet of half extents ``half_extent`` (x, y) [m]
    around ``center``, each droplet fully inside the rectangle and below the top surface, in a layer of thickness
    ``layer`` [m] under it."""
    m = len(diameters)
    out = np.empty((m, tries, 3))
    for axis in (0, 1):
        allowed = np.maximum(half_extent[axis] - 0.5 * diameters, 0.0)[:, None]
        out[..., axis] = center[axis] + allowed * rng.uniform(-1.0, 1.0, size=(m, tries))
    out[..., 2] = top - 0.5 * diameters[:, None] - rng.uniform(0.0, layer, size=(m, tries))
    return out
