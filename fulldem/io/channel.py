"""The channel measures of a coupled run, as defined once in :mod:`settler.output` for both engines.

* ``channel_radius``: the radius around the inlet axis that holds half the droplet volume at mid-height
  (:func:`settler.output.half_volume_radius` of the droplets within :data:`settler.output.MID_BAND` of the height
  around mid-height);
* ``channel_velocity``: the slag's downward velocity on the inlet axis at mid-height, interpolated trilinearly from
  the grid's z-face velocities;
* their profile against height (:data:`settler.output.CHANNEL_PROFILE`, :data:`settler.output.PROFILE_BANDS`
  bands), written at every snapshot to ``channel_profile.csv``.

Under a slot inlet (``geometry.inlet_length``) these still measure about the slot's centre axis, which is where one
channel of several may or may not be; a slab's channels are counted from its snapshots instead
(:mod:`analysis.channels`).
"""

from __future__ import annotations

import math

import numpy as np

from settler.output import MID_BAND, band_edges, half_volume_radius
from settler.physics import sphere_volume


def face_value(grid, field, axis, point) -> float:
    """Trilinear interpolation at ``point`` (3,) [m] of a face field on the faces normal to ``axis`` (clamped to the
    grid: a point outside takes the nearest face values)."""
    h = grid.spacing
    shape = field.shape
    index, weight = [], []
    for a in range(3):
        # face coordinates: integer on the normal axis, half-integer on the others
        s = (point[a] - grid.lower[a]) / h - (0.0 if a == axis else 0.5)
        s = min(max(s, 0.0), shape[a] - 1.0)
        i = min(int(math.floor(s)), shape[a] - 2) if shape[a] > 1 else 0
        index.append(i)
        weight.append(s - i if shape[a] > 1 else 0.0)
    value = 0.0
    for di in (0, 1):
        for dj in (0, 1):
            for dk in (0, 1):
                w = ((weight[0] if di else 1.0 - weight[0]) * (weight[1] if dj else 1.0 - weight[1])
                     * (weight[2] if dk else 1.0 - weight[2]))
                if w:
                    value += w * field[index[0] + di, index[1] + dj, index[2] + dk]
    return float(value)


def measures(sim, z_low, z_high, z_axis):
    """(channel radius [m], downward slag velocity on the axis at height ``z_axis`` [m], droplet volume [m^3]) of
    the droplets whose centres lie between heights ``z_low`` and ``z_high`` [m] above the bottom."""
    s, n = sim.store, sim.store.count
    x0, y0 = sim.bounds.inlet.centre
    z = s.position[:n, 2] - sim.lower[2]
    inside = (z >= z_low) & (z < z_high)
    r = np.hypot(s.position[:n, 0][inside] - x0, s.position[:n, 1][inside] - y0)
    volume = sphere_volume(s.diameter[:n][inside])
    point = (x0, y0, sim.lower[2] + z_axis)
    return half_volume_radius(r, volume), -face_value(sim.grid, sim.fluid.w, 2, point), float(volume.sum())


def time_series_columns(sim) -> dict:
    """``channel_radius`` and ``channel_velocity`` of the time series (see the module docstring)."""
    height = sim.grid.size[2]
    radius, velocity, _ = measures(sim, (0.5 - MID_BAND) * height, (0.5 + MID_BAND) * height, 0.5 * height)
    return {"channel_radius": radius, "channel_velocity": velocity}


def profile_rows(sim) -> list[dict]:
    """The channel profile at the current time: one row per height band (:data:`settler.output.CHANNEL_PROFILE`)."""
    edges = band_edges(sim.grid.size[2])
    rows = []
    for low, high in zip(edges[:-1], edges[1:]):
        radius, velocity, volume = measures(sim, low, high, 0.5 * (low + high))
        rows.append({"time": sim.time, "z": 0.5 * (low + high), "channel_radius": radius,
                     "channel_velocity": velocity, "droplet_volume": volume})
    return rows
