"""The matte layer over the floor, by size: the measure behind the thickness of popbal's bottom layer
(``bottom_layer_factor``, ``bottom_layer_form``; popbal.closures, the bottom layer).

Over a full run's steady window (its last third if none; :func:`analysis.steady.window_snapshots`) the droplets'
lowest points, z - d / 2 above the floor, are counted in :data:`BIN` high bins up to :data:`TOP` (at most 0.4 of the
slag height), over the whole floor and per size bin (:data:`EDGES`), as a mean over the window's droplet snapshots:
n(z) [1/m], droplets per metre of height. A layer is an excess over the far value n_far (the mean over
:data:`FAR` above the floor) that peaks at the floor; its *excess thickness* is

    delta = sum_z max(n(z) - n_far, 0) dz / (n(0) - n_far)   [m],

n(0) the lowest bin's, the height a layer of the floor's excess concentration would fill. The same with droplet
volume instead of number gives the layer's thickness over all sizes (the table's header). NaN where the floor bin
holds fewer than :data:`MIN_FLOOR` droplets per snapshot, or does not exceed 1.5 n_far (no layer). For an excess
A exp(-z / lambda) the estimate is dz / (1 - exp(-dz / lambda)) (lambda + dz / 2 for lambda >> dz; the tests).

What it measures (2026-12-06, the remade training runs' point folders, docs/guide/reduced-model.md): in every
coalescing run of the demo's families the layer is 2.5-5 mm thick for every droplet size alike (0.4 to 2 mm, own
settling velocities 0.4 to 6 mm/s), so it is not a sedimentation-dispersion layer (whose thickness D / U would
fall 15-fold over those sizes) but a layer of the flow: where the plume's discharge slows against the floor, its
droplets slow to their own settling velocity and gather. ``python -m analysis.floor_layer RUN...`` prints the table;
:func:`write_floor_layer` stores it beside a reference run (:data:`FLOOR_LAYER_FILE`, written by
``python -m analysis.reference_set``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from .files import MeasureError, read_window_header, window_header

#: Height of the profile's bins [m].
BIN = 1e-3
#: The profile's top above the floor [m] (at most 0.4 of the slag height).
TOP = 40e-3
#: The far value's span above the floor [m] (scaled with TOP where the slag is lower).
FAR = (30e-3, 40e-3)
#: Size-bin edges [m] of the table (the last bin open above).
EDGES = np.array([0.0, 0.45, 0.55, 0.65, 0.8, 1.0, 1.3, 2.0, np.inf]) * 1e-3
#: Fewest droplets per snapshot in a bin's floor bin for a thickness.
MIN_FLOOR = 3.0
#: The stored table's name beside a reference run.
FLOOR_LAYER_FILE = "floor_layer.csv"
#: Its columns: name -> (unit, meaning).
FLOOR_LAYER_UNITS = {
    "diameter_low": ("m", "size bin's lower edge"),
    "diameter_high": ("m", "size bin's upper edge (inf: open)"),
    "mean_diameter": ("m", "mean diameter of the bin's droplets in the floor bin"),
    "settling_velocity": ("m/s", "their own terminal settling velocity at that diameter"),
    "floor_number": ("1/m", "droplets per metre of height in the lowest bin, whole floor, mean over snapshots"),
    "far_number": ("1/m", "the same, mean over the far span"),
    "thickness": ("m", "excess thickness delta of the bin's layer (NaN: no layer)"),
}


def excess_thickness(profile, bin_height: float = BIN, far: slice | None = None) -> float:
    """delta [m] of ``profile`` (values per bin from the floor up, each ``bin_height`` [m] high; module docstring),
    its far value the mean over the bins ``far`` (default: the top quarter). NaN where the floor bin does not
    exceed 1.5 times the far value."""
    n = np.asarray(profile, dtype=float)
    far = far if far is not None else slice(3 * len(n) // 4, len(n))
    n_far = float(n[far].mean())
    if not n[0] > 1.5 * n_far:
        return math.nan
    return float(np.sum(np.maximum(n - n_far, 0.0)) * bin_height / (n[0] - n_far))


def layer_profiles(snapshots, height: float, edges=EDGES) -> dict:
    """{"heights" (bin bottoms [m]), "number" (size bins x height bins [1/m]), "volume" (height bins [m^3/m]),
    "diameter_sum" (size bins: summed diameters in the floor bin [m]), "far" (the far span's slice)} over
    ``snapshots``, a list of DataFrames with z [m] (centre above the floor) and diameter [m]; means over them.
    ValueError without snapshots."""
    if not snapshots:
        raise ValueError("no droplet snapshot in the window: the floor layer needs one or more")
    top = min(TOP, 0.4 * height)
    bins = max(int(round(top / BIN)), 4)
    z_edges = np.arange(bins + 1) * BIN
    scale = bins * BIN / TOP
    far = slice(int(round(FAR[0] * scale / BIN)), int(round(FAR[1] * scale / BIN)))
    sizes = len(edges) - 1
    number = np.zeros((sizes, bins))
    volume = np.zeros(bins)
    diameter_sum = np.zeros(sizes)
    for frame in snapshots:
        d = frame["diameter"].to_numpy(dtype=float)
        low = frame["z"].to_numpy(dtype=float) - 0.5 * d
        size = np.clip(np.digitize(d, edges) - 1, 0, sizes - 1)
        for k in range(sizes):
            number[k] += np.histogram(low[size == k], z_edges)[0]
        volume += np.histogram(low, z_edges, weights=np.pi / 6.0 * d**3)[0]
        floor = (low >= 0.0) & (low < BIN)
        np.add.at(diameter_sum, size[floor], d[floor])
    count = len(snapshots)
    return {"heights": z_edges[:-1], "number": number / (count * BIN), "volume": volume / (count * BIN),
            "diameter_sum": diameter_sum / count, "far": far}


def layer_table(profiles, case=None) -> tuple[pd.DataFrame, float]:
    """(table per size bin, thickness of the layer by volume [m]) of :func:`layer_profiles`; each bin's settling
    velocity from ``case`` (settler.derived.settling_velocity; NaN without one)."""
    number, far = profiles["number"], profiles["far"]
    rows = []
    for k in range(number.shape[0]):
        floor_count = number[k, 0] * BIN
        mean_d = profiles["diameter_sum"][k] / floor_count if floor_count > 0 else math.nan
        thick = excess_thickness(number[k], BIN, far) if floor_count >= MIN_FLOOR else math.nan
        rows.append({"diameter_low": EDGES[k], "diameter_high": EDGES[k + 1], "mean_diameter": mean_d,
                     "floor_number": number[k, 0], "far_number": float(number[k, far].mean()), "thickness": thick})
    table = pd.DataFrame(rows)
    velocity = np.full(len(table), math.nan)
    known = table["mean_diameter"].notna().to_numpy()
    if case is not None and known.any():
        from settler.derived import settling_velocity

        velocity[known] = settling_velocity(case, table["mean_diameter"].to_numpy()[known])
    table.insert(3, "settling_velocity", velocity)
    return table, excess_thickness(profiles["volume"], BIN, far)


def measure_floor_layer(run, window: tuple[float, float] | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder or :class:`analysis.Run` over ``window`` (default: its steady window, else
    its last third): :func:`layer_table` of its droplet snapshots there; meta {"window", "snapshots", "thickness"
    (by volume, all sizes [m])}. ValueError where the window holds no droplet snapshot."""
    from .runs import load_run
    from .steady import window_snapshots

    run = run if hasattr(run, "timeseries") else load_run(run)
    window, times = window_snapshots(run, window)
    if not times:
        raise ValueError(f"no droplet snapshot within {window[0]:g}-{window[1]:g} s: the floor layer needs one or more "
                         "(a stored reference keeps few; give the run folder or another window)")
    profiles = layer_profiles([run.droplets(t)[1] for t in times], run.case.geometry.height)
    table, thickness = layer_table(profiles, run.case)
    return table, {"window": (float(window[0]), float(window[1])), "snapshots": list(times), "thickness": thickness}


def write_floor_layer(run_folder, dest, window: tuple[float, float] | None = None) -> Path:
    """Measure ``run_folder`` over ``window`` (:func:`measure_floor_layer`) and write :data:`FLOOR_LAYER_FILE` into
    ``dest`` atomically, the window, the thickness by volume and the snapshots in its header."""
    from settler.output import atomic_write_text, units_line

    table, meta = measure_floor_layer(run_folder, window)
    header = units_line(FLOOR_LAYER_UNITS) + window_header(meta["window"], meta["snapshots"],
                                                           {"thickness": f"{meta['thickness']!r} m"})
    path = Path(dest) / FLOOR_LAYER_FILE
    atomic_write_text(path, header + table.to_csv(index=False, float_format="%.7g"))
    return path


def read_floor_layer(path) -> tuple[pd.DataFrame, dict]:
    """The (table, meta) a :func:`write_floor_layer` file holds (meta: window, thickness, snapshots)."""
    fields = read_window_header(path)
    meta = {"window": fields["window"], "thickness": float(fields["thickness"].split()[0]),
            "snapshots": fields["snapshots"]}
    return pd.read_csv(path, comment="#"), meta


def bottom_factor(runs, reference_dir, values: dict | None = None) -> dict:
    """popbal's bottom layer factor f_b = delta_b / R_c [-] measured in stored runs, not fitted: per run the floor
    layer's thickness by volume delta_b [m] (:data:`FLOOR_LAYER_FILE` beside the run, its steady window) over popbal's
    channel radius R_c [m] at the [popbal] ``values`` (dotted keys on the run's own case.toml, its calibration layer
    set aside; :func:`popbal.model.channel_closure`), as popbal makes the layer h_b = f_b R_c thick. f_b is the
    geometric mean over the runs; "standard_error" the log values' standard deviation over sqrt(n), times f_b (NaN
    for one run); "spread" exp of that standard deviation, the factor one run lies off the mean; "per_run" {run:
    {"thickness", "channel_radius", "factor"}}; "no_layer" the runs whose floor holds no layer (thickness NaN: too
    few droplets there, or no excess over the far value, as in the deep family, whose large droplets settle as they
    arrive), left out of the mean: their layer is not thin but absent, which f_b R_c cannot say. For coalescing runs
    only: a floor without coalescence fills (docs/guide/reduced-model.md), which is not the layer h_b stands for.
    ValueError naming the run whose file is missing, holds no thickness or one not positive and finite, whose case
    popbal refuses or gives no channel at ``values``; MeasureError (a ValueError) when no run has a layer."""
    from popbal.model import channel_closure
    from settler.cases import NO_CALIBRATION, CaseError, load_case

    if not runs:
        raise MeasureError("the bottom layer factor needs at least one stored run with its floor layer; none was "
                           "given")
    per_run, no_layer = {}, []
    for run in runs:
        folder = Path(reference_dir) / run
        path = folder / FLOOR_LAYER_FILE
        if not path.is_file():
            raise ValueError(f"{path}: missing (python -m analysis.reference_set writes it beside every stored run, "
                             "python -m analysis.floor_layer measures a run folder)")
        try:
            thickness = read_floor_layer(path)[1]["thickness"]
        except (KeyError, ValueError, IndexError) as exc:
            raise ValueError(f"{path}: no thickness in its header ({exc}); rewrite it with python -m "
                             "analysis.reference_set") from None
        if math.isnan(thickness):
            no_layer.append(run)
            continue
        if not (math.isfinite(thickness) and thickness > 0.0):
            raise ValueError(f"{path}: floor layer thickness {thickness!r} m; allowed: a positive finite thickness or "
                             "NaN (no layer)")
        try:
            case = load_case(folder / "case.toml", {"case.calibration": NO_CALIBRATION, **(values or {})})
            radius = channel_closure(case)[0]
        except CaseError as exc:
            raise ValueError(f"{run}: {exc}") from None
        if not radius > 0.0:
            raise ValueError(f"{run}: popbal's channel radius is {radius!r} m at the values given; allowed: a channel "
                             "(popbal.channel_radius_factor > 0)")
        per_run[run] = {"thickness": thickness, "channel_radius": radius, "factor": thickness / radius}
    if not per_run:
        raise MeasureError(f"no floor layer in {', '.join(runs)} (floor_layer.csv thickness NaN in each): the "
                           "bottom layer factor needs at least one run with a layer")
    logs = np.log([v["factor"] for v in per_run.values()])
    sd = float(np.std(logs, ddof=1)) if len(logs) > 1 else math.nan
    value = float(np.exp(logs.mean()))
    return {"value": value, "standard_error": value * sd / math.sqrt(len(logs)), "spread": math.exp(sd),
            "per_run": per_run, "no_layer": no_layer, "runs": list(per_run)}


def _report(folder, table, meta) -> None:
    print(f"{folder}: {meta['window'][0]:g}-{meta['window'][1]:g} s, {len(meta['snapshots'])} snapshots; "
          f"layer thickness by volume {meta['thickness'] * 1e3:.2f} mm")
    show = table.copy()
    for column in ("diameter_low", "diameter_high", "mean_diameter", "thickness"):
        show[column] *= 1e3
    show["settling_velocity"] *= 1e3
    print(show.rename(columns={"diameter_low": "d_low [mm]", "diameter_high": "d_high [mm]", "mean_diameter": "d [mm]",
                               "settling_velocity": "U [mm/s]", "floor_number": "n(0) [1/m]",
                               "far_number": "n_far [1/m]", "thickness": "delta [mm]"}).to_string(
        index=False, float_format=lambda x: f"{x:.4g}"))


def main(argv=None) -> int:
    from .steady import window_measure_main

    return window_measure_main(
        argv, "python -m analysis.floor_layer",
        "the matte layer over the floor of full runs, by size (the measure of popbal's bottom layer thickness)",
        "full run folders or stored references (one snapshot gives a noisy profile; a run folder's every snapshot "
        "in the window is used)", measure_floor_layer, _report)


if __name__ == "__main__":
    raise SystemExit(main())
