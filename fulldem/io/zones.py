"""The zone diagnostics of a coupled run, as defined once in :mod:`settler.output` (:data:`~settler.output.ZONE_PROFILE`,
:data:`~settler.output.ZONES`, :data:`~settler.output.LIFT_BY_SIZE`, :data:`~settler.output.MERGES_BY_HEIGHT`),
written at every snapshot beside the channel profile: what the reduced model's zones (roof layer, plume core,
downflow skirt, return annulus) can be fitted to.

The measures are plain functions of arrays (:func:`return_radius`, :func:`roof_layer`, :func:`lift_table`), checked
against closed forms in tests/test_zones.py; :func:`snapshot_tables` applies them to a :class:`fulldem.stepper.
Simulation`.
"""

from __future__ import annotations

import math

import numpy as np

from settler.output import RING_CELLS, ROOF_SHARE, band_edges, half_volume_radius
from settler.physics import sphere_volume


def return_radius(w_plane, x, y, axis, ring) -> float:
    """The distance [m] from ``axis`` (x, y) [m] at which the ring-averaged vertical velocity of ``w_plane`` (nx, ny)
    [m/s] on cell centres ``x`` (nx,), ``y`` (ny,) [m] turns from downward (w < 0) to upward (w > 0), linearly
    interpolated between the centres of rings ``ring`` [m] wide. NaN if the innermost ring does not flow down or no
    ring further out flows up."""
    r = np.hypot(x[:, None] - axis[0], y[None, :] - axis[1]).ravel()
    w = np.asarray(w_plane, dtype=float).ravel()
    k = np.floor(r / ring).astype(np.int64)
    count = np.bincount(k)
    occupied = count > 0
    mean = np.bincount(k, weights=w)[occupied] / count[occupied]
    centre = (np.bincount(k, weights=r)[occupied] / count[occupied])
    if mean.size == 0 or not mean[0] < 0.0:
        return math.nan
    up = np.nonzero(mean > 0.0)[0]
    if up.size == 0:
        return math.nan
    j = int(up[0])
    # the last non-upward ring before it (mean <= 0) and the first upward one: the zero between their centres
    w0, w1 = mean[j - 1], mean[j]
    return float(centre[j - 1] + (centre[j] - centre[j - 1]) * (-w0) / (w1 - w0))


def roof_layer(depth, volume, slice_height, area, height) -> tuple[float, float, float]:
    """(thickness [m], volume fraction [-], peak slice fraction [-]) of the roof layer of droplets at depths
    ``depth`` [m] below the slag top with volumes ``volume`` [m^3], in a region of horizontal ``area`` [m^2] and
    slag height ``height`` [m], sliced ``slice_height`` [m] from the top (:data:`settler.output.ZONES`): the slices
    from the top down to the last one, below the upper half's peak, whose fraction is at least
    :data:`settler.output.ROOF_SHARE` of the peak. (0, NaN, 0) with no droplets in the upper half."""
    slices = max(1, int(math.ceil(0.5 * height / slice_height - 1e-9)))
    k = np.floor(np.asarray(depth, dtype=float) / slice_height).astype(np.int64)
    keep = (k >= 0) & (k < slices)
    fraction = np.bincount(k[keep], weights=np.asarray(volume, dtype=float)[keep], minlength=slices).astype(float)
    fraction /= area * slice_height
    peak = int(np.argmax(fraction))
    if fraction[peak] <= 0.0:
        return 0.0, math.nan, 0.0
    last = peak
    while last + 1 < slices and fraction[last + 1] >= ROOF_SHARE * fraction[peak]:
        last += 1
    thickness = (last + 1) * slice_height
    return thickness, float(fraction[: last + 1].sum() * slice_height / thickness), float(fraction[peak])


def lift_table(diameter, velocity_z, edges) -> list[dict]:
    """Rows (diameter_low, diameter_high, count, rising_count, rising_velocity) of the occupied bins ``edges`` [m]
    (bin 0 below edges[0], the last above edges[-1]) for droplets of ``diameter`` [m] moving at ``velocity_z``
    [m/s] (upward positive)."""
    d = np.asarray(diameter, dtype=float)
    vz = np.asarray(velocity_z, dtype=float)
    bins = np.searchsorted(edges, d, side="right")
    bounds = np.concatenate([[0.0], edges, [np.inf]])
    nbins = bounds.size - 1
    count = np.bincount(bins, minlength=nbins)
    up = vz > 0.0
    rising = np.bincount(bins[up], minlength=nbins)
    speed = np.bincount(bins[up], weights=vz[up], minlength=nbins)
    rows = []
    for b in np.nonzero(count)[0]:
        rows.append({"diameter_low": bounds[b], "diameter_high": bounds[b + 1], "count": int(count[b]),
                     "rising_count": int(rising[b]),
                     "rising_velocity": speed[b] / rising[b] if rising[b] else math.nan})
    return rows


def _plane(sim, eps_w, z) -> tuple[np.ndarray, np.ndarray]:
    """(w, eps) on the layer of z faces nearest to height ``z`` [m] above the bottom."""
    k = int(round(z / sim.grid.spacing))
    k = min(max(k, 0), sim.fluid.w.shape[2] - 1)
    return sim.fluid.w[:, :, k], eps_w[:, :, k]


def snapshot_tables(sim, eps_faces) -> dict[str, list[dict]]:
    """The rows of ``zone_profile.csv``, ``zones.csv``, ``lift_by_size.csv`` and ``merges_by_height.csv`` at the
    current time (keys: file names), ``eps_faces`` the face void fractions of the droplets' current positions
    (:meth:`fulldem.stepper.Simulation.void_fraction`)."""
    from fulldem.submodels.coalescence import SIZE_BINS

    s, n, grid = sim.store, sim.store.count, sim.grid
    h = grid.spacing
    height = grid.size[2]
    inlet = sim.bounds.inlet
    x0, y0 = inlet.centre
    position = s.position[:n]
    z = position[:, 2] - sim.lower[2]
    r = np.hypot(position[:, 0] - x0, position[:, 1] - y0)
    volume = sphere_volume(s.diameter[:n])
    vz = s.velocity[:n, 2]
    x = sim.lower[0] + (np.arange(grid.shape[0]) + 0.5) * h
    y = sim.lower[1] + (np.arange(grid.shape[1]) + 0.5) * h
    area = grid.size[0] * grid.size[1]
    edges = band_edges(height)
    profile = []
    for low, high in zip(edges[:-1], edges[1:]):
        inside = (z >= low) & (z < high)
        core = half_volume_radius(r[inside], volume[inside])
        w, eps = _plane(sim, eps_faces[2], 0.5 * (low + high))
        flux = eps * w * h * h
        profile.append({
            "time": sim.time, "z": 0.5 * (low + high),
            "volume_fraction": float(volume[inside].sum()) / (area * (high - low)),
            "core_volume_fraction": (float(volume[inside & (r <= core)].sum()) / (math.pi * core**2 * (high - low))
                                     if core > 0.0 else math.nan),
            "upward_slag_flux": float(flux[flux > 0.0].sum()), "downward_slag_flux": float(-flux[flux < 0.0].sum()),
            "return_radius": return_radius(w, x, y, (x0, y0), RING_CELLS * h),
            "rising_volume": float(volume[inside & (vz > 0.0)].sum())})
    if inlet.is_slot:  # the roof layer under a slot: the droplets above its rectangle
        under = inlet.contains(position[:, 0], position[:, 1])
        thickness, fraction, peak = roof_layer(height - z[under], volume[under], h, inlet.area, height)
    else:
        under = r <= inlet.radius
        thickness, fraction, peak = roof_layer(height - z[under], volume[under], h, math.pi * inlet.radius**2,
                                               height)
    below = z < height - sim.case.fulldem.insertion_layer
    rising = below & (vz > 0.0)
    zones = [{"time": sim.time, "roof_thickness": thickness, "roof_volume_fraction": fraction,
              "roof_peak_fraction": peak, "rising_count": int(rising.sum()),
              "rising_volume": float(volume[rising].sum())}]
    lift = [{"time": sim.time, **row} for row in lift_table(s.diameter[:n][below], vz[below], SIZE_BINS)]
    places = sim.counters.merges_by_height
    merges = [{"time": sim.time, "z": 0.5 * (low + high), "merges_under_inlet": int(places[k, 0]),
               "merges_elsewhere": int(places[k, 1])} for k, (low, high) in enumerate(zip(edges[:-1], edges[1:]))]
    return {"zone_profile.csv": profile, "zones.csv": zones, "lift_by_size.csv": lift, "merges_by_height.csv": merges}
