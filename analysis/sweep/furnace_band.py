"""The furnace's matte loss with its prediction band, in wt% Cu of the tapped slag beside what plants report.

**What the settling model represents.** Copper leaves a flash-smelting settler with the slag in three forms
(``../shared/reference/reduced-model.md`` section 3): dissolved in the slag (oxidic and sulfidic; it rises with the
matte grade and the oxygen potential), matte droplets attached to spinels or gas bubbles, and free matte droplets
too small to settle in the slag's residence time. popbal models only the last: the *entrained free matte*, fed
with the preset's droplet-size distribution, coalescing and settling through the slag while it flows to the tap
hole. Its loss, a share of the matte fed, becomes copper in the slag by

    Cu_entrained [wt %] = 100 L m_matte w_Cu / (m_slag + L m_matte)

with L the matte loss [-], m_matte = feed.mass_rate and m_slag = slag.feed_rate [kg/s] and w_Cu the matte's copper
content :data:`MATTE_GRADE`. Plants report the total, 1-2 wt % Cu in flash-smelting slag (:data:`PLANT_SLAG_COPPER`).

**The band** (:func:`loss_band`): popbal over parameter draws of a hierarchical calibration layer (``settler
calibrate --set``; :mod:`analysis.calibration.bands`), each run's loss times the layer's log-normal discrepancy
factor exp(delta z). The furnace has no plume channel (``channel_feed_fraction = 0``), so of the layer's parameters
only the collision efficiency acts; the band is mostly the discrepancy, the model error the layer measured on the
0.2 m boxes, carried to a 1 m, 6 h settler it was never fitted on.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from settler.cases import case_with_overrides

#: Copper content of the matte [-]: 0.60 [chosen] inside the 55-70 wt % of flash-smelting mattes ([paper] section
#: 1, after its ref. 1); :data:`MATTE_GRADE_RANGE` is that range.
MATTE_GRADE = 0.60
MATTE_GRADE_RANGE = (0.55, 0.70)
#: Copper in flash-smelting slag [wt %], dissolved and entrained together: [lit] Khan & Jokilaakso, Processes 10
#: (2022) 784 (smelting slag 1-2 %, converter slag 4-8 %); flash slags up to 2 % against 0.5 % in reverberatory
#: furnaces, 74 % of it sulfidic, [lit] Zivkovic et al., J. Min. Metall. B 45 (2009) 23.
PLANT_SLAG_COPPER = (1.0, 2.0)
#: Keys of the banded trends: the study's axes less the collision efficiency, which the calibration layer sets.
BAND_KEYS = ("slag.temperature", "feed.mean_diameter", "feed.scale_std", "geometry.height", "slag.feed_rate")


def entrained_copper(matte_loss, matte_rate: float, slag_rate: float, grade: float = MATTE_GRADE):
    """Entrained copper in the tapped slag [wt %] (module docstring) from the matte loss [-] (a number or array),
    the matte and slag feed rates [kg/s] and the matte's copper content ``grade`` [-]."""
    lost = np.asarray(matte_loss, dtype=float) * matte_rate
    return 100.0 * lost * grade / (slag_rate + lost)


def _loss(case) -> float:
    """popbal's matte loss [-] of a case: the sweeps' matte_loss (mass_lost / mass_fed at the last output)."""
    import popbal

    from .execution import summarize

    return summarize(popbal.run(popbal.setup(case), progress=False).timeseries)["matte_loss"]


def loss_band(overrides: dict, layer: str | None = None, samples: int = 20, seed: int = 0, base: str = "furnace",
              keys=("collision_efficiency",)) -> dict:
    """The matte loss of preset ``base`` with ``overrides`` under calibration ``layer`` (None: the current layer,
    :data:`analysis.calibration.bands.CURRENT_LAYER`): the layer's draws of the
    [popbal] ``keys`` (default the collision efficiency alone: the furnace keeps its own no-channel zones, which the
    layer's plume closures do not describe) applied to the preset. Returns {"losses": (samples,) each draw's loss
    times its discrepancy factor, "quantiles": their 5/50/95 % [-], "at_estimates": the loss at the layer's mean of
    ``keys``, "copper": the three quantiles as entrained copper [wt %] (:func:`entrained_copper`), "delta": the
    layer's discrepancy, "draws": {key: (samples,)}}."""
    from analysis.calibration.bands import QUANTILES, discrepancy_factors, layer_samples

    draws, delta = layer_samples(layer, samples, seed)
    factors = discrepancy_factors(samples, ["matte_loss"], delta, seed)["matte_loss"]
    losses = np.array([_loss(case_with_overrides(base, {**overrides, **{f"popbal.{k}": float(d[k]) for k in keys}}))
                       for d in draws]) * factors
    means = {f"popbal.{k}": float(np.mean([d[k] for d in draws])) for k in keys}
    case = case_with_overrides(base, {**overrides, **means})
    quantiles = np.quantile(losses, QUANTILES)
    return {"losses": losses, "quantiles": quantiles, "at_estimates": _loss(case), "delta": delta,
            "copper": entrained_copper(quantiles, case.feed.mass_rate, case.slag.feed_rate),
            "draws": {k: np.array([d[k] for d in draws]) for k in keys}}


def banded_trends(base_overrides: dict, axes: dict, points: int, layer: str | None = None, samples: int = 10,
                  progress=None) -> pd.DataFrame:
    """One-at-a-time trends with bands: for each key of :data:`BAND_KEYS` in ``axes`` ({key: (low, high, ...)}),
    ``points`` values over its range (linear), the others at ``base_overrides``; per point :func:`loss_band` with the
    same draws and discrepancy factors at every point (one seed), so that a curve's shape carries the parameters'
    uncertainty and its level the discrepancy as well. Rows: key, value, loss_low, loss_median, loss_high,
    loss_at_estimates [-], copper_low, copper_median, copper_high [wt %], losses (the draws' losses, an array).
    ``progress``: a callable (done, total) or None."""
    rows, total, done = [], sum(points for k in BAND_KEYS if k in axes), 0
    for key in (k for k in BAND_KEYS if k in axes):
        low, high = axes[key][:2]
        for value in np.linspace(low, high, points):
            band = loss_band({**base_overrides, key: float(value)}, layer, samples)
            q, c = band["quantiles"], band["copper"]
            rows.append({"key": key, "value": float(value), "loss_low": q[0], "loss_median": q[1], "loss_high": q[2],
                         "loss_at_estimates": band["at_estimates"], "copper_low": c[0], "copper_median": c[1],
                         "copper_high": c[2], "losses": band["losses"]})
            done += 1
            if progress is not None:
                progress(done, total)
    return pd.DataFrame(rows)


def trend_ratios(table: pd.DataFrame) -> pd.DataFrame:
    """Per key of a :func:`banded_trends` table, the loss at the high end of its range over the loss at the low
    end, draw by draw (the discrepancy factor, common to both ends, cancels): the 5/50/95 % of that ratio and
    ``resolved``, whether its 90 % interval excludes 1: the direction is resolved *under a common discrepancy*,
    i.e. if the model's error is the same factor all along the curve (what is left is the parameters' spread).
    A loss of 0 at either end leaves the ratio undefined: NaN quantiles and ``resolved`` False."""
    from analysis.calibration.bands import QUANTILES

    rows = []
    for key, group in table.groupby("key", sort=False):
        group = group.sort_values("value")
        first, last = np.asarray(group["losses"].iloc[0]), np.asarray(group["losses"].iloc[-1])
        defined = (first > 0.0) & (last > 0.0) & np.isfinite(first) & np.isfinite(last)
        low, median, high = (np.quantile(last / first, QUANTILES) if defined.all() else (np.nan,) * 3)
        rows.append({"key": key, "low": float(group["value"].iloc[0]), "high": float(group["value"].iloc[-1]),
                     "ratio_low": low, "ratio_median": median, "ratio_high": high,
                     "resolved": bool(math.isfinite(low) and (high < 1.0 or low > 1.0))})
    return pd.DataFrame(rows)


def plot_banded_trends(table: pd.DataFrame, layer: str):
    """Entrained copper [wt %] against each key, the 90 % band shaded and the loss at the layer's estimates drawn,
    beside the plants' 1-2 wt % (hatched); log axis, since the two lie decades apart."""
    from matplotlib.figure import Figure

    from .results import axis_scale

    keys = list(dict.fromkeys(table["key"]))
    fig = Figure(figsize=(12, 6.5), layout="constrained")
    axes = np.atleast_1d(fig.subplots(2, math.ceil(len(keys) / 2))).ravel()
    for ax, key in zip(axes, keys):
        rows = table[table["key"] == key].sort_values("value")
        factor, label = axis_scale(key, rows["value"])
        x = rows["value"] * factor
        ax.fill_between(x, rows["copper_low"], rows["copper_high"], alpha=0.3, linewidth=0,
                        label=f"90 % band ({layer})")
        ax.plot(x, rows["copper_median"], "o-", ms=3, label="band median")
        ax.axhspan(*PLANT_SLAG_COPPER, facecolor="none", edgecolor="grey", hatch="//", linewidth=0,
                   label="plant slag, all Cu forms")
        ax.set_yscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("entrained Cu in slag [wt %]")
        ax.grid(alpha=0.3, which="both")
    for ax in axes[len(keys):]:
        ax.set_visible(False)
    axes[0].legend(fontsize="small")
    fig.suptitle(f"furnace: copper entrained as free matte droplets (popbal, calibration {layer!r}) against the "
                 "1-2 wt % Cu of flash-smelting slags")
    return fig
