"""What the return flow lifts off the floor, by size: the measure behind popbal's ``bottom_lift_share`` and
``bottom_lift_velocity_ratio`` (popbal.closures, the bottom layer's lift).

Over a full run's steady window (its last third if none; :func:`analysis.steady.window_of`), each pair of
consecutive droplet snapshots is compared by the droplets' ``ident``: of the droplets in the floor band (the bottom
:data:`FLOOR_BAND` of the slag height) at the first, those found above the band at the second were *lifted*, those
no longer in the slag (settled, or merged: a merge gives the product a new ident) *left* otherwise; the rest are
still there. By size bin (:data:`EDGES`, the first snapshot's diameters), the share lifted of those that went,
lifted / (lifted + left), estimates the share of what leaves the floor that the return flow carries off it. The
snapshots must be close enough for few droplets to go in and out of the band between them (the remade runs write
one a second; a droplet settling at 1 mm/s crosses a 10 mm band in 10 s).

:func:`fit_lift` fits popbal's form lambda exp(-(U / u_b)^2) (:func:`popbal.closures.lift_share`, the one
implementation) to those counts by binomial maximum likelihood, U each bin's own terminal settling velocity at its
droplets' mean diameter (:func:`settler.derived.settling_velocity`), and the run's slag gives u_up, the mean upflow
over the part of the mid-height layer of cells where the slag rises (time mean over the window's slag snapshots; NaN
where the snapshots keep no whole slag grid), so that beta = u_b / u_up. Measured on the demo at 2.5 mm cells
continued to 60 s (35-60 s, 26 snapshots; exploratory, 2026-12-06): 4.5 % of the floor's leavers lifted, 0.136 below
0.5 mm and none above 1 mm; lambda 0.199 +- 0.008, u_b 0.754 +- 0.016 mm/s, u_up 3.78 mm/s, beta 0.199.

``python -m analysis.floor_lift RUN...`` prints the table and the fit; ``write_floor_lift`` stores it beside a
reference run (:data:`FLOOR_LIFT_FILE`, written by ``python -m analysis.reference_set``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from .files import read_window_header, window_header

#: The floor band: the bottom tenth of the slag height [-] (the zone diagnostics' bottom band).
FLOOR_BAND = 0.1
#: Size-bin edges [m] of the table (the last bin open above).
EDGES = np.array([0.0, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0, 1.2, 1.6, 2.4, np.inf]) * 1e-3
#: The stored table's name beside a reference run.
FLOOR_LIFT_FILE = "floor_lift.csv"
#: Its columns: name -> (unit, meaning).
FLOOR_LIFT_UNITS = {
    "diameter_low": ("m", "size bin's lower edge"),
    "diameter_high": ("m", "size bin's upper edge (inf: open)"),
    "mean_diameter": ("m", "mean diameter of the bin's floor droplets"),
    "settling_velocity": ("m/s", "their own terminal settling velocity at that diameter"),
    "held": ("-", "droplets in the floor band, mean over the snapshot pairs' first snapshots"),
    "lifted": ("1/s", "floor droplets found above the band at the next snapshot, per second"),
    "left": ("1/s", "floor droplets no longer in the slag at the next snapshot (settled or merged), per second"),
    "share": ("-", "lifted / (lifted + left)"),
}


def lift_counts(snapshots, height: float, edges=EDGES) -> tuple[pd.DataFrame, float]:
    """(table, seconds) from ``snapshots``, a time-ordered list of (time [s], DataFrame with ident, z [m] and
    diameter [m]): per size bin of ``edges`` [m] the droplets held in the floor band (mean over the first snapshots
    of each pair), lifted and left (totals over the pairs, module docstring) and their summed diameters; seconds is
    the time the pairs span [s]. ValueError with fewer than two snapshots or without idents."""
    if len(snapshots) < 2:
        raise ValueError(f"{len(snapshots)} droplet snapshot(s) in the window: the floor's lift needs two or more")
    band = FLOOR_BAND * height
    bins = len(edges) - 1
    held, lifted, left, diameter_sum = (np.zeros(bins) for _ in range(4))
    span = 0.0
    for (t_a, a), (t_b, b) in zip(snapshots[:-1], snapshots[1:]):
        if "ident" not in a or "ident" not in b:
            raise ValueError("the droplet snapshots carry no ident: the floor's lift needs droplets followed from one "
                             "snapshot to the next")
        floor = a["z"].to_numpy() < band
        ident = a["ident"].to_numpy()[floor].astype(np.int64)
        size = np.clip(np.digitize(a["diameter"].to_numpy()[floor], edges) - 1, 0, bins - 1)
        later = pd.Series(b["z"].to_numpy(), index=b["ident"].to_numpy().astype(np.int64))
        later = later[~later.index.duplicated()]
        found = later.reindex(ident).to_numpy()
        np.add.at(held, size, 1.0)
        np.add.at(diameter_sum, size, a["diameter"].to_numpy()[floor])
        np.add.at(lifted, size[found >= band], 1.0)
        np.add.at(left, size[np.isnan(found)], 1.0)
        span += float(t_b - t_a)
    pairs = len(snapshots) - 1
    with np.errstate(invalid="ignore", divide="ignore"):
        table = pd.DataFrame({"diameter_low": edges[:-1], "diameter_high": edges[1:],
                              "mean_diameter": diameter_sum / held, "held": held / pairs,
                              "lifted": lifted / span, "left": left / span, "share": lifted / (lifted + left)})
    return table, span


def fit_lift(velocity, lifted, left) -> dict:
    """Binomial maximum-likelihood fit of lambda exp(-(U / u_b)^2) to ``lifted`` of ``lifted + left`` droplets per
    bin of settling velocity U [m/s] (counts, or rates over one span): {"share" lambda [-], "lift_velocity" u_b
    [m/s], "standard_errors" (of both, from the observed information; counts must then be counts), "converged"}.
    NaN where nothing was lifted."""
    from scipy.optimize import minimize

    from popbal.closures import lift_share

    u = np.asarray(velocity, dtype=float)
    k, m = np.asarray(lifted, dtype=float), np.asarray(left, dtype=float)
    use = np.isfinite(u) & (k + m > 0)
    u, k, m = u[use], k[use], m[use]
    nan = {"share": math.nan, "lift_velocity": math.nan, "standard_errors": (math.nan, math.nan), "converged": False}
    if k.sum() <= 0.0 or len(u) < 2:
        return nan
    scale = float(np.median(u[k > 0])) or 1e-3

    def nll(x):  # the binomial negative log-likelihood of (lambda, u_b)
        p = np.clip(lift_share(u, x[0], x[1]), 1e-300, 1.0 - 1e-15)
        return -float(np.sum(k * np.log(p) + m * np.log1p(-p)))

    def unpack(theta):  # lambda in (0, 1) by a logistic, u_b > 0 by a logarithm
        return 1.0 / (1.0 + math.exp(-theta[0])), scale * math.exp(theta[1])

    first = k.sum() / (k.sum() + m.sum())
    best = minimize(lambda theta: nll(unpack(theta)), [math.log(first / (1.0 - first)), 0.0], method="Nelder-Mead",
                    options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 4000})
    lam, ub = unpack(best.x)
    # observed information in (lambda, u_b) by central differences of the log-likelihood
    step = np.array([1e-4 * lam, 1e-4 * ub])
    x0 = np.array([lam, ub])
    info = np.zeros((2, 2))
    for i in range(2):
        for j in range(2):
            ei, ej = np.eye(2)[i] * step[i], np.eye(2)[j] * step[j]
            info[i, j] = (nll(x0 + ei + ej) - nll(x0 + ei - ej) - nll(x0 - ei + ej) + nll(x0 - ei - ej)) \
                / (4.0 * step[i] * step[j])
    try:
        errors = tuple(float(e) for e in np.sqrt(np.diag(np.linalg.inv(info))))
    except np.linalg.LinAlgError:
        errors = (math.nan, math.nan)
    return {"share": lam, "lift_velocity": ub, "standard_errors": errors, "converged": bool(best.success)}


def mid_height_upflow(run, times) -> float:
    """u_up [m/s]: the mean upward slag velocity over the cells of the mid-height layer where the slag rises, time
    mean over the slag snapshots at ``times`` [s]; NaN where they keep no whole slag grid (a stored reference)."""
    from .files import NoData

    values = []
    height = run.case.geometry.height
    for time in times:
        try:
            _, centres, velocity = run.slag(time)
        except (NoData, ValueError):
            return math.nan
        z = centres[:, 2]
        layer = np.isclose(z, z[np.argmin(np.abs(z - 0.5 * height))])
        if layer.sum() < 4:  # one plane of the slag, not a layer of cells
            return math.nan
        w = velocity[layer, 2]
        values.append(w[w > 0.0].mean() if (w > 0.0).any() else 0.0)
    return float(np.mean(values)) if values else math.nan


def measure_floor_lift(run, window: tuple[float, float] | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder or :class:`analysis.Run` over ``window`` (default: its steady window, else
    its last third): :func:`lift_counts` with each bin's own settling velocity, and meta {"window", "snapshots",
    "share", "lift_velocity", "standard_errors", "upflow", "velocity_ratio"} (module docstring). ValueError where the
    window holds fewer than two snapshots or they carry no idents."""
    from settler.derived import settling_velocity

    from .runs import load_run
    from .steady import window_snapshots

    run = run if hasattr(run, "timeseries") else load_run(run)
    window, times = window_snapshots(run, window)
    snapshots = [(t, run.droplets(t)[1]) for t in times]
    table, _ = lift_counts(snapshots, run.case.geometry.height)
    diameter = table["mean_diameter"].to_numpy()
    velocity = np.full(len(diameter), math.nan)
    held = np.isfinite(diameter)
    velocity[held] = settling_velocity(run.case, diameter[held])
    table.insert(3, "settling_velocity", velocity)
    counts = table["held"].notna() & (table["lifted"] + table["left"] > 0)
    span = times[-1] - times[0]
    fit = fit_lift(table.loc[counts, "settling_velocity"], table.loc[counts, "lifted"] * span,
                   table.loc[counts, "left"] * span)
    upflow = mid_height_upflow(run, times)
    meta = {"window": (float(window[0]), float(window[1])), "snapshots": times, **fit, "upflow": upflow,
            "velocity_ratio": fit["lift_velocity"] / upflow if upflow and math.isfinite(upflow) else math.nan}
    return table, meta


def write_floor_lift(run_folder, dest, window: tuple[float, float] | None = None) -> Path:
    """Measure ``run_folder`` over ``window`` (:func:`measure_floor_lift`; default its steady window, else its last
    third) and write :data:`FLOOR_LIFT_FILE` into ``dest`` atomically, the window, snapshots and the fit in its
    header."""
    from settler.output import atomic_write_text, units_line

    table, meta = measure_floor_lift(run_folder, window)
    se = meta["standard_errors"]
    header = units_line(FLOOR_LIFT_UNITS) + window_header(meta["window"], meta["snapshots"], {
        "share": f"{meta['share']!r} +- {se[0]!r}", "lift_velocity": f"{meta['lift_velocity']!r} +- {se[1]!r} m/s",
        "upflow": f"{meta['upflow']!r} m/s", "velocity_ratio": repr(meta["velocity_ratio"])})
    path = Path(dest) / FLOOR_LIFT_FILE
    atomic_write_text(path, header + table.to_csv(index=False, float_format="%.9g"))
    return path


def read_floor_lift(path) -> tuple[pd.DataFrame, dict]:
    """The (table, meta) a :func:`write_floor_lift` file holds (meta: window, share, lift_velocity, their standard
    errors, upflow, velocity_ratio, snapshots)."""
    fields = read_window_header(path)

    def value_error(text):
        parts = text.replace(" m/s", "").split(" +- ")
        return float(parts[0]), float(parts[1])

    share, share_se = value_error(fields["share"])
    lift, lift_se = value_error(fields["lift_velocity"])
    meta = {"window": fields["window"], "share": share, "lift_velocity": lift,
            "standard_errors": (share_se, lift_se), "upflow": float(fields["upflow"].split()[0]),
            "velocity_ratio": float(fields["velocity_ratio"]), "snapshots": fields["snapshots"]}
    return pd.read_csv(path, comment="#"), meta


def _report(folder, table, meta) -> None:
    se = meta["standard_errors"]
    print(f"{folder}: {meta['window'][0]:g}-{meta['window'][1]:g} s, {len(meta['snapshots'])} snapshots; "
          f"lifted share lambda {meta['share']:.4f} +- {se[0]:.4f}, u_b {meta['lift_velocity'] * 1e3:.3f} +- "
          f"{se[1] * 1e3:.3f} mm/s, mid-height upflow {meta['upflow'] * 1e3:.3f} mm/s, beta "
          f"{meta['velocity_ratio']:.3f}")
    show = table[table["held"] > 0].copy()
    for column in ("diameter_low", "diameter_high", "mean_diameter"):
        show[column] *= 1e3
    show["settling_velocity"] *= 1e3
    print(show.rename(columns={"diameter_low": "d_low [mm]", "diameter_high": "d_high [mm]", "mean_diameter": "d [mm]",
                               "settling_velocity": "U [mm/s]", "lifted": "lifted [1/s]",
                               "left": "left [1/s]"}).to_string(index=False, float_format=lambda x: f"{x:.4g}"))


def main(argv=None) -> int:
    from .steady import window_measure_main

    return window_measure_main(
        argv, "python -m analysis.floor_lift",
        "what the return flow lifts off the floor of full runs, by size (the measure of popbal's bottom_lift_share)",
        "full run folders (a stored reference keeps too few snapshots)", measure_floor_lift, _report)


if __name__ == "__main__":
    raise SystemExit(main())
