"""The furnace study: one-at-a-time matte-loss trends and a global sensitivity ranking of the furnace preset, which
the trends report calls.
"""

from __future__ import annotations

import math

import pandas as pd

from settler.cases import case_with_overrides
from settler.output import atomic_write_text, prepare_output_folder, source_commit, to_json

from .execution import POINTS, Executor, sweep
from .results import _save_png, _style, axis_scale


#: Baseline of the furnace study: the furnace preset with these overrides. The feed is a truncated normal, the only
#: feed distribution whose mean size and width are case keys, matched to the preset's table: mean 200 um with scale
#: std 0.3 on [0.1, 1.9] has a mass-mean diameter of 245 um [derived], the table's (Jylha et al. 2020, Table 2) is
#: 247 um. end_time 1e6 s so that every run stops at its own residence time (a deeper bath or a lower throughput
#: keeps the slag longer). Resolution: the preset's own (100 cells, 30 s steps, 3 sections per doubling). A coarser
#: study resolution (50 cells, 60 s, 2 per doubling) biased the baseline loss 5 % low (and 12 % low against 200
#: cells, 15 s, 4 per doubling; measured 2026-12-02 on the table feed: 8.84e-4, 9.34e-4, 1.01e-3; upwind diffusion
#: in z); it was used only for speed, until popbal's pair-list coalescence halved a point's cost: 100 points at the
#: preset's resolution took 110 s on the 2-core machine with 2 workers (load average 2.9-4.8; 168 s at 5.7-6.1),
#: benchmarks/bench_sweep.py --resolution preset, 2026-12-02. The tap hole's height, unused by the plug-flow
#: column, is lowered to 0.2 m [chosen] so that it lies inside the thinnest slag layer of the study (0.5 m).
FURNACE_BASE = {
    "feed.distribution": "normal", "feed.mean_diameter": 200e-6, "feed.scale_std": 0.3, "feed.scale_min": 0.1,
    "feed.scale_max": 1.9, "popbal.end_time": 1.0e6, "geometry.outlet_height": 0.2,
}
#: Coarser for quick=True (report CI: numbers that run in seconds, not results).
FURNACE_QUICK = {"popbal.height_cells": 20, "popbal.time_step": 120.0, "popbal.output_interval": 1800.0,
                 "popbal.sections_per_doubling": 2}
#: The study's axes: key -> (low, high, source). The one-at-a-time trends take TREND_POINTS values over each range
#: (linear; the baseline value is one of them), the others at the baseline; the global designs sample the same box.
FURNACE_AXES = {
    "slag.temperature": (1493.15, 1593.15, "[lit] 1220-1320 C, the settler slag temperatures of the seed paper "
                                           "(section 1); viscosity 0.86-0.25 Pa s by the Arrhenius law of the "
                                           "property set (0.45 Pa s at 1270 C)"),
    "feed.mean_diameter": (100e-6, 400e-6, "[chosen] around the 200 um baseline (table's mass-mean 247 um, "
                                           "Jylha et al. 2020)"),
    "feed.scale_std": (0.1, 0.4, "[chosen] narrow (0.1, the seed paper's Table 3) to wide (0.4 of the mean; the "
                                 "truncation at 0.1-1.9 is then 2.25 std)"),
    "geometry.height": (0.5, 1.5, "[chosen] slag depth around the preset's 1 m; at a fixed slag feed the residence "
                                  "time grows with it (3-9 h)"),
    "slag.feed_rate": (10.208333333333334, 40.833333333333336, "[chosen] slag throughput 0.5 to 2 times the "
                       "preset's 20.4 kg/s (derived there from a 6 h residence): residence 12 h to 3 h at 1 m"),
    "popbal.collision_efficiency": (0.0, 3.0, "[chosen] 0 (no coalescence) to 3; the calibration layer "
                                              "data/calibration/paper.toml (simple + cubic, 2026-12-02) gives 0.09 "
                                              "+- 0.25, not determined by its data (first fit, simple only: 1.60 +- "
                                              "1.35); the baseline keeps the furnace preset's uncalibrated 1, as "
                                              "the preset does not apply that layer"),
}
TREND_POINTS = 7
#: Global designs of the full study: Sobol N (points N (D + 2)), Morris trajectories (points r (D + 1)).
FURNACE_SOBOL_SAMPLES = 64
FURNACE_MORRIS_TRAJECTORIES = 20


def furnace_study(out, quick: bool = False, workers: int | None = None, scheduler: str | None = None,
                  progress: bool = True, seed: int = 0) -> dict:
    """The matte-loss study of the furnace preset (reduced model, horizontal plug flow) into ``out``.

    Trends: loss, settled fraction and mean size against each key of :data:`FURNACE_AXES` alone
    (``out/trends/<key>/``, TREND_POINTS values, the others at :data:`FURNACE_BASE`), and ``out/trends.png``.
    Global sensitivity over the whole box: Sobol (``out/sobol/``, N = FURNACE_SOBOL_SAMPLES) and Morris
    (``out/morris/``, FURNACE_MORRIS_TRAJECTORIES trajectories), each with sensitivity.csv and .png. All sweeps
    share ``out/points`` and one cluster, so a rerun or a point repeated between designs is not run again.
    quick=True: 3 values per key, Morris with 2 trajectories, no Sobol, at FURNACE_QUICK resolution, in this
    process unless ``workers`` is given, without the per-trend PNGs (seconds; for report CI). Writes
    ``ranking.csv`` (:func:`ranking`) and ``study.json`` (baseline, axes with sources). Returns {"trends": {key:
    SweepResult}, "sobol", "morris": SweepResult or None, "figure": Path, "ranking": DataFrame}. From a script,
    call it under ``if __name__ == "__main__":`` (see :func:`sweep`).
    """
    out = prepare_output_folder(out, resume=True)
    base = case_with_overrides("furnace", {**FURNACE_BASE, **(FURNACE_QUICK if quick else {})})
    points = out / POINTS
    count = 3 if quick else TREND_POINTS
    options = dict(points_dir=points, progress=progress, seed=seed)
    results: dict = {"trends": {}, "sobol": None, "morris": None}
    with Executor(0 if quick and workers is None and scheduler is None else workers, scheduler) as executor:
        options["client"] = executor.client
        options["workers"] = 0 if executor.local else None
        for key, (low, high, _) in FURNACE_AXES.items():
            results["trends"][key] = sweep(base, [f"{key}={low}:{high}:{count}"], "grid",
                                           out=out / "trends" / key, plots=not quick, **options)
        box = [f"{key}={low}:{high}" for key, (low, high, _) in FURNACE_AXES.items()]
        if not quick:
            results["sobol"] = sweep(base, box, "sobol", FURNACE_SOBOL_SAMPLES, out=out / "sobol", **options)
        results["morris"] = sweep(base, box, "morris", 2 if quick else FURNACE_MORRIS_TRAJECTORIES,
                                  out=out / "morris", **options)
    results["figure"] = _save_png(plot_study(results["trends"]), out / "trends.png")
    results["ranking"] = ranking(results)
    atomic_write_text(out / "ranking.csv", results["ranking"].to_csv(index=False))
    atomic_write_text(out / "study.json", to_json({
        "base_case": "furnace", "overrides": {**FURNACE_BASE, **(FURNACE_QUICK if quick else {})}, "quick": quick,
        "axes": {k: {"low": lo, "high": hi, "source": src} for k, (lo, hi, src) in FURNACE_AXES.items()},
        "trend_points": count, **source_commit()}))
    return results


def ranking(results: dict) -> pd.DataFrame:
    """What changes the matte loss most, one row per key of FURNACE_AXES: the one-at-a-time range of the loss
    (``trend_loss_min``, ``_max``, ``_range``) and, for each global design run, its indices of the loss and of its
    log10 (``sobol_<output>_ST``, ``_ST_conf``, ``_S1``, ``_S1_conf``; ``morris_<output>_mu_star``,
    ``_mu_star_conf``). Ordered by the first present of Morris mu* of log10 loss, Sobol ST of log10 loss, the trend
    range: relative changes, since the loss spans decades over the box."""
    rows = {key: {"parameter": key} for key in FURNACE_AXES}
    for key, trend in results["trends"].items():
        loss = trend.table["matte_loss"]
        rows[key].update(trend_loss_min=float(loss.min()), trend_loss_max=float(loss.max()),
                         trend_loss_range=float(loss.max() - loss.min()))
    indices = {"sobol": ("ST", "ST_conf", "S1", "S1_conf"), "morris": ("mu_star", "mu_star_conf")}
    for design, columns in indices.items():
        frame = results[design].sensitivity if results.get(design) is not None else None
        if frame is None:
            continue
        for _, row in frame[frame["metric"].isin(["matte_loss", "log10_matte_loss"])].iterrows():
            rows[row["parameter"]].update({f"{design}_{row['metric']}_{c}": row.get(c) for c in columns})
    table = pd.DataFrame(list(rows.values()))
    order = next((c for c in ("morris_log10_matte_loss_mu_star", "sobol_log10_matte_loss_ST", "trend_loss_range")
                  if c in table and table[c].notna().all()), None)
    return table.sort_values(order, ascending=False).reset_index(drop=True) if order else table


def plot_study(trends: dict):
    """Matte loss against each key of the one-at-a-time trends, one panel each (loss in %)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 6.5), layout="constrained")
    axes = fig.subplots(2, math.ceil(len(trends) / 2)).ravel()
    for ax, (key, trend) in zip(axes, trends.items()):
        ok = trend.table[trend.table["status"] == "done"].sort_values(key)
        factor, label = axis_scale(key, ok[key])
        ax.plot(ok[key] * factor, ok["matte_loss"] * 100.0, "o-", ms=3)
        _style(ax, key, "matte_loss", ok["matte_loss"], label)
        ax.set_ylabel("matte loss [%]")
    fig.suptitle("furnace: matte lost with the slag, one key at a time (others at the study baseline)")
    return fig
