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
* :func:`height_bands` -- where a run's droplets are: the count in the top band (the roof layer), the bottom band
  (over the floor) and between, from a full run's snapshot or popbal's distribution alike, so that the two engines'
  counts can be compared zone by zone rather than as one number.
* :func:`merge_shares` -- where a run merges over a window: from ``merges_by_height.csv`` (full engine since
  a04ea13, popbal), the merge rate and its shares under the inlet, in the top and the bottom band, band by band.
* :func:`band_efficiency` -- the collision efficiency of a whole run band by band: its merges over the gravitational
  collisions its droplets make cell by cell (:mod:`analysis.band_efficiency`), to set beside the kernel run's.
* :func:`floor_arrivals` -- how a full run's droplets reach the floor: their count, mean vertical velocity against
  their own settling velocity, and arrival rate within a thin layer over the floor, under the plume and away from
  it.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from settler.derived import settling_velocity
from settler.output import half_volume_radius

from .band_efficiency import band_efficiency, cell_collision_rates, merges_between  # noqa: F401
from .kernel_run import (EXPOSURE_FILE, collision_efficiency, kernel_exposure, kernel_run_efficiency,  # noqa: F401
                         pair_exposure, write_kernel_exposure)
from .runs import REDUCED_ENGINE, load_run
from .steady import CYCLE, STEADY_CYCLES, STEADY_TOLERANCE, steady_window, window_of  # noqa: F401

#: (coarse, fine) runs of the resolution checks in :func:`report`: the same case at 5 mm and finer cells.
RESOLUTION_PAIRS = (("deep", "deep_fine"), ("demo", "demo_cell_33"), ("demo", "demo_cell_25"),
                    ("demo_feed_half", "demo_feed_half_fine"), ("demo_feed_double", "demo_feed_double_fine"))


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


#: Thickness of the top and bottom bands of :func:`height_bands` [m]: two 5 mm cells of the designed set's grid.
HEIGHT_BAND = 0.01


def height_bands(run, time: float | None = None, band: float = HEIGHT_BAND) -> dict:
    """Where the droplets of ``run`` (an :class:`analysis.Run`, full engine or popbal) are at the output nearest
    ``time`` [s] (default: the last): {"time" [s], "top" (droplets within ``band`` [m] of the slag's top), "bottom"
    (within ``band`` of the floor), "middle" (between), "total"}, counts [-]. A full run's are counted in its
    snapshot; popbal's are its number density [1/m^3] times the zone's area [m^2] and the cell's height, the cells
    counted by their centres. Refuses a band that leaves no middle."""
    height = float(run.case.geometry.height)
    if not (0.0 < band < height / 2.0):
        raise ValueError(f"band = {band!r} m: must be > 0 and below half the height ({height / 2.0:g} m)")
    if run.engine == REDUCED_ENGINE:
        data = run.distribution()
        times = data["time"].to_numpy()
        k = len(times) - 1 if time is None else int(np.argmin(np.abs(times - time)))
        z = data["z"].to_numpy()
        dz = np.gradient(z) if len(z) > 1 else np.array([height])
        density = data["number_density"].isel(time=k).to_numpy().sum(axis=-1)  # zone, z [1/m^3]
        per_height = (density * data["zone_area"].to_numpy()[:, None]).sum(axis=0) * dz
        at = float(times[k])
    else:
        at, droplets = run.droplets(run.snapshot_times()[-1] if time is None else time)
        z = droplets["z"].to_numpy()
        per_height = np.ones_like(z)
    top = float(per_height[z >= height - band].sum())
    bottom = float(per_height[z < band].sum())
    total = float(per_height.sum())
    return {"time": float(at), "top": top, "bottom": bottom, "middle": total - top - bottom, "total": total}


def merge_shares(run, window: tuple[float, float] | None = None) -> dict:
    """Where ``run`` (an :class:`analysis.Run` of either engine, or a folder) merged between the ``merges_by_height``
    rows nearest the ``window`` (start, end) [s] (default: its steady window, else its last third,
    :func:`window_of`): {"window" (the rows' times) [s], "merges" [-], "rate" [1/s], "under_inlet", "top", "bottom"
    (shares of the merges under the inlet, in the top and in the bottom height band) [-], "bands" (a DataFrame: z
    [m], merges_under_inlet, merges_elsewhere over the window [-])}; shares NaN without merges. Raises ValueError for
    a run without the table (full runs made before a04ea13) or a window shorter than its snapshot spacing."""
    run = load_run(run)
    table = run.zones.get("merges_by_height")
    if table is None or table.empty:
        raise ValueError(f"{run.folder}: no merges_by_height.csv (full runs made before a04ea13 lack it)")
    if window is None:
        window, _ = window_of(run.timeseries)
    t0, t1, bands = merges_between(table, window, run.folder)
    columns = ["merges_under_inlet", "merges_elsewhere"]
    merges = float(bands[columns].to_numpy().sum())
    per_band = bands[columns].sum(axis=1).to_numpy()
    share = (lambda x: float(x) / merges) if merges > 0.0 else (lambda x: math.nan)
    return {"window": (t0, t1), "merges": merges, "rate": merges / (t1 - t0),
            "under_inlet": share(bands["merges_under_inlet"].sum()), "top": share(per_band[-1]),
            "bottom": share(per_band[0]), "bands": bands}


#: Layer over the floor of :func:`floor_arrivals` [m] and its rings around the inlet axis [m]: the plume's footprint
#: (within one 5 mm cell of the axis), its edge, and the rest of the floor.
FLOOR_LAYER = 1e-3
FLOOR_RINGS = (5e-3, 15e-3)


def floor_arrivals(run, time: float | None = None, layer: float = FLOOR_LAYER, rings=FLOOR_RINGS) -> list[dict]:
    """How a full run's droplets reach the floor, at the snapshot nearest ``time`` [s] (default: the last): per ring
    around the inlet axis (r < rings[0], rings[0] <= r < rings[1], r >= rings[1], r [m] the horizontal distance), the
    droplets within ``layer`` [m] of the floor: {"ring" (inner, outer radius [m]), "count" [-], "velocity" (their mean
    vertical velocity [m/s], negative down), "settling_velocity" (their mean single-droplet terminal velocity
    [m/s]), "ratio" (minus the first over the second: 1 for droplets that cross the floor's wall layer at their own
    settling speed), "arrival_rate" (count x max(0, -velocity) / layer [1/s]: droplets reaching the floor per
    second), "time" [s]}. Where the slag's normal velocity falls to zero at the floor, droplets as small as the fed
    ones (Stokes numbers ~1e-5) reach it at about their settling velocity; a ratio far above 1 that shrinks with
    the cell is the grid's (docs/guide/full-model.md, "near a wall")."""
    if run.engine == REDUCED_ENGINE:
        raise ValueError("floor_arrivals: needs a full run's snapshot (droplet velocities); this is a popbal run")
    if not (layer > 0.0 and all(b > a for a, b in zip((0.0, *rings), rings))):
        raise ValueError(f"layer = {layer!r} m, rings = {rings!r} m: the layer must be > 0 and the ring radii "
                         "increasing and > 0")
    at, droplets = run.droplets(run.snapshot_times()[-1] if time is None else time)
    near = droplets[droplets["z"] < layer]
    axis = run.case.inlet_center
    r = np.hypot(near["x"].to_numpy() - axis[0], near["y"].to_numpy() - axis[1])
    edges = (0.0, *rings, math.inf)
    out = []
    for inner, outer in zip(edges[:-1], edges[1:]):
        ring = near[(r >= inner) & (r < outer)]
        count = len(ring)
        w = float(ring["w"].mean()) if count else math.nan
        terminal = settling_velocity(run.case, ring["diameter"].to_numpy(), ring["density"].to_numpy())
        settling = float(np.mean(terminal)) if count else math.nan
        out.append({"ring": (inner, outer), "count": count, "velocity": w, "settling_velocity": settling,
                    "ratio": -w / settling if count else math.nan,
                    "arrival_rate": count * max(0.0, -w) / layer if count else 0.0, "time": float(at)})
    return out


#: Steady quantities of the paper table and the seed scatter: time-series columns.
STEADY_COLUMNS = ("droplet_count", "mean_diameter", "sauter_diameter", "channel_radius", "channel_velocity",
                  "centreline_settling_velocity", "mean_settling_velocity", "coalesced_count")


def run_summary(run) -> dict:
    """The steady window of a run's droplet count (:func:`steady_window`) and the means of :data:`STEADY_COLUMNS`
    over it (over the last third where no window is steady: ``steady`` False)."""
    series = run.timeseries
    window = steady_window(series)
    (start, _), steady = window_of(series)
    means = steady_means(series, [c for c in STEADY_COLUMNS if c in series], start)
    last = series.iloc[-1]
    fed = float(last["mass_fed"])
    return {"steady": steady, "start": start, "cycles": window["cycles"], "spread": window["spread"], **means,
            "settled_fraction": float(last["mass_settled"]) / fed if fed > 0 else math.nan,
            "end_time": float(last["time"])}


def pair_window(first: pd.DataFrame, second: pd.DataFrame) -> tuple[tuple[float, float], list[pd.DataFrame]]:
    """The window over which two time series of one case (two seeds) are compared: both cut to their common span,
    from the later of their steady starts (:func:`steady_window`; the last third where a run has none) to the span's
    end. Returns ((start, end) [s], [first, second] cut). Two runs of different lengths compared over their own
    windows would score start-up as seed scatter."""
    end = min(float(first["time"].iloc[-1]), float(second["time"].iloc[-1]))
    cut = [s[s["time"] <= end + 1e-9] for s in (first, second)]
    return (max(window_of(series)[0][0] for series in cut), end), cut


def pair_scatter(first: pd.DataFrame, second: pd.DataFrame) -> tuple[tuple[float, float], dict[str, float]]:
    """The seed scatter of two time series of one case over :func:`pair_window`: ((start, end) [s],
    :func:`seed_scatter` of their :data:`STEADY_COLUMNS` means)."""
    window, cut = pair_window(first, second)
    columns = [c for c in STEADY_COLUMNS if c in cut[0] and c in cut[1]]
    means = [steady_means(series, columns, *window) for series in cut]
    return window, seed_scatter(means[0], means[1])


def density_line(droplets: pd.DataFrame) -> tuple[float, float]:
    """Least-squares line density = a + b z of a snapshot's droplets: (a [kg/m^3], b [kg/m^4]) (seed paper Fig. 20)."""
    b, a = np.polyfit(droplets["z"].to_numpy(), droplets["density"].to_numpy(), 1)
    return float(a), float(b)


def report(root="data/reference") -> str:
    """The reference set's evidence as text: each stored run's steady summary, the seed scatter of simple and
    cubic, deep's rim and density line, the collision efficiency, where the runs merge, the resolution checks. ``python -m analysis.evidence [ROOT]``."""
    from pathlib import Path

    root = Path(root)
    runs = {p.name: load_run(p) for p in sorted(root.iterdir()) if (p / "reference.json").is_file()}
    summaries = {name: run_summary(run) for name, run in runs.items()}
    lines = ["run | steady from [s] (cycles, spread) | count | mean d [mm] | d32 [mm] | channel radius [mm] | "
             "axis velocity [mm/s] | settled fraction | end [s]"]
    for name, s in summaries.items():
        steady = f"{s['start']:.0f} ({s['cycles']}, {100 * s['spread']:.1f} %)" if s["steady"] else \
            f"not steady (last third from {s['start']:.0f})"
        # a slot's run has a row of channels: one plume's radius and axis velocity mean nothing there
        plume = "- | -" if runs[name].case.inlet_is_slot else \
            f"{1e3 * s['channel_radius']:.1f} | {1e3 * s['channel_velocity']:.1f}"
        lines.append(f"{name} | {steady} | {s['droplet_count']:.0f} | {1e3 * s['mean_diameter']:.3f} | "
                     f"{1e3 * s['sauter_diameter']:.3f} | {plume} | {s['settled_fraction']:.3f} | {s['end_time']:g}")
    for first, second in (("simple", "simple_seed2"), ("cubic", "cubic_seed2")):
        if first in runs and second in runs:
            window, scatter = pair_scatter(runs[first].timeseries, runs[second].timeseries)
            lines.append(f"seed scatter {second} vs {first} over {window[0]:.0f}-{window[1]:.0f} s: "
                         + ", ".join(f"{k} {100 * v:+.1f} %" for k, v in scatter.items()))
    for name in ("deep", "deep_fine"):
        if name not in runs:
            continue
        run = runs[name]
        t, frame = run.droplets()
        axis = run.case.inlet_center
        for low, high in ((0.15, 0.35),):
            rim = rim_share(frame, axis, low, high)
            lines.append(f"{name} rim test at t = {t:g} s, z {low}-{high} m: {rim['rim']} of {rim['outside']} droplets "
                         f"beyond 2 r_half = {2e3 * rim['half_volume_radius']:.1f} mm never merged and older than "
                         f"2 x the median age {rim['median_age']:.1f} s: share {rim['share']:.3f}")
        a, b = density_line(frame)
        lines.append(f"{name} density line at t = {t:g} s: {a:.0f} + {b:.0f} z kg/m^3 (z in m above the bottom)")
    for name in ("kernel", "kernel_ratio4"):
        if name in runs:
            e = kernel_run_efficiency(root / name)
            lines.append(f"{name} collision efficiency E = {e['efficiency']:.3f} +- {e['standard_error']:.3f} "
                         f"({e['merges']} merges against {e['expected_collisions']:.0f} gravitational collisions over "
                         f"{e['snapshots']} snapshots; quadrature error {e['quadrature_error']:.3f})")
    for name in (n for n, run in runs.items() if run.case.inlet_is_slot):
        from .channels import run_counts

        for r in run_counts(root / name):
            centres = ", ".join(f"{1e3 * c:.0f}" for c in r["centres_50"])
            lines.append(f"{name} channels at t = {r['time']:g} s (central x-z plane): {r['n_25']} / {r['n_50']} / "
                         f"{r['n_75']} at 1/4, 1/2, 3/4 of the height; at mid-height centred at x = {centres} mm")
    for name, run in runs.items():  # where the runs merge (runs made since a04ea13 have the table)
        table = run.zones.get("merges_by_height")
        if table is None or table.empty or not run.case.coalescence.enabled:
            continue
        m = merge_shares(run, (summaries[name]["start"], summaries[name]["end_time"]))
        lines.append(f"{name} merges over {m['window'][0]:.0f}-{m['window'][1]:.0f} s: {m['rate']:.4g} per s, "
                     f"{100 * m['under_inlet']:.0f} % under the inlet, {100 * m['top']:.0f} % in the top tenth of "
                     f"the height, {100 * m['bottom']:.0f} % in the bottom tenth")
        try:  # a stored run keeps few snapshots: the window may hold none
            e = band_efficiency(run, m["window"])
        except ValueError:
            continue
        lines.append(f"{name} collision efficiency where it merges: E = {e['efficiency']:.3f} +- "
                     f"{e['standard_error']:.3f} in {1e3 * e['cell']:g} mm cells over {len(e['snapshots'])} "
                     f"snapshot(s), by band top first " + " ".join(f"{x:.2f}" for x in e["bands"]["efficiency"][::-1]))
        if e["kernels"] is not None:  # the gravitational and shear efficiencies, where the slag's shear was measured
            lines.extend(_kernel_lines(e["kernels"]))
    for coarse, fine in RESOLUTION_PAIRS:
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


def _print_per_run(prog: str, folders, header: str, measure, lines) -> int:
    """Print ``header``, then for each run folder the lines ``lines(name, run, measure(run))``; exit status 0, or 2
    (the error on stderr) at the first folder that cannot be read or measured."""
    import sys
    from pathlib import Path

    from settler.errors import OutputError

    print(header)
    for folder in folders:
        try:
            run = load_run(folder)
            rows = measure(run)
        except (OutputError, ValueError) as exc:
            print(f"{prog}: error: {exc}", file=sys.stderr)
            return 2
        for line in lines(Path(folder).name, run, rows):
            print(line)
    return 0


def _print_height_bands(prog: str, folders, time, band) -> int:
    def measure(run):
        times = [time] if time is not None or run.engine == REDUCED_ENGINE else run.snapshot_times()
        return [height_bands(run, t, band) for t in times]

    def lines(name, run, rows):
        return [f"{name:28s} {run.engine or '?':8s} {b['time']:8.3g} {b['top']:8.0f} {b['middle']:8.0f} "
                f"{b['bottom']:8.0f} {b['total']:8.0f}" for b in rows]

    header = (f"{'run':28s} {'engine':8s} {'time [s]':>8s} {'top':>8s} {'middle':>8s} {'bottom':>8s} {'total':>8s}"
              f"   (droplets; top and bottom bands {1e3 * band:g} mm)")
    return _print_per_run(prog, folders, header, measure, lines)


def _print_floor_arrivals(prog: str, folders, time, layer) -> int:
    def ring(f):
        inner, outer = f["ring"]
        return f"{1e3 * inner:g}-{1e3 * outer:g}" if math.isfinite(outer) else f">{1e3 * inner:g}"

    def lines(name, run, rows):
        return [f"{name:28s} {f['time']:8.3g} {ring(f):>10s} {f['count']:6d} {1e3 * f['velocity']:9.2f} "
                f"{1e3 * f['settling_velocity']:10.2f} {f['ratio']:7.1f} {f['arrival_rate']:14.0f}" for f in rows]

    header = (f"{'run':28s} {'time [s]':>8s} {'ring [mm]':>10s} {'count':>6s} {'w [mm/s]':>9s} {'U_t [mm/s]':>10s} "
              f"{'-w/U_t':>7s} {'arrivals [1/s]':>14s}   (droplets within {1e3 * layer:g} mm of the floor)")
    return _print_per_run(prog, folders, header, lambda run: floor_arrivals(run, time, layer), lines)


def _print_merge_shares(prog: str, folders) -> int:
    def lines(name, run, m):
        per_band = m["bands"][["merges_under_inlet", "merges_elsewhere"]].sum(axis=1).to_numpy()
        profile = " ".join(f"{x / m['merges']:.2f}" if m["merges"] > 0 else "nan" for x in per_band[::-1])
        return [f"{name:28s} {run.engine or '?':8s} {m['window'][0]:7.4g}-{m['window'][1]:<7.4g} {m['rate']:10.4g} "
                f"{m['under_inlet']:7.3f} {m['top']:6.3f} {m['bottom']:7.3f}   {profile}"]

    header = (f"{'run':28s} {'engine':8s} {'window [s]':>15s} {'rate [1/s]':>10s} {'inlet':>7s} {'top':>6s} "
              f"{'bottom':>7s}   shares by height band, top first (merges over the steady window or last third)")
    return _print_per_run(prog, folders, header, merge_shares, lines)


def _kernel_lines(fit) -> list[str]:
    if fit is None:
        return ["    (no whole slag grid in the window: the shear kernel is not measured)"]
    se = fit["standard_errors"]
    return [f"    merges = E_g C_g + E_s C_s over {fit['regions']} band regions: E_g = {fit['gravitational']:.3f} +- "
            f"{se[0]:.3f}, E_s = {fit['shear']:.3f} +- {se[1]:.3f}, correlation {fit['correlation']:.2f}, reduced "
            f"chi2 {fit['chi2_reduced']:.3g}; shear / gravitational collisions {fit['shear_over_gravitational']:.3f}"]


def _print_band_efficiency(prog: str, folders, cell) -> int:
    def lines(name, run, e):
        held = e["bands"]["held"].to_numpy()
        return [f"{name:28s} {e['window'][0]:7.4g}-{e['window'][1]:<7.4g} {len(e['snapshots']):5d} "
                f"{1e3 * e['cell']:6.3g} {e['efficiency']:7.3f} {e['standard_error']:6.3f} "
                f"{e['mixed']['under_inlet']:7.3f} {e['mixed']['elsewhere']:7.3f}   "
                + " ".join(f"{x:.2f}" for x in e["bands"]["efficiency"][::-1])
                + "   held " + " ".join(f"{x / held.sum():.2f}" for x in held[::-1])] + _kernel_lines(e["kernels"])

    header = (f"{'run':28s} {'window [s]':>15s} {'snaps':>5s} {'cell':>6s} {'E':>7s} {'+-':>6s} {'E_inlet':>7s} "
              f"{'E_else':>7s}   efficiency by height band (cell by cell), top first; then the share of the droplets "
              "each band holds (cell in mm; E_inlet, E_else: with each band under the inlet and elsewhere well mixed)")
    return _print_per_run(prog, folders, header, lambda run: band_efficiency(run, None, cell), lines)


def main(argv=None) -> int:
    """``python -m analysis.evidence [ROOT]``: print :func:`report`; ``--height-bands RUN ...``: print
    :func:`height_bands` of each run instead. Exit status 0, 2 for a ROOT that holds no stored reference run or a RUN
    that cannot be read."""
    import argparse
    import sys
    from pathlib import Path

    parser = argparse.ArgumentParser(prog="python -m analysis.evidence", description=report.__doc__.split(".")[0])
    parser.add_argument("root", nargs="?", default="data/reference",
                        help="folder of stored reference runs (default: data/reference)")
    parser.add_argument("--height-bands", nargs="+", metavar="RUN",
                        help="instead of the report, print where the droplets of each RUN folder (a full run, a "
                             "stored reference or a popbal run) are: height_bands at --time (default: each "
                             "snapshot of a full run, the last output of a popbal run)")
    parser.add_argument("--floor", nargs="+", metavar="RUN",
                        help="instead of the report, print how the droplets of each full RUN folder reach the floor "
                             "(floor_arrivals: count, mean vertical velocity and settling velocity within --layer of "
                             "the floor, in rings around the inlet axis) at --time (default: the last snapshot)")
    parser.add_argument("--merges", nargs="+", metavar="RUN",
                        help="instead of the report, print where each RUN folder (a full run since a04ea13, a "
                             "stored reference that has merges_by_height.csv, or a popbal run) merged over its "
                             "steady window (else its last third): merge_shares")
    parser.add_argument("--efficiency", nargs="+", metavar="RUN",
                        help="instead of the report, print the collision efficiency of each full RUN folder band by "
                             "band over its steady window (else its last third): its merges over the gravitational "
                             "collisions of its droplets cell by cell, and with the slag's whole grid the "
                             "gravitational and shear efficiencies fitted together (band_efficiency; needs "
                             "merges_by_height.csv and a droplet snapshot in the window, or a stored reference's "
                             "collisions_by_height.csv)")
    parser.add_argument("--cell", type=float, default=None,
                        help="cell edge for --efficiency [m] (default: the run's fulldem.cell_size)")
    parser.add_argument("--layer", type=float, default=FLOOR_LAYER,
                        help=f"thickness of the floor layer for --floor [m] (default {FLOOR_LAYER})")
    parser.add_argument("--time", type=float, default=None, help="output time for --height-bands and --floor [s]")
    parser.add_argument("--band", type=float, default=HEIGHT_BAND,
                        help=f"thickness of the top and bottom bands for --height-bands [m] (default {HEIGHT_BAND})")
    args = parser.parse_args(argv)
    if args.height_bands:
        return _print_height_bands(parser.prog, args.height_bands, args.time, args.band)
    if args.floor:
        return _print_floor_arrivals(parser.prog, args.floor, args.time, args.layer)
    if args.merges:
        return _print_merge_shares(parser.prog, args.merges)
    if args.efficiency:
        return _print_band_efficiency(parser.prog, args.efficiency, args.cell)
    root = Path(args.root)
    if not root.is_dir() or not any((p / "reference.json").is_file() for p in root.iterdir()):
        print(f"{parser.prog}: error: {root} holds no stored reference run (no <name>/reference.json)",
              file=sys.stderr)
        return 2
    print(report(root))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
