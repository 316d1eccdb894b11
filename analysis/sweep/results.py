"""What a sweep's table says: SALib's sensitivity indices, and the trend and sensitivity plots.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd

from .axes import _field
from .designs import MORRIS_LEVELS, Design


#: Bootstrap resamples of SALib's confidence intervals (95 %).
RESAMPLES = 200


#: Metrics plotted against each swept key and analysed for sensitivity: name -> (axis label, scale to the label).
PLOTTED = {"matte_loss": ("matte loss [%]", 100.0), "settled_fraction": ("settled fraction [%]", 100.0),
           "mean_diameter": ("mean diameter at size_time [um]", 1e6)}
#: Outputs whose sensitivity indices are computed: name -> title. log10_matte_loss ranks relative (factor) changes:
#: where the loss spans decades over the box, the variance of the loss itself is set by the few points with the
#: largest loss (analysed only when every loss is > 0).
ANALYSED = {"matte_loss": "matte loss", "log10_matte_loss": "log10 of the matte loss",
            "settled_fraction": "settled fraction", "mean_diameter": "mean diameter"}


#: Resolution of the PNGs [dots per inch].
DPI = 120
#: Lines drawn per panel of a grid's trend plot (one per combination of the other axes); more are summarised.
MAX_LINES = 8


def sensitivity(table: pd.DataFrame, plan: Design, seed: int = 0) -> tuple[pd.DataFrame | None, str]:
    """SALib's indices of each :data:`ANALYSED` output over the swept keys: Sobol S1, ST (with 95 % confidence
    half-widths) or Morris mu*, mu, sigma (mu* in the output's unit per full range of the key; on log10 for log
    axes); ``rank`` 1 for the largest ST or mu* per output. (None, reason) when a point failed (the estimators need
    every point); an output that is not finite at every point (log10 of a zero loss) gets NaN indices."""
    from ..extras import require

    require("SALib")
    from SALib.analyze import morris, sobol

    failed = int((table["status"] != "done").sum())
    if failed:
        return None, f"no sensitivity indices: {failed} point(s) failed, and SALib needs every point"
    rows = []
    for metric in ANALYSED:
        if metric == "log10_matte_loss":
            with np.errstate(divide="ignore", invalid="ignore"):
                y = np.log10(table["matte_loss"].to_numpy(dtype=float))
        else:
            y = table[metric].to_numpy(dtype=float)
        if not np.all(np.isfinite(y)):
            rows += [{"metric": metric, "parameter": a.key} for a in plan.swept]
            continue
        if plan.name == "sobol":
            s = sobol.analyze(plan.problem, y, calc_second_order=False, num_resamples=RESAMPLES, seed=seed)
            values = {"S1": s["S1"], "S1_conf": s["S1_conf"], "ST": s["ST"], "ST_conf": s["ST_conf"]}
        else:
            s = morris.analyze(plan.problem, plan.samples, y, num_resamples=RESAMPLES, num_levels=MORRIS_LEVELS,
                               seed=seed)
            values = {"mu_star": s["mu_star"], "mu_star_conf": s["mu_star_conf"], "mu": s["mu"],
                      "sigma": s["sigma"]}
        for i, axis in enumerate(plan.swept):
            rows.append({"metric": metric, "parameter": axis.key, "scale": "log10" if axis.log else "linear",
                         **{k: float(v[i]) for k, v in values.items()}})
    frame = pd.DataFrame(rows)
    score = "ST" if plan.name == "sobol" else "mu_star"
    if score in frame:
        frame["rank"] = frame.groupby("metric")[score].rank(ascending=False, method="min")
    return frame, ""


def _save_png(fig, path: Path) -> Path:
    from settler.output import atomic_write_bytes

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    fig.clear()
    atomic_write_bytes(path, buffer.getvalue())
    return path


#: Smaller units for lengths: (largest value below which it is used [m], factor, unit).
LENGTH_UNITS = ((1e-3, 1e6, "µm"), (1e-1, 1e3, "mm"))


def axis_scale(key: str, values=None) -> tuple[float, str]:
    """(factor, label) of a case key on a plot axis: the key in words ("slag.temperature" -> "slag temperature")
    with its unit, lengths below 0.1 m in mm and below 1 mm in µm (``values`` [SI] decide), so that no axis shows
    a diameter in m with an offset."""
    unit = _field(key).unit
    words = key.replace(".", " ").replace("_", " ")
    factor = 1.0
    if unit == "m" and values is not None:
        v = np.abs(np.asarray(values, dtype=float))
        v = v[np.isfinite(v)]
        if v.size:
            for limit, scale, name in LENGTH_UNITS:
                if v.max() < limit:
                    factor, unit = scale, name
                    break
    return factor, (f"{words} [{unit}]" if unit and unit not in ("-", "–") else words)


def _axis_label(key: str) -> str:
    return axis_scale(key)[1]


def _style(ax, key: str, metric: str, values, label: str | None = None) -> None:
    """Axis label (``label``, else the key in words with its unit) and grid; a log y axis for the loss when it
    spans more than two decades (all > 0)."""
    ax.set_xlabel(label or _axis_label(key))
    y = np.asarray(values, dtype=float)
    y = y[np.isfinite(y)]
    if metric == "matte_loss" and y.size and y.min() > 0.0 and y.max() > 100.0 * y.min():
        ax.set_yscale("log")
    ax.grid(alpha=0.3)


def _positions(values: pd.Series):
    """x positions of a column: numbers as they are, anything else as categories (positions, tick labels)."""
    if pd.api.types.is_numeric_dtype(values) and not pd.api.types.is_bool_dtype(values):
        return values.astype(float).to_numpy(), None
    labels = list(dict.fromkeys(map(str, values)))
    return np.array([labels.index(str(v)) for v in values], dtype=float), labels


def plot_trends(table: pd.DataFrame, plan: Design, key: str, title: str = ""):
    """Loss, settled fraction and mean diameter (:data:`PLOTTED`) against one swept key: a grid draws a line per
    combination of the other keys (at most MAX_LINES, else the median over them with its range); a sampled design
    a scatter. Failed points are left out."""
    from matplotlib.figure import Figure

    ok = table[table["status"] == "done"]
    others = [a.key for a in plan.swept if a.key != key]
    fig = Figure(figsize=(12, 3.6), layout="constrained")
    axes = fig.subplots(1, len(PLOTTED))
    for ax, (metric, (label, scale)) in zip(axes, PLOTTED.items()):
        labels = None
        factor, xlabel = axis_scale(key, ok[key] if pd.api.types.is_numeric_dtype(ok[key]) else None)
        if plan.name != "grid":
            x, labels = _positions(ok[key])
            ax.scatter(x * (factor if labels is None else 1.0), ok[metric] * scale, s=12, alpha=0.7)
        else:
            groups = list(ok.groupby(others, sort=True)) if others else [((), ok)]
            if len(groups) <= MAX_LINES:
                for name, group in groups:
                    group = group.sort_values(key)
                    x, labels = _positions(group[key])
                    x = x * (factor if labels is None else 1.0)
                    text = ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                                     for k, v in zip(others, name if isinstance(name, tuple) else (name,)))
                    ax.plot(x, group[metric] * scale, "o-", ms=3, label=text or None)
            else:
                summary = ok.groupby(key, sort=True)[metric].agg(["median", "min", "max"]).reset_index()
                x, labels = _positions(summary[key])
                x = x * (factor if labels is None else 1.0)
                ax.plot(x, summary["median"] * scale, "o-", ms=3, label=f"median over {len(groups)} others")
                ax.fill_between(x, summary["min"] * scale, summary["max"] * scale, alpha=0.25, label="range")
        if labels is not None:
            ax.set_xticks(range(len(labels)), labels)
            ax.set_xlabel(_axis_label(key))
            ax.grid(alpha=0.3)
        else:
            _style(ax, key, metric, ok[metric], xlabel)
        ax.set_ylabel(label)
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(fontsize=7)
    fig.suptitle(f"{title}: {plan.name} sweep over {key}" if title else f"{plan.name} sweep over {key}")
    return fig


def plot_sensitivity(frame: pd.DataFrame, design: str, title: str = ""):
    """Bar chart of the sensitivity indices: one panel per metric, one bar (group) per swept key, with the 95 %
    confidence half-widths: Sobol S1 and ST, or Morris mu* (normalised by its largest value, so the panels share a
    scale)."""
    from matplotlib.figure import Figure

    metrics = [m for m in dict.fromkeys(frame["metric"])
               if frame.loc[frame["metric"] == m].notna().all(axis=None)]
    fig = Figure(figsize=(4.2 * len(metrics), 0.5 * frame["parameter"].nunique() + 2.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(metrics), sharey=True))
    for ax, metric in zip(axes, metrics):
        part = frame[frame["metric"] == metric]
        y = np.arange(len(part))
        if design == "sobol":
            ax.barh(y - 0.2, part["S1"], 0.4, xerr=part["S1_conf"], label="first order S1")
            ax.barh(y + 0.2, part["ST"], 0.4, xerr=part["ST_conf"], label="total order ST")
            ax.set_xlabel("Sobol index")
        else:
            top = float(part["mu_star"].max()) or 1.0
            ax.barh(y, part["mu_star"] / top, 0.6, xerr=part["mu_star_conf"] / top, label="mu* / max mu*")
            ax.set_xlabel("Morris mu* (relative)")
        ax.set_yticks(y, part["parameter"])
        ax.set_title(ANALYSED[metric])
        ax.grid(alpha=0.3, axis="x")
        ax.legend(fontsize=7)
    fig.suptitle(f"{title}: {design} sensitivity" if title else f"{design} sensitivity")
    return fig
