"""What the reduced model is scored on: each reference run's steady-window means and their standard errors.

The issue's four columns (:data:`TARGET_COLUMNS`, SI units): droplet_count [-], mean_diameter [m], settling_flux
[kg/s] (matte settled per second: the slope of mass_settled over the window, not the cumulative settled fraction,
which scores start-up timing) and channel_velocity [m/s] (slag down the axis at mid-height).

The window: the steady window of :func:`analysis.evidence.steady_window` (cycle means of the droplet count within
2 % of their mean), else the last third of the run (``steady`` False, recorded); at most its last :data:`MAX_WINDOW`
seconds, ending with the run. The last part, not the first: a steady count does not make a steady settling flux.
In deep's feed the count is steady from 30-35 s while the first droplet reaches the floor at about 45 s, so over the
steady window's first 30 s deep_w005 settles 33.5 mg/s and over its last 30 s (90-120 s) 110 mg/s of the 150 mg/s
fed (until 2026-12-04 the window was the first 30 s, which scored start-up timing, what the settling flux column is
meant to avoid). The reduced model runs to the run's end; the seed and block errors are those of the window used.

The standard error of a window mean (what a residual is divided by) comes from the run's own scatter, twice:

* **within the run** -- the window is cut into blocks of :data:`BLOCK` seconds; s is the standard deviation of the
  block means about a straight line (so that a slow trend is not counted as noise) and rho their lag-1
  autocorrelation (clipped to [0, 0.95]); neighbouring blocks carry partly the same fluctuation, so the blocks count
  as n_eff = n (1 - rho) / (1 + rho) independent ones (the large-n variance of the mean of an AR(1) series) and
  se_within = s / sqrt(n_eff). The settling flux's se is the slope's standard error, inflated alike.
* **between seeds** -- the relative difference of the window means of a seed pair (simple and simple_seed2 over
  the common steady window of their common span), divided by sqrt(2) for one run's scatter: se_seed = that x
  abs(mean). It is the
  scatter a replicate would show, which the within-run blocks miss (a run's mean count depends on its seed more
  than on its own fluctuation). Where a column has no seed pair the seed term is 0 and noted.

se = sqrt(se_within^2 + se_seed^2) [column's unit].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from analysis.evidence import pair_window, window_of

#: The columns scored: name -> (unit, meaning).
TARGET_COLUMNS: dict[str, tuple[str, str]] = {
    "droplet_count": ("-", "droplets in the slag"),
    "mean_diameter": ("m", "number-mean droplet diameter"),
    "settling_flux": ("kg/s", "matte settled per second (slope of mass_settled over the window)"),
    "channel_velocity": ("m/s", "slag velocity down the axis at mid-height"),
}
#: Longest window [s] (the steady window's last part; module docstring).
MAX_WINDOW = 30.0
#: Block length [s] of the within-run scatter (the plume's bursts last a few seconds).
BLOCK = 1.0
#: Largest lag-1 autocorrelation used (beyond it n_eff would rest on a handful of blocks).
RHO_MAX = 0.95
#: The seed pairs that give the between-seed scatter: (first, second) reference run names.
SEED_PAIRS = (("simple", "simple_seed2"), ("cubic", "cubic_seed2"))


@dataclass
class Target:
    """One reference run's steady means and standard errors (SI units, :data:`TARGET_COLUMNS`)."""

    name: str
    window: tuple[float, float]  # s
    steady: bool
    means: dict[str, float]
    standard_errors: dict[str, float]
    within: dict[str, float] = field(default_factory=dict)  # se_within per column
    seed: dict[str, float] = field(default_factory=dict)  # se_seed per column
    effective_blocks: dict[str, float] = field(default_factory=dict)


def scored_window(series: pd.DataFrame, max_window: float = MAX_WINDOW) -> tuple[tuple[float, float], bool]:
    """((start, end) [s], steady?) over which a run is scored: the last ``max_window`` [s] of :func:`window_of`'s
    window, ending with the run (module docstring)."""
    (start, end), steady = window_of(series)
    return (max(start, end - max_window), end), steady


def window_means(series: pd.DataFrame, window) -> dict[str, float]:
    """The :data:`TARGET_COLUMNS` of a time series over ``window`` [s]: means, and the settling flux's slope."""
    from analysis.evidence import steady_means

    t = series["time"].to_numpy(float)
    out = steady_means(series, [c for c in TARGET_COLUMNS if c != "settling_flux"], window[0], window[1])
    with_start = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    out["settling_flux"] = float(np.polyfit(t[with_start], series["mass_settled"].to_numpy(float)[with_start], 1)[0])
    return out


def lag1_autocorrelation(values) -> float:
    """The lag-1 autocorrelation of a series [-] (about its mean; NaN with fewer than 3 finite values)."""
    y = np.asarray(values, dtype=float)
    y = y[np.isfinite(y)]
    if y.size < 3:
        return math.nan
    y = y - y.mean()
    denominator = float(y @ y)
    return float(y[:-1] @ y[1:]) / denominator if denominator > 0 else 0.0


def effective_count(n: int, rho: float) -> float:
    """Independent blocks n_eff = n (1 - rho) / (1 + rho) of n blocks with lag-1 autocorrelation rho, which is
    clipped to [0, :data:`RHO_MAX`] (at least 1)."""
    rho = min(max(0.0 if not math.isfinite(rho) else rho, 0.0), RHO_MAX)
    return max(1.0, n * (1.0 - rho) / (1.0 + rho))


def within_run_errors(series: pd.DataFrame, window, block: float = BLOCK) -> tuple[dict, dict]:
    """({column: se_within}, {column: n_eff}) of the window means (module docstring)."""
    t = series["time"].to_numpy(float)
    edges = np.arange(window[0], window[1] + 1e-9, block)
    if edges.size < 4:
        raise ValueError(f"window {window[0]:g}-{window[1]:g} s holds fewer than 3 blocks of {block:g} s")
    centres = 0.5 * (edges[:-1] + edges[1:])
    errors, counts = {}, {}
    for column in TARGET_COLUMNS:
        if column == "settling_flux":
            mass = series["mass_settled"].to_numpy(float)
            at = np.interp(edges, t, mass)
            values = np.diff(at) / block  # the settling flux of each block [kg/s]
        else:
            y = series[column].to_numpy(float)
            masks = [(t > a + 1e-9) & (t <= b + 1e-9) for a, b in zip(edges[:-1], edges[1:])]
            values = np.array([np.nanmean(y[m]) if m.any() else math.nan for m in masks])
        ok = np.isfinite(values)
        if ok.sum() < 3:
            errors[column], counts[column] = math.nan, 0.0
            continue
        slope, intercept = np.polyfit(centres[ok], values[ok], 1)
        detrended = values[ok] - (slope * centres[ok] + intercept)
        spread = float(np.sqrt(np.sum(detrended**2) / (ok.sum() - 2))) if ok.sum() > 2 else math.nan
        n_eff = effective_count(int(ok.sum()), lag1_autocorrelation(detrended))
        errors[column], counts[column] = spread / math.sqrt(n_eff), n_eff
    return errors, counts


def seed_scatter(reference_dir: str | Path = "data/reference") -> dict[str, float]:
    """{column: relative scatter of one run's window mean between seeds} from the stored seed pairs (module
    docstring): abs(second / first - 1) / sqrt(2) over the pair's common steady window (both cut to their common
    span first), the largest over the pairs."""
    from analysis.runs import load_run

    root = Path(reference_dir)
    out: dict[str, float] = {}
    for first, second in SEED_PAIRS:
        if not ((root / first / "timeseries.csv").is_file() and (root / second / "timeseries.csv").is_file()):
            continue
        window, (a, b) = pair_window(load_run(root / first).timeseries, load_run(root / second).timeseries)
        if window[1] - window[0] < 3 * BLOCK:
            continue
        mean_a, mean_b = window_means(a, window), window_means(b, window)
        for column in TARGET_COLUMNS:
            relative = abs(mean_b[column] / mean_a[column] - 1.0) / math.sqrt(2.0)
            out[column] = max(out.get(column, 0.0), relative)
    return out


def load_target(name: str, reference_dir: str | Path = "data/reference", seed: dict | None = None,
                block: float = BLOCK, max_window: float = MAX_WINDOW) -> Target:
    """The :class:`Target` of the stored reference ``reference_dir/name`` (``seed``: :func:`seed_scatter`'s result,
    computed when None)."""
    from analysis.runs import load_run

    series = load_run(Path(reference_dir) / name).timeseries
    window, steady = scored_window(series, max_window)
    means = window_means(series, window)
    within, counts = within_run_errors(series, window, block)
    seed = seed_scatter(reference_dir) if seed is None else seed
    seed_errors = {c: seed.get(c, 0.0) * abs(means[c]) for c in TARGET_COLUMNS}
    errors = {c: math.hypot(within[c], seed_errors[c]) for c in TARGET_COLUMNS}
    return Target(name=name, window=window, steady=steady, means=means, standard_errors=errors, within=within,
                  seed=seed_errors, effective_blocks=counts)
