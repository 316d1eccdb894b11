# %% [markdown]
# # Matte-loss trends: what changes the matte lost with the slag at furnace scale
#
# A process metallurgist asks how much matte leaves with the slag, and what changes it. This report runs the
# furnace study of `analysis.sweep.furnace_study` with the reduced model (`popbal`, horizontal plug flow of the slag
# through a full-size settler: 1 m of slag, a 6 h residence at the preset's throughput) and shows
#
# * the **one-at-a-time trends**: the matte loss (matte that leaves with the slag at the tap hole over the matte fed,
#   in %) against each key of the study, the others at the study's baseline;
# * the **sensitivity ranking** over the whole box of keys at once: Morris mu* and, in the full study, Sobol total
#   indices ST, both of log10 of the loss (the loss spans several decades over the box, so the ranking is one of
#   factors, not of absolute changes, which only the few largest losses would set);
# * what the ranking means for operation, and what the model cannot say.
#
# Every point is a resumable task in `<out>/points/<hash>/`: rendering again re-uses the finished points, so a
# second render of the full study takes seconds. The study writes `trends.png`, `ranking.csv`, `study.json` and,
# per sweep, `sweep.csv` / `sweep.nc` (and `sensitivity.csv` / `.png` for the global designs) into `<out>`.
#
# `quick = True` runs 3 values per key, Morris with 2 trajectories and no Sobol design, at a coarser resolution (20
# cells, 120 s steps) in this process: about 10 s, to check that the study and this report run. **Its numbers are
# not results**: 2 Morris trajectories rank the keys by chance as much as by effect (see the confidence
# half-widths). `quick = False` runs 7 values per key, Morris with 20 trajectories and Sobol with N = 64 (about ten
# minutes on 2 cores).
#
# Render: `settler report trends --out runs/reports/trends --timeout 1800` (the study's cell runs longer than the
# default per-cell timeout of 600 s on 2 cores; add `--param workers=4` on a larger machine, `--param
# out=/scratch/furnace_study` to keep the points elsewhere).

# %% tags=["parameters"]
quick = False
# folder of the study (its sweep points, tables and figures); empty: furnace_study/ in the report's folder
out = ""
# worker processes of the dask LocalCluster; None: furnace_study's default (this process when quick, else one per
# CPU); 0: in this process without dask
workers = None

# %%
import math
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
from IPython.display import Markdown, display

from analysis import sweep
from analysis.report import show
import popbal
from settler.cases import calibration_path, case_with_overrides

folder = Path(out) if out else Path("furnace_study")
started = time.perf_counter()
study = sweep.furnace_study(folder, quick=quick, workers=workers)
wall = time.perf_counter() - started
runs = [*study["trends"].values(), *(study[d] for d in ("sobol", "morris") if study[d] is not None)]
points = sum(len(r.table) for r in runs)
ran = sum(r.ran for r in runs)
failed = sum(r.failed for r in runs)
print(f"furnace study in {folder.resolve()}: {points} design points ({ran} run now, the others read back), "
      f"{failed} failed, {wall:.1f} s wall" + (f", {wall / ran:.2f} s per point run" if ran else ""))

# %% [markdown]
# ## The baseline and the study's box
#
# The furnace preset with the study's overrides (`analysis.sweep.FURNACE_BASE`: a truncated-normal feed of mean
# 200 um matched to the preset's size table, each run ending at its own residence time), and the range of each key
# with its source (`analysis.sweep.FURNACE_AXES`).

# %%
base = case_with_overrides("furnace", {**sweep.FURNACE_BASE, **(sweep.FURNACE_QUICK if quick else {})})


def value(key: str) -> float:
    """The baseline's value of a case key 'section.key' (SI units)."""
    section, name = key.split(".")
    return float(getattr(getattr(base, section), name))


print(f"baseline: slag viscosity {base.slag_viscosity:.3g} Pa s at {base.slag.temperature:.2f} K, "
      f"slag residence time {popbal.setup(base).residence_time / 3600:.2f} h, slag depth {base.geometry.height:g} m, "
      f"feed mean diameter {base.feed.mean_diameter * 1e6:.0f} um (scale std {base.feed.scale_std:g}), "
      f"collision efficiency {base.popbal.collision_efficiency:g}")
axes = pd.DataFrame([{"key": key, "low": low, "baseline": value(key), "high": high, "source": source}
                     for key, (low, high, source) in sweep.FURNACE_AXES.items()])
axes.style.format({"low": "{:.4g}", "baseline": "{:.4g}", "high": "{:.4g}"}).hide(axis="index")

# %% [markdown]
# ## One key at a time
#
# Matte loss [%] against each key, the others at the baseline (a log axis where the loss spans more than two
# decades). The table gives, per key, the loss at the ends of its range and the factor between the largest and the
# smallest loss; the slag viscosity and residence time of each point show how temperature and throughput act.

# %%
show(sweep.plot_study(study["trends"]))

# %%
rows = []
for key, trend in study["trends"].items():
    done = trend.table[trend.table["status"] == "done"].sort_values(key)
    loss = done["matte_loss"].to_numpy(float)
    rows.append({"key": key, "low": done[key].iloc[0], "loss at low [%]": 100 * loss[0], "high": done[key].iloc[-1],
                 "loss at high [%]": 100 * loss[-1],
                 "max / min loss": loss.max() / loss.min() if loss.min() > 0 else math.inf,
                 "residence [h]": "{:.2f}-{:.2f}".format(*done["residence_time"].agg(["min", "max"]) / 3600),
                 "viscosity [Pa s]": f"{done['slag_viscosity'].min():.3g}-{done['slag_viscosity'].max():.3g}"})
trend_table = pd.DataFrame(rows)
trend_table.style.format({"low": "{:.4g}", "high": "{:.4g}", "loss at low [%]": "{:.3g}",
                          "loss at high [%]": "{:.3g}", "max / min loss": "{:.3g}"}).hide(axis="index")

# %% [markdown]
# ## Sensitivity ranking over the whole box
#
# `ranking.csv`: one row per key, ordered by Morris mu* of log10 loss (the mean absolute elementary effect over the
# box, in decades of loss per the key's full range, with its 95 % bootstrap half-width; sigma, the spread of the
# effects, is large where a key's effect depends on the others), with Sobol's total index ST of log10 loss
# (the share of the variance of log10 loss that the key takes part in, interactions included) where the full study
# ran it. The indices of the loss itself are in the file too; they are set by the few points where the loss is
# largest.

# %%
ranking = study["ranking"]
shown = ["parameter"] + [c for c in ranking.columns if "log10" in c]
ranking[shown].style.format({c: "{:.3g}" for c in shown[1:]}, na_rep="–").hide(axis="index")

# %%
for design in ("morris", "sobol"):
    if study[design] is not None and study[design].sensitivity is not None:
        frame = study[design].sensitivity
        show(sweep.plot_sensitivity(frame[frame["metric"].isin(["log10_matte_loss", "matte_loss"])], design,
                                    "furnace"))
    elif design == "sobol":
        print("no Sobol design in quick mode (it needs N (D + 2) = 512 points at N = 64)")


# %%
def morris_row(key: str) -> pd.Series:
    """Morris indices of log10 loss for one key (mu*, its half-width, mu with its sign, sigma)."""
    frame = study["morris"].sensitivity
    return frame[(frame["metric"] == "log10_matte_loss") & (frame["parameter"] == key)].iloc[0]


def sentence(rank: int, key: str) -> str:
    """One line of the ranking in words: direction and size of the one-at-a-time change, Morris mu* and ST."""
    trend = trend_table.set_index("key").loc[key]
    way = "lowers" if trend["loss at high [%]"] < trend["loss at low [%]"] else "raises"
    morris = morris_row(key)
    text = (f"{rank}. **{key}**: raising it from {trend['low']:.4g} to {trend['high']:.4g} {way} the loss from "
            f"{trend['loss at low [%]']:.3g} % to {trend['loss at high [%]']:.3g} % (one at a time); Morris mu* "
            f"{morris['mu_star']:.2f} +- {morris['mu_star_conf']:.2f} decades of loss per the key's full range")
    if morris["sigma"] > 0.5 * morris["mu_star"]:
        text += f", sigma {morris['sigma']:.2f}: its effect depends on the other keys"
    column = "sobol_log10_matte_loss_ST"
    if column in ranking and np.isfinite(ranking.set_index("parameter").loc[key, column]):
        row = ranking.set_index("parameter").loc[key]
        text += f"; Sobol ST {row[column]:.2f} +- {row[column + '_conf']:.2f}"
    return text + "."


order = list(ranking["parameter"])
overlaps = [f"{a} and {b}" for a, b in zip(order, order[1:])
            if morris_row(a)["mu_star"] - morris_row(a)["mu_star_conf"]
            < morris_row(b)["mu_star"] + morris_row(b)["mu_star_conf"]]
lines = [sentence(rank, key) for rank, key in enumerate(order, start=1)]
if overlaps:
    lines.append("\nNeighbours in the ranking whose Morris confidence intervals overlap, so the data do not order "
                 "them: " + "; ".join(overlaps) + ".")
if quick:
    lines.append("\n**Quick mode: 2 Morris trajectories at a coarse resolution. This ordering is not a result.**")
display(Markdown("\n".join(lines)))

# %% [markdown]
# ## Why the slag depth matters little: a check without coalescence
#
# In plug flow, a droplet settling at velocity v is caught if v t_res >= its height above the floor; at a fixed slag
# feed the residence time t_res grows in proportion to the depth H, so for droplets that keep their size the caught
# fraction v t_res / H does not depend on H. What the depth trend above shows must then come from a process that does
# not scale with H. The same depth trend with coalescence switched off (`coalescence.enabled = false`) tests that.

# %%
depth = sweep.sweep(base, [f"geometry.height={sweep.FURNACE_AXES['geometry.height'][0]}:"
                           f"{sweep.FURNACE_AXES['geometry.height'][1]}:{3 if quick else sweep.TREND_POINTS}",
                           "coalescence.enabled=false"], "grid", out=folder / "depth_without_coalescence",
                    points_dir=folder / sweep.POINTS, workers=0, progress=False, plots=False)
with_coalescence = study["trends"]["geometry.height"].table.set_index("geometry.height")["matte_loss"]
check = depth.table.set_index("geometry.height")[["matte_loss"]].rename(columns={"matte_loss": "no coalescence"})
check["with coalescence (trend above)"] = with_coalescence.reindex(check.index)
(100 * check).style.format("{:.3g}", na_rep="–").format_index("{:.3g}").set_caption(
    "matte loss [%] against slag depth [m]")

# %%
spread = check["no coalescence"].max() / check["no coalescence"].min()
print(f"without coalescence the loss changes by a factor {spread:.3f} over depths {check.index.min():g}-"
      f"{check.index.max():g} m; with it, by {with_coalescence.max() / with_coalescence.min():.3g}")

# %% [markdown]
# ## What the ranking means in the furnace
#
# In this model a droplet is lost when it has not settled through the slag layer by the time its slag reaches the
# tap hole: the loss is the part of the feed whose settling time exceeds the slag's residence time. Every key acts
# through one side of that balance, which is why the loss changes by factors, and why a ranking of log10 loss is
# the useful one.
#
# * **Droplet size** acts through the settling velocity, about d^2 / viscosity for the Stokes droplets that make the
#   loss, so a key that shifts the size distribution (the feed's mean size; the collision efficiency, through
#   coalescence, which grows droplets while they settle) moves the loss by the largest factors. The feed size is set
#   upstream, in the reaction shaft, not in the settler.
# * **Slag temperature** acts through the viscosity (Arrhenius, 250 kJ/mol in the property set): over the study's
#   100 K the viscosity changes by a factor of about 3.5, and so does every droplet's velocity.
# * **Throughput** (slag feed at a fixed bath) sets the residence time: halving it doubles the time droplets have to
#   settle, and to coalesce.
# * **Slag depth**: a deeper bath is longer to settle through but, at a fixed slag feed, holds the slag longer in
#   proportion, so for droplets of fixed size the two cancel (the check above); what remains is coalescence, which
#   has longer to grow the droplets in a deeper bath.
#
# Of these, the slag temperature, the throughput and, within limits, the bath depth are what an operator sets; their
# costs (energy and refractory wear, production) are outside this model.
#
# **What the model cannot settle.** The collision efficiency is the least known of the keys (below: its value and
# standard error in the calibration layer, fitted to the full engine on the 0.2 m boxes, and the baseline's loss at
# that value), and the furnace preset does not apply that layer (the fit does not predict the deep reference case,
# and the furnace has no plume channel). Its row of the ranking is therefore a statement about the
# model's uncertainty as much as about the furnace: if coalescence in the dilute furnace slag is weak, the loss is
# decades above the baseline (the trend's first point is no coalescence at all). The absolute losses also rest on
# the plug-flow column (no recirculation, no stirring by gas or by the feed, no entrainment at the tap hole) and on
# the feed distribution; the ranking of factors is the more robust output. The loss here is a fraction of the matte
# entrained in the slag, not the plant's copper in slag, which also holds dissolved copper.

# %%
layer = tomllib.loads(calibration_path("paper").read_text())
efficiency = layer["popbal"]["collision_efficiency"]
error = layer["provenance"]["standard_errors"]["collision_efficiency"]
low, high, _ = sweep.FURNACE_AXES["popbal.collision_efficiency"]
print(f"calibration layer 'paper': collision_efficiency = {efficiency:.3g} +- {error:.3g} (standard error), fitted "
      f"on {', '.join(layer['provenance']['fitted_cases'])}; the study's range {low:g}-{high:g}, baseline "
      f"{base.popbal.collision_efficiency:g}")
# the baseline furnace at the layer's value (a coefficient fitted on 0.2 m boxes, applied here as it is)
at_layer = sweep.sweep(base, [f"popbal.collision_efficiency={efficiency!r},{base.popbal.collision_efficiency!r}"],
                       "grid", out=folder / "layer_efficiency", points_dir=folder / sweep.POINTS, workers=0,
                       progress=False, plots=False).table.set_index("popbal.collision_efficiency")["matte_loss"]
calibrated_loss, baseline_loss = at_layer.loc[efficiency], at_layer.loc[base.popbal.collision_efficiency]
print(f"baseline loss at the layer's collision efficiency {efficiency:.3g}: {100 * calibrated_loss:.3g} %; at the "
      f"study's baseline {base.popbal.collision_efficiency:g}: {100 * baseline_loss:.3g} % (factor "
      f"{calibrated_loss / baseline_loss:.3g})")

# %% [markdown]
# ## The furnace loss with its band, beside what plants see
#
# Flash-smelting slags carry about 1-2 wt % Cu (Khan & Jokilaakso, Processes 10 (2022) 784; the Boliden Rönnskär
# settling trials, Metals 11 (2021), found it rising with temperature and falling with CaO, both more than with
# settling time, and associated with spinels and gas bubbles). That copper is dissolved in the slag, attached to
# spinels and bubbles, or entrained as free matte droplets. **The settling model represents only the last**: free
# droplets fed with the preset's size distribution (Jylhä, Khan & Jokilaakso, Processes 8 (2020) 485, Table 2, fines
# included: 6 % of the mass at 50 µm, 2 % at 60 µm), coalescing and settling while the slag flows to the tap hole.
# Its loss is converted to copper in the tapped slag with a matte of 60 wt % Cu (the seed paper's 55-70 %):
# Cu = 100 L m_matte w_Cu / (m_slag + L m_matte) (`analysis.sweep.furnace_band`).
#
# The band is the current hierarchical calibration's (`analysis.calibration.bands.CURRENT_LAYER`, written by
# `settler calibrate --set`): the collision efficiency drawn from its kernel-run estimate and standard error (the
# furnace has no plume channel, so the layer's plume closures do not enter), and each run's loss times the layer's
# log-normal model discrepancy exp(delta z), the error it measured on the 0.2 m boxes. **The furnace lies far outside what the layer was fitted
# on** (1 m and 6 h against 0.2-0.5 m and a minute): the band says what the calibration knows, not what the
# furnace does.

# %%
from analysis.calibration.bands import CURRENT_LAYER
from analysis.sweep import furnace_band

band_layer = CURRENT_LAYER
band_samples = 5 if quick else 20
resolution = sweep.FURNACE_QUICK if quick else {}
preset_band = furnace_band.loss_band(resolution, band_layer, band_samples)
preset = case_with_overrides("furnace", resolution)
no_coalescence = furnace_band._loss(case_with_overrides("furnace", {**resolution, "popbal.collision_efficiency": 0.0}))
rows = [("at the layer (median and 90 % band)", *preset_band["quantiles"]),
        ("no coalescence (E = 0, no band)", no_coalescence, no_coalescence, no_coalescence)]
plant_table = pd.DataFrame(
    [{"furnace preset (cited feed table)": name, "matte loss [%]": f"{100 * mid:.3g} ({100 * lo:.3g}-{100 * hi:.3g})",
      "entrained Cu [wt %]": "{:.2g} ({:.2g}-{:.2g})".format(
          *furnace_band.entrained_copper([mid, lo, hi], preset.feed.mass_rate, preset.slag.feed_rate))}
     for name, mid, lo, hi in [(r[0], r[2], r[1], r[3]) for r in rows]]
    + [{"furnace preset (cited feed table)": "plant slags (all forms of Cu)", "matte loss [%]": "–",
        "entrained Cu [wt %]": "{:g}-{:g}".format(*furnace_band.PLANT_SLAG_COPPER)}])
print(f"{band_samples} popbal runs; collision efficiency drawn {preset_band['draws']['collision_efficiency'].min():.3g}"
      f"-{preset_band['draws']['collision_efficiency'].max():.3g}; discrepancy delta {preset_band['delta']:.3g}; "
      f"matte {100 * furnace_band.MATTE_GRADE:g} wt % Cu")
plant_table.style.hide(axis="index")

# %%
gap = furnace_band.PLANT_SLAG_COPPER[0] / furnace_band.entrained_copper(
    preset_band["quantiles"][2], preset.feed.mass_rate, preset.slag.feed_rate)
ceiling = furnace_band.entrained_copper(no_coalescence, preset.feed.mass_rate, preset.slag.feed_rate)
display(Markdown(
    f"Even the top of the band lies a factor {gap:.3g} below the plants' lower figure of "
    f"{furnace_band.PLANT_SLAG_COPPER[0]:g} wt % Cu; with no coalescence at all the free droplets would carry "
    f"{ceiling:.2g} wt % Cu, still below it. In this model free settling droplets are a small part of the copper "
    "in flash-smelting slag: the rest is dissolved copper and copper attached to spinels and bubbles, which the "
    "model does not represent, in line with the Rönnskär trials, where temperature and slag chemistry moved the slag's "
    "copper more than settling time did."))

# %% [markdown]
# ### The loss trends with their bands
#
# The one-at-a-time trends again, each point the band of `band_samples` popbal runs (5 keys: the collision
# efficiency is now the layer's, not an axis). Every point uses the same draws and discrepancy factors, so the
# discrepancy moves a whole curve up or down together and the *ratio* of the loss at the two ends of a key's range
# carries only the parameters' uncertainty: a trend is **resolved under a common discrepancy** where the 90 %
# interval of that ratio excludes 1, an assumption (the model's error the same factor along a curve) rather than a
# measurement; with the collision efficiency known to 2 % almost every trend passes it. The curves start from the
# study's baseline feed (`analysis.sweep.FURNACE_BASE`: a truncated normal of mean 200 µm, whose mean and width are
# axes), not the preset's cited table above, so their levels are not those of the table. Full mode: 5 values per key and 10 runs each (about 15
# minutes on 2 cores at the preset's resolution); quick: 3 values and 3 runs at the coarse resolution.

# %%
trend_points, trend_samples = (3, 3) if quick else (5, 10)
banded = furnace_band.banded_trends({**sweep.FURNACE_BASE, **resolution}, sweep.FURNACE_AXES, trend_points,
                                    band_layer, trend_samples)
show(furnace_band.plot_banded_trends(banded, band_layer))
ratios = furnace_band.trend_ratios(banded)
ratios.style.format({"low": "{:.4g}", "high": "{:.4g}", "ratio_low": "{:.3g}", "ratio_median": "{:.3g}",
                     "ratio_high": "{:.3g}"}).hide(axis="index").set_caption(
    "loss at the high end of each key's range over the loss at its low end (5 %, 50 %, 95 % of the draws)")

# %%
resolved = [r.key for r in ratios.itertuples() if r.resolved]
unresolved = [r.key for r in ratios.itertuples() if not r.resolved]
display(Markdown(
    f"Resolved under a common discrepancy (the ratio's 90 % interval excludes 1): {', '.join(resolved) or 'none'}; "
    "not resolved: "
    f"{', '.join(unresolved) or 'none'}. The absolute level of every curve is uncertain by the band's factor "
    f"{preset_band['quantiles'][2] / preset_band['quantiles'][0]:.3g} between its ends; the curves' directions are "
    "as certain as the collision efficiency's kernel-run estimate, which the furnace's dilute slag never tested."
    + ("\n\n**Quick mode: 3 runs per point at a coarse resolution; these bands are not results.**" if quick else "")))
