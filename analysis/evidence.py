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
  unequal pair (from ``merges_by_size.csv``) over the gravitational collisions that pi (a_i + a_j)^2 abs(U_i - U_j) n_i
  n_j V predicts, integrated over the snapshots in horizontal slices (so that the clouds' separation as they settle
  counts), with the measured mean settling velocity of each size; its standard error from the Poisson count of
  merges and the scatter of the velocity difference over the snapshots.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

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
    mean of the block means, "block_means", "spread": max abs(block mean / mean - 1)}."""
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
    """E = merges / (pi (a_s + a_l)^2 integral abs(U_l - U_s) C dt) with C = sum N_s N_l / V over slices
    (:func:`pair_exposure`), trapezoidal over the snapshots.

    Droplets placed at rest (a snapshot whose two mean velocities are both exactly 0: the initial state) reach their
    terminal velocity within the particle relaxation time rho_p d^2 / (18 mu), about 1 ms here, so such a snapshot
    takes the velocity difference of the next one; with 0 the first interval would count half its collisions.
    Standard error: the Poisson count (sqrt M / M), the standard error of the mean velocity difference over the
    snapshots and the time quadrature (the change of E when every second snapshot is dropped, a first-order
    estimate of the error of the trapezoidal rule at the snapshots' spacing), in quadrature. Returns {"efficiency",
    "standard_error", "quadrature_error", "expected_collisions", "merges", "velocity_difference" [m/s]}."""
    t = np.asarray(exposure["times"], dtype=float)
    u_small = np.asarray(exposure["velocity_small"], dtype=float)
    u_large = np.asarray(exposure["velocity_large"], dtype=float)
    du = np.abs(u_large - u_small)
    at_rest = (u_small == 0.0) & (u_large == 0.0)
    for i in np.flatnonzero(at_rest)[::-1]:
        later = [j for j in range(i + 1, len(du)) if not at_rest[j] and np.isfinite(du[j])]
        if later:
            du[i] = du[later[0]]
    c = np.asarray(exposure["exposure"], dtype=float)
    good = np.isfinite(du) & np.isfinite(c)
    cross = math.pi * (0.5 * (diameter_small + diameter_large)) ** 2
    rate = np.where(good, cross * np.nan_to_num(du) * c, 0.0)
    expected = _trapezoid(rate, t)
    efficiency = merges / expected if expected > 0 else math.nan
    half = sorted(set(range(0, len(t), 2)) | {len(t) - 1})
    coarse = _trapezoid(rate[half], t[half]) if len(t) > 2 else math.nan
    quadrature = abs(merges / coarse - efficiency) if coarse > 0 else math.nan
    weights = c[good]
    mean_du = float(np.average(du[good], weights=weights)) if weights.sum() > 0 else math.nan
    du_error = float(np.std(du[good], ddof=1) / math.sqrt(good.sum())) if good.sum() > 1 else math.nan
    relative = math.sqrt((1.0 / merges if merges > 0 else math.inf) + (du_error / mean_du) ** 2)
    statistical = efficiency * relative
    return {"efficiency": efficiency, "standard_error": math.hypot(statistical, np.nan_to_num(quadrature)),
            "quadrature_error": quadrature, "expected_collisions": expected, "merges": int(merges),
            "velocity_difference": mean_du}


def _trapezoid(y, x) -> float:
    return float(np.trapezoid(y, x)) if hasattr(np, "trapezoid") else float(np.trapz(y, x))


def _bin_of(diameter: float, edges: np.ndarray) -> tuple[float, float]:
    """The merges-by-size bin (low, high] [m] that holds ``diameter`` (edges of fulldem's SIZE_BINS)."""
    bounds = np.concatenate([[0.0], edges, [np.inf]])
    b = int(np.searchsorted(edges, diameter, side="right"))
    return float(bounds[b]), float(bounds[b + 1])


#: The kernel run's exposure over every droplet snapshot of its run folder, stored beside the reference (the
#: reference keeps a few snapshots only; E needs them all): time [s], exposure [1/m^3], velocity_small and
#: velocity_large [m/s], and the run's merges of the pair in the units line's header.
EXPOSURE_FILE = "kernel_exposure.csv"
EXPOSURE_UNITS = {"time": ("s", "snapshot time"), "exposure": ("1/m^3", "sum over slices of N_s N_l / V_slice"),
                  "velocity_small": ("m/s", "mean settling velocity of the small size"),
                  "velocity_large": ("m/s", "mean settling velocity of the large size")}


def kernel_exposure(run_folder, diameter_small: float = 0.5e-3, diameter_large: float = 1.0e-3,
                    slice_height: float | None = None) -> tuple[pd.DataFrame, int, dict]:
    """(the :func:`pair_exposure` table over every droplet snapshot of a kernel run folder, the merges between the
    merges-by-size bins of the two fed sizes, {"small": bin, "large": bin} [m]); slices of one cell height unless
    ``slice_height`` [m]."""
    from fulldem.submodels.coalescence import SIZE_BINS

    from .figures import read_droplets
    from .runs import load_run

    run = load_run(run_folder)
    if run.merges_by_size is None:
        raise ValueError(f"{run_folder}: no merges_by_size.csv (a kernel run has coalescence on)")
    case = run.case
    small, large = _bin_of(diameter_small, SIZE_BINS), _bin_of(diameter_large, SIZE_BINS)
    table = run.merges_by_size
    pair = table[np.isclose(table["small_low"], small[0]) & np.isclose(table["large_low"], large[0])]
    snapshots = [read_droplets(run_folder, float(t)) for t in run.snapshot_times()]
    exposure = pair_exposure(snapshots, small, large, case.geometry.width * case.geometry.depth,
                             slice_height or case.fulldem.cell_size)
    frame = pd.DataFrame({"time": exposure["times"], "exposure": exposure["exposure"],
                          "velocity_small": exposure["velocity_small"], "velocity_large": exposure["velocity_large"]})
    return frame, int(pair["merges"].sum()), {"small": small, "large": large}


def write_kernel_exposure(run_folder, dest, diameter_small: float = 0.5e-3, diameter_large: float = 1.0e-3) -> Path:
    """Write :data:`EXPOSURE_FILE` of the kernel run folder ``run_folder`` into the folder ``dest`` (atomically)."""
    from settler.output import atomic_write_text, units_line

    frame, merges, bins = kernel_exposure(run_folder, diameter_small, diameter_large)
    header = (units_line(EXPOSURE_UNITS) + f"# merges: {merges} between ({bins['small'][0]:.9g}, {bins['small'][1]:.9g}] "
              f"and ({bins['large'][0]:.9g}, {bins['large'][1]:.9g}] m; sizes {diameter_small:g} and "
              f"{diameter_large:g} m\n")
    path = Path(dest) / EXPOSURE_FILE
    atomic_write_text(path, header + frame.to_csv(index=False, float_format="%.9g"))
    return path


def kernel_run_efficiency(run_folder, diameter_small: float = 0.5e-3, diameter_large: float = 1.0e-3,
                          slice_height: float | None = None) -> dict:
    """The collision efficiency of a kernel run (two sizes settling without feed; the reference set's 'kernel'):
    the merges between the bins of the two fed sizes (``merges_by_size.csv``) over the gravitational collisions of
    :func:`collision_efficiency`, with the exposure and velocities from every droplet snapshot of the run folder,
    or from its :data:`EXPOSURE_FILE` where the folder is a stored reference (each size counted within its
    merges-by-size bin; slices of one cell height unless ``slice_height`` [m]).
    Returns the result of :func:`collision_efficiency` plus "bins" and "snapshots"."""
    stored = Path(run_folder) / EXPOSURE_FILE
    if stored.is_file() and slice_height is None:
        frame = pd.read_csv(stored, comment="#")
        head = [line for line in stored.read_text().splitlines()[:3] if line.startswith("# merges:")]
        numbers = re.findall(r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?", head[0].split(":", 1)[1])
        merges = int(numbers[0])
        bins = {"small": (float(numbers[1]), float(numbers[2])), "large": (float(numbers[3]), float(numbers[4]))}
    else:
        frame, merges, bins = kernel_exposure(run_folder, diameter_small, diameter_large, slice_height)
    exposure = {"times": frame["time"].to_numpy(), "exposure": frame["exposure"].to_numpy(),
                "velocity_small": frame["velocity_small"].to_numpy(), "velocity_large": frame["velocity_large"].to_numpy()}
    result = collision_efficiency(merges, exposure, diameter_small, diameter_large)
    result.update(bins=bins, snapshots=len(frame))
    return result


#: Steady quantities of the paper table and the seed scatter: time-series columns.
STEADY_COLUMNS = ("droplet_count", "mean_diameter", "sauter_diameter", "channel_radius", "channel_velocity",
                  "centreline_settling_velocity", "mean_settling_velocity", "coalesced_count")


def run_summary(run) -> dict:
    """The steady window of a run's droplet count (:func:`steady_window`) and the means of :data:`STEADY_COLUMNS`
    over it (over the last third where no window is steady: ``steady`` False)."""
    series = run.timeseries
    window = steady_window(series)
    steady = math.isfinite(window["start"])
    start = window["start"] if steady else float(series["time"].iloc[-1]) * 2.0 / 3.0
    means = steady_means(series, [c for c in STEADY_COLUMNS if c in series], start)
    last = series.iloc[-1]
    fed = float(last["mass_fed"])
    return {"steady": steady, "start": start, "cycles": window["cycles"], "spread": window["spread"], **means,
            "settled_fraction": float(last["mass_settled"]) / fed if fed > 0 else math.nan,
            "end_time": float(last["time"])}


def density_line(droplets: pd.DataFrame) -> tuple[float, float]:
    """Least-squares line density = a + b z of a snapshot's droplets: (a [kg/m^3], b [kg/m^4]) (seed paper Fig. 20)."""
    b, a = np.polyfit(droplets["z"].to_numpy(), droplets["density"].to_numpy(), 1)
    return float(a), float(b)


def report(root="data/reference") -> str:
    """The reference set's evidence as text: each stored run's steady summary, the seed scatter of simple and
    cubic, deep's rim and density line, the resolution checks. ``python -m analysis.evidence [ROOT]``."""
    from pathlib import Path

    from .runs import load_run

    root = Path(root)
    runs = {p.name: load_run(p) for p in sorted(root.iterdir()) if (p / "reference.json").is_file()}
    summaries = {name: run_summary(run) for name, run in runs.items()}
    lines = ["run | steady from [s] (cycles, spread) | count | mean d [mm] | d32 [mm] | channel radius [mm] | "
             "axis velocity [mm/s] | settled fraction | end [s]"]
    for name, s in summaries.items():
        steady = f"{s['start']:.0f} ({s['cycles']}, {100 * s['spread']:.1f} %)" if s["steady"] else \
            f"not steady (last third from {s['start']:.0f})"
        lines.append(f"{name} | {steady} | {s['droplet_count']:.0f} | {1e3 * s['mean_diameter']:.3f} | "
                     f"{1e3 * s['sauter_diameter']:.3f} | {1e3 * s['channel_radius']:.1f} | "
                     f"{1e3 * s['channel_velocity']:.1f} | {s['settled_fraction']:.3f} | {s['end_time']:g}")
    for first, second in (("simple", "simple_seed2"), ("cubic", "cubic_seed2")):
        if first in summaries and second in summaries:
            scatter = seed_scatter({k: summaries[first][k] for k in STEADY_COLUMNS if k in summaries[first]},
                                   summaries[second])
            lines.append(f"seed scatter {second} vs {first}: "
                         + ", ".join(f"{k} {100 * v:+.1f} %" for k, v in scatter.items()))
    if "deep" in runs:
        run = runs["deep"]
        t, frame = run.droplets()
        axis = run.case.inlet_center
        for low, high in ((0.15, 0.35),):
            rim = rim_share(frame, axis, low, high)
            lines.append(f"deep rim test at t = {t:g} s, z {low}-{high} m: {rim['rim']} of {rim['outside']} droplets "
                         f"beyond 2 r_half = {2e3 * rim['half_volume_radius']:.1f} mm never merged and older than "
                         f"2 x the median age {rim['median_age']:.1f} s: share {rim['share']:.3f}")
        a, b = density_line(frame)
        lines.append(f"deep density line at t = {t:g} s: {a:.0f} + {b:.0f} z kg/m^3 (z in m above the bottom)")
    if "kernel" in runs:
        e = kernel_run_efficiency(root / "kernel")
        lines.append(f"kernel collision efficiency E = {e['efficiency']:.3f} +- {e['standard_error']:.3f} ({e['merges']} "
                     f"merges against {e['expected_collisions']:.0f} gravitational collisions over {e['snapshots']} "
                     f"snapshots; quadrature error {e['quadrature_error']:.3f})")
    for coarse, fine in (("deep", "deep_fine"), ("demo", "demo_cell_33"), ("demo", "demo_cell_25")):
        if coarse in runs and fine in runs:
            end = min(summaries[fine]["end_time"], summaries[coarse]["end_time"])
            start = end * 2.0 / 3.0
            cols = ["droplet_count", "channel_radius", "channel_velocity"]
            c = steady_means(runs[coarse].timeseries, cols, start, end)
            f = steady_means(runs[fine].timeseries, cols, start, end)
            lines.append(f"resolution {fine} vs {coarse} over {start:.0f}-{end:.0f} s: "
                         + ", ".join(f"{k} {c[k]:.4g} -> {f[k]:.4g} ({100 * (f[k] / c[k] - 1):+.1f} %)"
                                     for k in cols))
    return "\n".join(lines)


if __name__ == "__main__":
    import sys

    print(report(sys.argv[1] if len(sys.argv) > 1 else "data/reference"))
