"""What the reference runs show, measured one way for every run: steadiness, seed scatter, the rim of never-merged
droplets, and the collision efficiency of the kernel run (SI units throughout).

* :func:`steady_window` -- the rule for "steady": the means of consecutive blocks one burst cycle long
  (:data:`CYCLE`, 5 s: the plume's bursts in simple and cubic), counted back from the run's end, all lie within
  ±:data:`STEADY_TOLERANCE` (2 %) of their common mean, over at least :data:`STEADY_CYCLES` (3) blocks; the window
  with the most blocks that passes. Cycle means, not single rows: the count swings ±6-7 % within a burst and ±1-2 %
  between cycles.
* :func:`steady_means` -- the means of time-series columns over a window; :func:`seed_scatter` their relative
  differences between two seeds of one case.
* :func:`rim_share` -- the rim test (seed paper section 4.2: a rim of never-coalesced droplets around the channel): in
  a height band, the share of the droplets farther than twice the half-volume radius from the inlet axis that have
  never merged and are older than twice the median age of the band's droplets.
* :func:`collision_efficiency` -- from a closed box of two droplet sizes settling without feed: the merges of the
  unequal pair (from ``merges_by_size.csv``) over the gravitational collisions that pi (a_i + a_j)^2 |U_i - U_j| n_i
  n_j V predicts, integrated over the snapshots in horizontal slices (so that the clouds' separation as they settle
  counts), with the measured mean settling velocity of each size; its standard error from the Poisson count of
  merges and the scatter of the velocity difference over the snapshots.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from settler.output import half_volume_radius

#: Burst cycle of the plume in simple and cubic [s] (measured on the old stored runs: 5-s bursts).
CYCLE = 5.0
#: Cycle means within this relative distance of their common mean [-].
STEADY_TOLERANCE = 0.02
#: Whole cycles the steady window must hold [-].
STEADY_CYCLES = 3


def steady_window(timeseries: pd.DataFrame, column: str = "droplet_count", cycle: float = CYCLE,
                  tolerance: float = STEADY_TOLERANCE, cycles: int = STEADY_CYCLES) -> dict:
    """The earliest steady start of ``column`` (module docstring), in whole cycles back from the run's last output:
    {"start": t0 [s] or NaN if no window of ``cycles`` blocks is steady, "cycles": blocks in the window, "mean": the
    mean of the block means, "block_means", "spread": max |block mean / mean - 1|}."""
    t = timeseries["time"].to_numpy(dtype=float)
    y = timeseries[column].to_numpy(dtype=float)
    end = t[-1]
    most = int(math.floor((end - t[0]) / cycle + 1e-9))
    for blocks in range(most, cycles - 1, -1):
        edges = end - cycle * np.arange(blocks, -1, -1)
        means = []
        for low, high in zip(edges[:-1], edges[1:]):
            inside = (t > low + 1e-9) & (t <= high + 1e-9)
            means.append(float(y[inside].mean()) if inside.any() else math.nan)
        means = np.array(means)
        if not np.isfinite(means).all():
            continue
        mean = float(means.mean())
        spread = float(np.max(np.abs(means / mean - 1.0)))
        if spread <= tolerance:
            return {"start": float(edges[0]), "cycles": blocks, "mean": mean, "block_means": means.tolist(),
                    "spread": spread}
    return {"start": math.nan, "cycles": 0, "mean": math.nan, "block_means": [], "spread": math.nan}


def steady_means(timeseries: pd.DataFrame, columns, start: float, end: float | None = None) -> dict[str, float]:
    """The mean of each of ``columns`` over the rows with start < time <= end (end: the last) [their units]."""
    t = timeseries["time"]
    end = float(t.iloc[-1]) if end is None else end
    inside = (t > start + 1e-9) & (t <= end + 1e-9)
    return {c: float(timeseries.loc[inside, c].mean()) for c in columns}


def seed_scatter(first: dict[str, float], second: dict[str, float]) -> dict[str, float]:
    """(second - first) / first for every key of both (the relative seed scatter of steady means) [-]."""
    return {k: (second[k] - first[k]) / first[k] if first[k] else math.nan for k in first if k in second}


def rim_share(droplets: pd.DataFrame, axis, z_low: float, z_high: float) -> dict:
    """The rim test (module docstring) on a snapshot's droplets (columns x, y, z, diameter, age, merged) for the
    inlet axis ``axis`` (x, y) [m] in heights z_low <= z < z_high [m] above the bottom: {"share", "outside" (droplets
    beyond 2 r_half), "rim" (of them never merged and older than twice the median age), "half_volume_radius" [m],
    "median_age" [s]}."""
    band = droplets[(droplets["z"] >= z_low) & (droplets["z"] < z_high)]
    r = np.hypot(band["x"].to_numpy() - axis[0], band["y"].to_numpy() - axis[1])
    volume = np.pi / 6.0 * band["diameter"].to_numpy() ** 3
    r_half = half_volume_radius(r, volume)
    age = band["age"].to_numpy()
    median = float(np.median(age)) if len(age) else math.nan
    outside = r > 2.0 * r_half
    rim = outside & (band["merged"].to_numpy() == 0) & (age > 2.0 * median)
    count = int(outside.sum())
    return {"share": int(rim.sum()) / count if count else math.nan, "outside": count, "rim": int(rim.sum()),
            "half_volume_radius": r_half, "median_age": median}


def pair_exposure(snapshots, small: tuple[float, float], large: tuple[float, float], area: float,
                  slice_height: float) -> dict:
    """sum over snapshots of sum over horizontal slices of N_small N_large / V_slice, and the mean settling
    velocities of the two size ranges, for ``snapshots`` [(time [s], droplets DataFrame with z, diameter,
    settling_velocity)], size ranges [m] (low, high], a box of horizontal ``area`` [m^2] sliced ``slice_height``
    [m]: {"times", "exposure" (per snapshot) [1/m^3], "velocity_small", "velocity_large" (per snapshot) [m/s]}."""
    times, exposure, u_small, u_large = [], [], [], []
    for time, frame in snapshots:
        d = frame["diameter"].to_numpy()
        z = frame["z"].to_numpy()
        k = np.floor(z / slice_height).astype(np.int64)
        is_small = (d > small[0]) & (d <= small[1])
        is_large = (d > large[0]) & (d <= large[1])
        size = int(k.max()) + 1 if len(k) else 1
        n_small = np.bincount(k[is_small], minlength=size)
        n_large = np.bincount(k[is_large], minlength=size)
        exposure.append(float((n_small * n_large).sum()) / (area * slice_height))
        u_small.append(float(frame["settling_velocity"].to_numpy()[is_small].mean()) if is_small.any() else math.nan)
        u_large.append(float(frame["settling_velocity"].to_numpy()[is_large].mean()) if is_large.any() else math.nan)
        times.append(float(time))
    return {"times": np.array(times), "exposure": np.array(exposure), "velocity_small": np.array(u_small),
            "velocity_large": np.array(u_large)}


def collision_efficiency(merges: int, exposure: dict, diameter_small: float, diameter_large: float) -> dict:
    """E = merges / (pi (a_s + a_l)^2 integral |U_l - U_s| C dt) with C = sum N_s N_l / V over slices
    (:func:`pair_exposure`), trapezoidal over the snapshots; standard error from the Poisson count (sqrt M / M)
    and the standard error of the mean velocity difference over the snapshots, in quadrature. Returns {"efficiency",
    "standard_error", "expected_collisions", "merges", "velocity_difference" [m/s]}."""
    t = exposure["times"]
    du = np.abs(exposure["velocity_large"] - exposure["velocity_small"])
    c = exposure["exposure"]
    good = np.isfinite(du) & np.isfinite(c)
    cross = math.pi * (0.5 * (diameter_small + diameter_large)) ** 2
    rate = np.where(good, cross * np.nan_to_num(du) * c, 0.0)
    expected = float(np.trapezoid(rate, t)) if hasattr(np, "trapezoid") else float(np.trapz(rate, t))
    efficiency = merges / expected if expected > 0 else math.nan
    weights = c[good]
    mean_du = float(np.average(du[good], weights=weights)) if weights.sum() > 0 else math.nan
    du_error = float(np.std(du[good], ddof=1) / math.sqrt(good.sum())) if good.sum() > 1 else math.nan
    relative = math.sqrt((1.0 / merges if merges > 0 else math.inf) + (du_error / mean_du) ** 2)
    return {"efficiency": efficiency, "standard_error": efficiency * relative, "expected_collisions": expected,
            "merges": int(merges), "velocity_difference": mean_du}
