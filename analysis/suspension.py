"""How a full run's droplets away from the plume are spread over the height, size by size (SI units).

A droplet of settling velocity U in a column stirred with an eddy diffusivity D and no mean vertical flow settles
into n(z) ∝ exp(-U z / D) (the steady Mason-Weaver profile: the settling flux U n balances the diffusive flux
-D dn/dz). popbal's outer zone carries its droplets by the mean upflow alone, with no such spreading, so that a size
whose U exceeds the upflow cannot stay suspended there. This module measures, in one snapshot (or several), the
vertical profile of each size class of the droplets farther than ``exclude`` from the inlet axis (the plume's core
left out) between a tenth and nine tenths of the height (the roof and floor layers left out), fits ln n = a - k z by
Poisson-weighted least squares (weights n, the inverse variance of ln n), and gives the apparent diffusivity
D = U_mean / k [m^2/s] of the class, U_mean its droplets' mean terminal velocity (:func:`settler.derived.
settling_velocity`). Apparent: a mean upflow u there would make the slope (U - u) / D. The slopes' errors count the
droplets as independent: summed over several snapshots of one run, which hold largely the same droplets, they are
too small. :func:`settling_fit` fits the classes' slopes as one suspension, k = k0 + U / D_e.

``python -m analysis.suspension RUN... [--exclude MM] [--window START:END]`` prints the table; the registered
hold-outs are refused (the measure is for designing closures). Default exclusion 0.6 of the inlet radius [chosen:
outside the collision core of every training run, analysis.channel_clustering, and inside the box of each].

What it measures (2026-12-07, the stored runs' last snapshot, docs/guide/reduced-model.md): in simple and cubic
every class from 0.3 to 2 mm decays upward, the apparent D rising with size from 0.5e-4 to 3.7e-4 m^2/s, and
:func:`settling_fit` gives k0 = 5.0 +- 0.2 and 5.5 +- 0.3 /m, D_e = (4.8 +- 0.3)e-4 and (5.0 +- 0.5)e-4 m^2/s
(chi2 per degree of freedom 2.2 and 5.0). Of the demo families only demo_visc_half_fine determines D_e,
(4.3 +- 2.2)e-4 m^2/s; in the others it is undetermined or the slope does not grow with U.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd


#: Size-class edges [m] (the last class open above 2 mm is left out: too few droplets to fit).
EDGES = np.array([0.0, 0.4, 0.6, 0.8, 1.0, 1.3, 2.0]) * 1e-3
#: Height bins between a tenth and nine tenths of the height.
HEIGHT_BINS = 8
#: The fewest droplets a height bin needs to enter a fit, and the fewest bins a fit needs.
MIN_BIN_COUNT, MIN_BINS = 5, 3
#: Default exclusion radius about the inlet axis, as a share of the inlet radius [chosen, module docstring].
EXCLUDE_SHARE = 0.6

#: Columns of :func:`size_profiles`: name -> (unit, meaning).
PROFILE_UNITS = {
    "diameter_low": ("m", "the class's lower edge"),
    "diameter_high": ("m", "the class's upper edge"),
    "droplets": ("-", "droplets of the class in the fitted heights, summed over the snapshots"),
    "settling_velocity": ("m/s", "their mean terminal velocity U"),
    "slope": ("1/m", "k of ln n = a - k z, Poisson-weighted (NaN: too few droplets)"),
    "slope_error": ("1/m", "its standard error"),
    "diffusivity": ("m^2/s", "apparent D = U / k (NaN where k <= 0 or not fitted)"),
}


def fit_slope(z, counts) -> tuple[float, float]:
    """(k [1/m], its standard error) of ln n = a - k z over the bins at heights ``z`` [m] holding ``counts`` (at
    least :data:`MIN_BIN_COUNT` droplets each, else left out), weighted by n (Poisson: var ln n = 1/n); NaN with
    fewer than :data:`MIN_BINS` such bins."""
    z, n = np.asarray(z, dtype=float), np.asarray(counts, dtype=float)
    keep = n >= MIN_BIN_COUNT
    if keep.sum() < MIN_BINS:
        return math.nan, math.nan
    z, n = z[keep], n[keep]
    zbar = float(np.sum(n * z) / n.sum())
    sxx = float(np.sum(n * (z - zbar) ** 2))
    slope = float(np.sum(n * (z - zbar) * np.log(n)) / sxx)
    return -slope, 1.0 / math.sqrt(sxx)


def size_profiles(snapshots, centre, exclude: float, height: float) -> pd.DataFrame:
    """The :data:`PROFILE_UNITS` table of ``snapshots``, each a tuple (position (n, 3) [m], diameter (n,) [m],
    settling velocity (n,) [m/s]): the droplets farther than ``exclude`` [m]
    from the vertical axis through ``centre`` (x, y) [m] and between 0.1 and 0.9 of ``height`` [m], in
    :data:`HEIGHT_BINS` equal bins."""
    bins = np.linspace(0.1 * height, 0.9 * height, HEIGHT_BINS + 1)
    mid = 0.5 * (bins[1:] + bins[:-1])
    classes = len(EDGES) - 1
    counts = np.zeros((classes, HEIGHT_BINS))
    u_sum = np.zeros(classes)
    for position, diameter, velocity in snapshots:
        position = np.asarray(position, dtype=float).reshape(-1, 3)
        far = np.hypot(position[:, 0] - centre[0], position[:, 1] - centre[1]) > exclude
        inside = far & (position[:, 2] >= bins[0]) & (position[:, 2] < bins[-1])
        k = np.searchsorted(EDGES, np.asarray(diameter, dtype=float), side="right") - 1
        ok = inside & (k >= 0) & (k < classes)
        np.add.at(counts, (k[ok], np.clip(np.searchsorted(bins, position[ok, 2], side="right") - 1, 0,
                                           HEIGHT_BINS - 1)), 1.0)
        np.add.at(u_sum, k[ok], np.asarray(velocity, dtype=float)[ok])
    rows = []
    for c in range(classes):
        total = counts[c].sum()
        slope, error = fit_slope(mid, counts[c])
        u = u_sum[c] / total if total > 0 else math.nan
        rows.append({"diameter_low": EDGES[c], "diameter_high": EDGES[c + 1], "droplets": total,
                     "settling_velocity": u, "slope": slope, "slope_error": error,
                     "diffusivity": u / slope if slope > 0 else math.nan})
    return pd.DataFrame(rows)


def settling_fit(table: pd.DataFrame) -> dict:
    """The classes' slopes as one stirred suspension, k = k0 + U / D_e (Mason-Weaver's U / D plus a gradient k0 that
    even the slowest droplets share), fitted by least squares weighted by the slopes' standard errors over the classes
    of ``table`` (:func:`size_profiles`) whose slope was fitted: {"k0" [1/m], "k0_error", "diffusivity" D_e [m^2/s],
    "diffusivity_error", "chi2_per_dof" [-], "classes" [(low, high) [m]]}. The errors are scaled by sqrt(chi2 per
    degree of freedom) where that exceeds 1 (the line does not hold within the slopes' own errors). NaN with fewer
    than three classes."""
    rows = table[np.isfinite(table["slope"]) & np.isfinite(table["slope_error"]) & (table["slope_error"] > 0)]
    classes = [(float(a), float(b)) for a, b in zip(rows["diameter_low"], rows["diameter_high"])]
    nan = {"k0": math.nan, "k0_error": math.nan, "diffusivity": math.nan, "diffusivity_error": math.nan,
           "chi2_per_dof": math.nan, "classes": classes}
    if len(rows) < 3:
        return nan
    u, k, w = (rows[c].to_numpy(dtype=float) for c in ("settling_velocity", "slope", "slope_error"))
    a = np.column_stack([np.ones_like(u), u]) / w[:, None]
    coefficients, *_ = np.linalg.lstsq(a, k / w, rcond=None)
    covariance = np.linalg.inv(a.T @ a)
    chi2 = float(np.sum(((k - coefficients[0] - coefficients[1] * u) / w) ** 2)) / (len(rows) - 2)
    covariance *= max(chi2, 1.0)
    k0, inverse = float(coefficients[0]), float(coefficients[1])
    inverse_error = math.sqrt(covariance[1, 1])
    return {"k0": k0, "k0_error": math.sqrt(covariance[0, 0]),
            "diffusivity": 1.0 / inverse if inverse > 0 else math.nan,
            "diffusivity_error": inverse_error / inverse**2 if inverse > 0 else math.nan,
            "chi2_per_dof": chi2, "classes": classes}


def measure_suspension(run, exclude: float | None = None,
                       window: tuple[float, float] | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder, stored reference or :class:`analysis.Run`: :func:`size_profiles` of its
    droplet snapshots in ``window`` (default its steady window, else its last third) beyond ``exclude`` [m] (default
    :data:`EXCLUDE_SHARE` of the inlet radius); meta {"window", "snapshots", "exclude"}. ValueError naming the run
    where the window holds no snapshot or the inlet is a slot."""
    from .plume_zones import axis_window, settling_snapshots

    run, window, times, _ = axis_window(run, window, (), "the suspension is measured away from")
    g = run.case.geometry
    exclude = EXCLUDE_SHARE * 0.5 * float(g.inlet_diameter) if exclude is None else float(exclude)
    snapshots = settling_snapshots(run, times)
    table = size_profiles(snapshots, tuple(run.case.inlet_center), exclude, float(g.height))
    return table, {"window": window, "snapshots": list(times), "exclude": exclude}


def main(argv=None) -> int:
    """``python -m analysis.suspension RUN... [--exclude MM] [--window START:END] [--registry FILE]``: exit 0, or 2
    with one line naming the run or the value that failed."""
    import argparse
    import sys
    from pathlib import Path

    from .calibration.registry import RegistryError, load_registry, refuse_holdout_folders
    from .files import NoData, OutputError
    from .steady import parse_window

    prog = "python -m analysis.suspension"
    parser = argparse.ArgumentParser(prog=prog, description=(
        "how a full run's droplets away from the plume are spread over the height, size class by size class: the "
        "slope of ln n against z and the apparent eddy diffusivity D = U / slope"))
    parser.add_argument("runs", nargs="+", help="full run folders or stored references")
    parser.add_argument("--exclude", type=float, metavar="MM", help="radius [mm] about the inlet axis left out "
                        f"(default {EXCLUDE_SHARE:g} of the inlet radius)")
    parser.add_argument("--window", help="START:END [s]; default each run's steady window, else its last third")
    parser.add_argument("--registry", default="data/calibration/holdouts.toml",
                        help="the calibration's registry: its pre-registered hold-outs are refused")
    args = parser.parse_args(argv)
    try:
        window = parse_window(args.window) if args.window else None
        if args.exclude is not None and not (args.exclude >= 0.0 and math.isfinite(args.exclude)):
            raise ValueError(f"--exclude {args.exclude!r}: a radius in mm must be zero or positive")
        refuse_holdout_folders(args.runs, load_registry(args.registry), "the suspension measure")
    except (ValueError, OSError, RegistryError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    for folder in args.runs:
        try:
            table, meta = measure_suspension(folder, None if args.exclude is None else args.exclude * 1e-3, window)
        except (OutputError, ValueError, OSError, NoData) as exc:
            text = str(exc)
            print(f"{prog}: {text if text.startswith(str(Path(folder))) else f'{folder}: {text}'}", file=sys.stderr)
            return 2
        print(f"{folder}: beyond {meta['exclude'] * 1e3:.1f} mm of the inlet axis, {len(meta['snapshots'])} "
              f"snapshot(s) in {meta['window'][0]:g}-{meta['window'][1]:g} s")
        for row in table.itertuples():
            print(f"  d {row.diameter_low * 1e3:.1f}-{row.diameter_high * 1e3:.1f} mm  droplets {row.droplets:7.0f}"
                  f"  U {row.settling_velocity * 1e3:5.2f} mm/s  slope {row.slope:7.1f} +- {row.slope_error:5.1f} /m"
                  f"  D {row.diffusivity:.2e} m^2/s")
        fit = settling_fit(table)
        span = (f"{fit['classes'][0][0] * 1e3:.1f}-{fit['classes'][-1][1] * 1e3:.1f} mm" if fit["classes"] else "none")
        print(f"  k = k0 + U / D_e over the {len(fit['classes'])} fitted classes ({span}), weighted by the slopes' "
              f"errors: k0 {fit['k0']:.1f} +- {fit['k0_error']:.1f} /m, D_e {fit['diffusivity']:.2e} +- "
              f"{fit['diffusivity_error']:.1e} m^2/s, chi2 per degree of freedom {fit['chi2_per_dof']:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
