# %% [markdown]
# # Calibration: the reduced model fitted to the full engine's reference runs, and the held-out prediction
#
# `popbal`'s closures (collision efficiency, channel and feed-layer coefficients, ...) are chosen numbers until they
# are fitted to the full engine (`fulldem`). `settler calibrate` (`analysis/calibrate.py`) fits them to the stored
# reference runs in `data/reference/<case>/` by weighted least squares and writes the result, with its provenance,
# as a calibration layer (`data/calibration/paper.toml`) that the `simple` preset applies. This report shows
#
# 1. the fitted parameters with their standard errors (from the Jacobian at the optimum) and correlations, and which
#    of them the data do not determine;
# 2. the residuals per column: `popbal` run with the fitted values on each reference case (the fitted ones and the
#    held-out one) against the full run, block by block over the steady window, in units of the full run's own
#    scatter sigma (`analysis.calibrate`), and the time series side by side (`analysis.compare`);
# 3. the errors of the steady-window means against the targets, <= 10 % on the fitted cases and <= 20 % on
#    the held-out case for droplet count, mean diameter, settled fraction and channel velocity, stated plainly,
#    misses included.
#
# By default (`refit = false`) the report shows the **committed calibration**: the estimates, standard errors,
# correlations and recorded errors are read from the layer's provenance, and the reduced model is run again with
# the layer's values (at the resolution of the reference cases, as in the fit) to draw the residuals and to check
# that the recorded errors are reproduced by the code as it is now. `refit = true` runs the fit again
# (`analysis.calibrate.calibrate`, by default on the layer's cases, columns and held-fixed keys, starting from its
# estimates, at most `max_evaluations` model runs of about a second each on 2 cores) and shows that fit instead,
# beside the committed one; it writes `refit/` (fit.json, summary.txt, comparison.csv/png) and `<layer>_refit.toml`
# into the report's folder, never into the checkout.
#
# `quick = true` shows the same committed calibration and the same runs over the same steady windows (a few seconds
# of model time): the reduced runs are cheap enough that a shorter or coarser run would only show other numbers. It
# leaves out the runs with the uncalibrated closures and the refit (`refit = true` is refused with `quick = true`,
# since a fit takes minutes).
#
# Render: `settler report calibration --out runs/reports/calibration` (add `--param refit=true --timeout 1800` to
# fit again).

# %% tags=["parameters"]
quick = False
# fit again with analysis.calibrate.calibrate instead of reading the committed layer
refit = False
# calibration layer shown (data/calibration/<layer>.toml)
layer = "paper"
# refit only: reference cases fitted (empty: the layer's), the case held out (empty: the layer's; "none": none),
# [popbal] keys fitted (empty: the layer's), budget of model runs
cases = []
holdout = ""
parameters = []
max_evaluations = 60
# folder of the stored reference runs (empty: the data folder's reference/)
references = ""

# %%
import math
import time
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
from IPython.display import Markdown, display
from matplotlib.figure import Figure

import popbal
from analysis import calibrate as cal
from analysis.compare import Window, compare, comparison_figure
from analysis.report import show
from settler.cases import calibration_path, list_presets, load_case
from settler.paths import DATA_DIR

if quick and refit:
    raise ValueError("refit = true with quick = true: allowed: quick = false for a refit (a fit takes minutes)")
root = Path(references) if references else DATA_DIR / "reference"
layer_path = calibration_path(layer)
layer_text = layer_path.read_text()
stored = tomllib.loads(layer_text)
provenance = stored["provenance"]
fitted_keys = list(provenance["correlation"])  # the fitted keys, in the order of the correlation matrix
committed = {
    "parameters": fitted_keys,
    "estimates": {name: stored["popbal"][name] for name in fitted_keys},
    # [popbal] keys of the layer held fixed during the fit (the closure's form): applied with the estimates
    "fixed": {f"popbal.{name}": value for name, value in stored["popbal"].items() if name not in fitted_keys},
    "standard_errors": dict(provenance["standard_errors"]),
    "correlation": np.array([provenance["correlation"][name] for name in fitted_keys], dtype=float),
    "cases": list(provenance["fitted_cases"]),
    "holdout": provenance["holdout_case"] or None,
    "columns": list(provenance.get("columns", cal.COLUMNS)),
    "windows": {case: tuple(provenance[case]["steady_window"]) for case in
                [*provenance["fitted_cases"], *([provenance["holdout_case"]] if provenance["holdout_case"] else [])]},
}
print(f"calibration layer {layer_path}: fitted on {', '.join(committed['cases'])}, held out "
      f"{committed['holdout'] or 'none'}; {provenance['date']}, code {provenance['code_commit'][:10]}"
      f"{' (tree dirty)' if provenance['code_tree_dirty'] else ''}")
print(f"command: {provenance['command']}")
print(f"fit status: {provenance['status']}; {provenance['residual_count']} residuals of "
      f"{', '.join(committed['columns'])}, rms {provenance['residual_rms']:.3g} sigma")
print("held fixed: " + (", ".join(f"{k} = {v!r}" for k, v in committed["fixed"].items()) or "nothing"))
presets = [name for name in list_presets() if load_case(name).case.calibration == layer]
print(f"presets that apply this layer: {', '.join(presets) or 'none'}")
notes = [line[2:] for line in layer_text.split("\n[", 1)[0].splitlines() if line.startswith("# ")]
display(Markdown("The layer's own notes:\n\n> " + "\n> ".join(notes)))

# %%
if refit:
    started = time.perf_counter()
    held_out = committed["holdout"] if holdout == "" else None if holdout == "none" else holdout
    result = cal.calibrate(cases=cases or committed["cases"], holdout=held_out,
                           parameters=parameters or committed["parameters"], columns=committed["columns"],
                           reference_dir=root, start=committed["estimates"], fixed=committed["fixed"],
                           max_evaluations=max_evaluations, progress=True)
    Path("refit").mkdir(exist_ok=True)
    cal.write_outputs(result, Path("refit"))
    written = cal.write_layer(result, f"{layer}_refit.toml", f"settler report calibration --param refit=true "
                                                            f"(cases {','.join(result.cases)}, holdout {held_out})")
    print(f"refit in {time.perf_counter() - started:.0f} s: {result.evaluations} model runs, {result.status}; "
          f"wrote refit/ and {written}")
    print(result.summary())
    fit = {"parameters": result.parameters, "estimates": result.estimates, "fixed": committed["fixed"],
           "standard_errors": result.standard_errors, "correlation": result.correlation, "cases": result.cases,
           "holdout": result.holdout, "columns": result.columns, "windows": result.windows}
else:
    fit = committed

# %% [markdown]
# ## Fitted parameters
#
# Standard errors: cov = s^2 (J^T J)^-1 with s^2 the residuals' mean square (m residuals, p parameters, m - p
# degrees of freedom), J the Jacobian of the weighted residuals at the optimum. A parameter is flagged as **not
# determined** by the data when its standard error exceeds its estimate, its estimate lies on a bound, or it
# correlates beyond +-0.95 with another (`analysis.calibrate.flag_undetermined`, applied here to the numbers shown);
# the fit also checks the singular values of the Jacobian, which the layer records in its `undetermined` line.

# %%
low, high = cal._bounds(fit["parameters"], fit["fixed"])  # the bounds of the fit (they depend on the form)
x = np.array([fit["estimates"][name] for name in fit["parameters"]], dtype=float)
errors = np.array([fit["standard_errors"][name] for name in fit["parameters"]], dtype=float)
flags = cal.flag_undetermined(fit["parameters"], x, low, high, errors, fit["correlation"], np.array([]))
table = pd.DataFrame({"estimate": x, "standard error": errors, "relative": errors / np.abs(x),
                      "unit": [cal.PARAMETERS[name][2] for name in fit["parameters"]],
                      "bounds": [f"{a:g} - {b:g}" for a, b in zip(low, high)],
                      "determined?": [("no: " + flags[name]) if name in flags else "yes"
                                      for name in fit["parameters"]]}, index=fit["parameters"])
if refit:
    table.insert(2, "committed", [committed["estimates"].get(name, math.nan) for name in fit["parameters"]])
    table.insert(3, "committed s.e.", [committed["standard_errors"].get(name, math.nan)
                                       for name in fit["parameters"]])
undetermined = [name for name in fit["parameters"] if name in flags]
print(f"determined by the data: {', '.join(n for n in fit['parameters'] if n not in flags) or 'none'}")
print(f"not determined: {', '.join(undetermined) or 'none'}")
if not refit:
    print(f"recorded in the layer: {provenance['undetermined'] or 'none'}")
table.style.format({"estimate": "{:.4g}", "standard error": "{:.3g}", "relative": "{:.0%}", "committed": "{:.4g}",
                    "committed s.e.": "{:.3g}"})


# %%
def correlation_figure(names, correlation) -> Figure:
    """The correlation matrix of the estimates, coloured from -1 to 1, each entry written in its cell."""
    fig = Figure(figsize=(1.0 * len(names) + 3.0, 0.8 * len(names) + 1.5), layout="constrained")
    ax = fig.subplots()
    image = ax.imshow(correlation, cmap="RdBu_r", vmin=-1.0, vmax=1.0)
    for (i, j), value in np.ndenumerate(correlation):
        ax.text(j, i, f"{value:.2f}", ha="center", va="center", fontsize=8,
                color="white" if abs(value) > 0.7 else "black")
    ax.set_xticks(range(len(names)), names, rotation=40, ha="right", fontsize=8)
    ax.set_yticks(range(len(names)), names, fontsize=8)
    fig.colorbar(image, ax=ax, label="correlation of the estimates")
    ax.set_title("correlation of the fitted parameters (|r| > 0.95: not separable)", fontsize=9)
    return fig


show(correlation_figure(fit["parameters"], fit["correlation"]))

# %% [markdown]
# ## The reduced model with the fitted values, against each reference run
#
# `popbal` on each reference run's own resolved case (`data/reference/<case>/case.toml`) with the fitted values
# over the whole span of the run, saved into `reduced/<case>/` beside this report; the comparison is over the
# steady window of the calibration (shaded; the errors of its window means are written on each panel).

# %%
OUTPUT_INTERVAL = 0.5  # [s] output interval of the reduced runs, that of the fit (analysis.calibrate.run_reduced)


def reduced_run(reference: cal.Reference, overrides: dict, folder: Path) -> tuple[Path, float]:
    """popbal on the reference's case with the case ``overrides`` ({section.key: value}) to its end time [s], saved
    into ``folder``; returns the folder and the wall time [s]. As analysis.calibrate.run_reduced runs it."""
    overrides = {**overrides, "popbal.end_time": reference.end_time, "popbal.output_interval": OUTPUT_INTERVAL}
    result = popbal.run(popbal.setup(load_case(reference.case_file, overrides)), progress=False)
    return result.save(folder), result.wall_time


calibrated = {**{f"popbal.{name}": float(value) for name, value in fit["estimates"].items()}, **fit["fixed"]}


roles = {case: "fitted" for case in fit["cases"]}
if fit["holdout"]:
    roles[fit["holdout"]] = "held out"
runs = {}
for case, role in roles.items():
    reference = cal.load_reference(case, root, fit["windows"].get(case))
    folder, wall = reduced_run(reference, calibrated, Path("reduced") / case)
    comparison = compare(reference.folder, folder, [Window("steady", *reference.window)])
    runs[case] = (reference, comparison)
    display(Markdown(f"### {case} ({role}): steady window {reference.window[0]:g}-{reference.window[1]:g} s; "
                     f"reduced run to {reference.end_time:.0f} s in {wall:.1f} s wall (`{folder}`)"))
    show(comparison_figure(comparison))

# %% [markdown]
# ## Residuals per column
#
# Residual of a block = (reduced block mean - full block mean) / sigma, over 1 s blocks of the steady window; sigma
# is the full run's scatter about a straight line over the window, floored at 1 % of its mean (the weights of the
# fit). A model that reproduces the full run to within its own fluctuation has residuals of order 1 without a trend.
# The table gives the root mean square per column; for the fitted cases, the rms over the residuals of the fitted
# columns is what the fit minimised.


# %%
def residual_blocks(reference: cal.Reference, comparison) -> pd.DataFrame:
    """Weighted residuals per 1 s block (rows: block centre [s]) and column [sigma]."""
    reduced = cal.column_frame(comparison.reduced.timeseries)
    blocks = cal.block_means(reduced, reference.window, cal.BLOCK)
    return (blocks - reference.blocks) / reference.sigma


def residual_figure(residuals: dict[str, pd.DataFrame]) -> Figure:
    """One panel per column: the block residuals [sigma] of each case against time [s]."""
    fig = Figure(figsize=(12, 5.5), layout="constrained")
    axes = fig.subplots(2, math.ceil(len(cal.COLUMNS) / 2)).ravel()
    for ax, column in zip(axes, cal.COLUMNS):
        for case, frame in residuals.items():
            ax.plot(frame.index, frame[column], "o-", ms=3, label=f"{case} ({roles[case]})")
        ax.axhspan(-1.0, 1.0, color="0.9", zorder=0)
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_title(column + ("" if column in fit["columns"] else " (not in the fit)"), fontsize=9)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("residual [sigma]")
        ax.set_yscale("symlog", linthresh=3.0)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    for ax in axes[len(cal.COLUMNS):]:
        ax.set_visible(False)
    fig.suptitle("(reduced - full) block means over the steady window, in units of the full run's scatter "
                 "(shaded: +-1 sigma; symmetric log axis beyond 3)")
    return fig


residuals = {case: residual_blocks(reference, comparison) for case, (reference, comparison) in runs.items()}
show(residual_figure(residuals))
rms = pd.DataFrame({case: np.sqrt((frame**2).mean()) for case, frame in residuals.items()}).T
sigma = pd.DataFrame({case: runs[case][0].sigma for case in runs}).T
display(rms.style.format("{:.3g}").set_caption("rms residual per column [sigma]"))
display(sigma.style.format("{:.3g}").set_caption("sigma per column (the column's unit: -, m, -, m/s, m)"))
fitted_residuals = np.concatenate([cal.residuals(runs[c][0], cal.column_frame(runs[c][1].reduced.timeseries),
                                                 fit["columns"]) for c in fit["cases"]])
now = float(np.sqrt(np.mean(fitted_residuals**2)))
print(f"rms over the {fitted_residuals.size} residuals of the fitted case(s): {now:.3g} sigma"
      + ("" if refit else f"; recorded in the layer: {provenance['residual_rms']:.3g} sigma"))

# %% [markdown]
# ## Errors against the targets
#
# Error = mean over the steady window of the reduced run / that of the full run - 1 (`analysis.compare`: the reduced
# run interpolated onto the full run's output times). Targets of the issue: |error| <= 10 % on the fitted cases and
# <= 20 % on the held-out case, for the four target columns (the channel radius carries no target).
# `recorded` is the error the layer's provenance holds (the calibration's own window means over each run's rows),
# to check that the code as it is now reproduces the committed calibration.

# %%
rows = []
for case, (reference, comparison) in runs.items():
    limit = cal.TARGETS["holdout" if roles[case] == "held out" else "fitted"]
    steady = comparison.errors.set_index("column")
    for column in cal.COLUMNS:
        full, reduced = steady.loc[column, "mean_full"], steady.loc[column, "mean_reduced"]
        error = reduced / full - 1.0
        recorded = provenance.get(case, {}).get(f"error_{column}", math.nan) if not refit else math.nan
        target = column in cal.TARGET_COLUMNS
        rows.append({"case": case, "role": roles[case], "column": column, "full": full, "reduced": reduced,
                     "error": error, "recorded": recorded, "target": limit if target else math.nan,
                     "met": ("yes" if abs(error) <= limit else "NO") if target else "(no target)"})
targets = pd.DataFrame(rows)


def highlight(row):
    """Red where a target is missed."""
    return ["color: #b00" if row["met"] == "NO" else "" for _ in row]


(targets.style.apply(highlight, axis=1)
 .format({"full": "{:.4g}", "reduced": "{:.4g}", "error": "{:+.1%}", "recorded": "{:+.1%}", "target": "{:.0%}"},
         na_rep="–").hide(axis="index"))


# %%
def verdict(case: str) -> str:
    """One paragraph: the target columns of a case that meet and miss their target, with the errors."""
    part = targets[(targets["case"] == case) & (targets["met"] != "(no target)")].to_dict("records")
    met = [f"{r['column']} ({r['error']:+.1%})" for r in part if r["met"] == "yes"]
    missed = [f"{r['column']} ({r['error']:+.1%})" for r in part if r["met"] == "NO"]
    text = (f"**{case}** ({roles[case]}, target {part[0]['target']:.0%}): {len(met)} of {len(part)} target columns "
            "within it" + (f": {', '.join(met)}" if met else ""))
    return text + (f". **Missed: {', '.join(missed)}.**" if missed else ".")


lines = [verdict(case) for case in runs]
missed_by_role = {role: bool(((targets["role"] == role) & (targets["met"] == "NO")).any())
                  for role in set(roles.values())}
lines.append("**The issue's targets are " + ("; ".join(f"{'missed' if miss else 'met'} on the {role} case(s)"
                                                        for role, miss in sorted(missed_by_role.items())) + ".**"))
if not refit and "exceeded" in provenance["status"]:
    lines.append(f"The committed fit stopped at its budget of model runs ('{provenance['status']}'), not at a "
                 "converged optimum.")
if not refit:
    drift = (targets["error"] - targets["recorded"]).abs().max()
    lines.append(f"The errors recomputed now differ from those recorded in the layer by at most {drift:.1%} "
                 "(the two window means differ slightly: interpolated onto the full run's times here, each run's own "
                 "rows in the calibration).")
display(Markdown("\n\n".join(lines)))

# %% [markdown]
# ## What the calibration changed
#
# The same runs with the closures each reference's resolved case holds (the chosen values before the calibration,
# `data/reference/<case>/case.toml`), against the calibrated ones: signed errors of the steady-window means. Left
# out when `quick = true`.


# %%
def signed_errors(comparison) -> pd.Series:
    """column -> mean_reduced / mean_full - 1 [-] over the comparison's steady window."""
    steady = comparison.errors.set_index("column")
    return steady["mean_reduced"] / steady["mean_full"] - 1.0


if quick:
    print("quick mode: the runs with the uncalibrated closures are left out (quick = false shows them)")
else:
    changes = []
    for case, (reference, comparison) in runs.items():
        folder, _ = reduced_run(reference, {}, Path("uncalibrated") / case)
        before = signed_errors(compare(reference.folder, folder, [Window("steady", *reference.window)]))
        after = signed_errors(comparison)
        changes += [{"case": case, "role": roles[case], "column": column, "uncalibrated": before[column],
                     "calibrated": after[column]} for column in cal.COLUMNS]
    display(pd.DataFrame(changes).style.format({"uncalibrated": "{:+.1%}", "calibrated": "{:+.1%}"}, na_rep="–")
            .hide(axis="index"))

# %% [markdown]
# ## Reading the result
#
# What the numbers above say, in words: where the calibrated model meets the targets, what the held-out case
# shows about the closure's form, which parameters the data do not separate, and what the calibration changed.

# %%
def listing(items) -> str:
    """'a, b and c' ('none' for no items)."""
    items = list(items)
    return "none" if not items else items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def missed(case: str) -> list[str]:
    """The target columns of a case that miss their target."""
    part = targets[(targets["case"] == case) & (targets["met"] == "NO")]
    return list(part["column"])


said = []
fitted_misses = {case: missed(case) for case in fit["cases"]}
if not any(fitted_misses.values()):
    said.append(f"**Fitted cases.** On {listing(fit['cases'])} the calibrated model meets the 10 % target in all "
                f"four target columns: the closures can be made to reproduce these full runs.")
else:
    said.append("**Fitted cases.** Target columns missed even on the cases fitted: "
                + "; ".join(f"{case}: {listing(cols)}" for case, cols in fitted_misses.items() if cols)
                + ". The fit cannot make the closures' form reproduce them (or stopped before it could).")
if fit["holdout"]:
    held = missed(fit["holdout"])
    said.append(f"**Held-out case.** {fit['holdout']}: " + (
        "all four target columns within 20 %: the fitted closures predict a case they were not fitted on."
        if not held else f"{listing(held)} miss the 20 % target: the closures fitted on {listing(fit['cases'])} "
        f"do not carry over to it; their form, not only their values, would have to change to predict it."))
pairs = [f"{a} and {b} ({fit['correlation'][i, j]:+.3f})" for i, a in enumerate(fit["parameters"])
         for j, b in enumerate(fit["parameters"]) if j > i and abs(fit["correlation"][i, j]) > cal.CORRELATION_LIMIT]
said.append(f"**Uncertainty.** Not determined by the data: {listing(undetermined)}."
            + (f" Pairs beyond +-{cal.CORRELATION_LIMIT:g} correlation: {listing(pairs)}; the data fix a "
               "combination of each such group, not each key. More reference cases in the fit would separate them; "
               "a longer fit would not." if pairs else ""))
if not quick:
    change = pd.DataFrame(changes).set_index(["case", "column"])
    better = [f"{case} {column}" for (case, column), row in change.iterrows()
              if column in cal.TARGET_COLUMNS and abs(row["uncalibrated"]) < abs(row["calibrated"])]
    said.append("**Before and after.** Target columns the uncalibrated closures came closer to than the calibrated "
                f"ones: {listing(better)}." + (" The fit weighs each column by the full run's own scatter, so it "
                                                "trades a noisy column for steady ones." if better else ""))
said.append(f"**Where the layer applies.** Presets that apply it: {listing(presets)}.")
display(Markdown("\n\n".join(said)))

# %% [markdown]
# ## The hierarchical calibration against the designed set, and its prediction bands
#
# The current layer (`analysis.calibration.bands.CURRENT_LAYER`, `data/calibration/<name>.toml`) is the layer of
# `settler calibrate --set data/calibration/holdouts.toml --closures NAME` (`analysis.calibration`): the collision
# efficiency from the kernel run's merges alone, then the levels its closure set fits (for 'designed' the plume
# coefficient and return-flow ratio from the coalescence-off runs and the shear coefficient from the whole runs; for
# 'zones_core' the slag core's and the droplets' channel radii from the whole runs), each level with its
# identifiability gate, and the hold-outs named in `holdouts.toml` before any fit scored only after every gate
# passed. The hold-outs' 90 % prediction bands are popbal over the layer's parameter covariance with its log-normal
# model discrepancy (`analysis.calibration.bands`); the check is the share of their window means inside. The layer
# is read as committed (quick or not): the whole hierarchy takes one to two hours on 2 cores.

# %%
from analysis.calibration.bands import CURRENT_LAYER
from analysis.calibration.layer import BANDS_DRAW_FROM, bands_draw_parameters, fitted_set_engine

#: What the report says of a layer whose bands predate the fix (bands_draw_parameters False) or may (None).
BANDS_CAVEAT = {False: f"This layer was written before {BANDS_DRAW_FROM[:7]} (2026-12-07), from which popbal runs at "
                       "each parameter draw: its draws were overridden by the estimates, and its bands are the "
                       "discrepancy term's alone, too narrow for the parameters' uncertainty.",
                None: f"git cannot tell whether this layer was written after {BANDS_DRAW_FROM[:7]} (2026-12-07), "
                      "from which popbal runs at each parameter draw; if before, its bands are the discrepancy "
                      "term's alone, too narrow for the parameters' uncertainty."}
from analysis.calibration.targets import TARGET_COLUMNS, load_target, seed_scatter

layer_path = calibration_path(CURRENT_LAYER)
current = tomllib.loads(layer_path.read_text())
dprov = current["provenance"]
print(f"layer {layer_path.name}: command {dprov['command']!r}; code {dprov['code_commit'][:10]}"
      f"{' (tree dirty)' if dprov['code_tree_dirty'] else ''}; gate {'passed' if dprov['gate_passed'] else 'FAILED'}")
level_rows = [{"level": "collision", "parameter": "collision_efficiency", "runs": "kernel",
               "estimate": dprov["collision"]["efficiency"], "standard error": dprov["collision"]["standard_error"],
               "profile 95 %": "–", "discrepancy": math.nan}]
fitted_levels = [level for level in ("transport", "whole") if level in dprov]
for level in fitted_levels:
    table = dprov[level]
    for name in (k for k in table if isinstance(table[k], list) and f"correlation_{k}" in table):
        estimate, se, low, high = table[name]
        level_rows.append({"level": level, "parameter": name, "runs": ", ".join(table["runs"]), "estimate": estimate,
                           "standard error": se, "profile 95 %": f"{low:.3g}-{high:.3g}",
                           "discrepancy": table["discrepancy"]})
pd.DataFrame(level_rows).style.format({"estimate": "{:.4g}", "standard error": "{:.3g}", "discrepancy": "{:.3g}"},
                                      na_rep="–").hide(axis="index")

# %%
error_rows = []
for level in (*fitted_levels, "holdouts"):
    for key, values in dprov.get(level, {}).items():
        if key.startswith("error_"):
            role = "held out" if level == "holdouts" else f"fitted ({level})"
            limit = 0.2 if level == "holdouts" else 0.1
            error_rows.append({"run": key[len("error_"):], "role": role,
                               **{c: 100 * v for c, v in zip(TARGET_COLUMNS, values)},
                               "within target": sum(abs(v) <= limit for v in values)})
errors_layer = pd.DataFrame(error_rows)
within = errors_layer.groupby(errors_layer["role"] == "held out")["within target"].sum()
counts = errors_layer.groupby(errors_layer["role"] == "held out").size() * len(TARGET_COLUMNS)
errors_layer.style.format({c: "{:+.1f}" for c in TARGET_COLUMNS}).hide(axis="index").set_caption(
    "reduced / full - 1 [%] of the steady-window means; target: 10 % fitted, 20 % held out")

# %%
seed = seed_scatter(root)
holdout_runs = [k[len("error_"):] for k in dprov.get("holdouts", {}) if k.startswith("error_")
                and f"band_{k[len('error_'):]}_{list(TARGET_COLUMNS)[0]}" in dprov["holdouts"]]
# The bands are checked against the stored runs only where they are the runs the layer was fitted to: the same set
# engine (data/reference/engines.toml) at the layer's code commit as now.
fitted_engine = fitted_set_engine(dprov["code_commit"], DATA_DIR.parent)
engines_now = root / "engines.toml"
stored_engine = tomllib.loads(engines_now.read_text()).get("set") if engines_now.is_file() else None
if holdout_runs and (fitted_engine is None or fitted_engine != stored_engine):
    recorded = dprov["holdouts"].get("band_coverage", math.nan)
    print(f"the layer was fitted at {dprov['code_commit'][:10]} to "
          + ("a reference set that git cannot show here" if fitted_engine is None else
             f"the reference set of engine fulldem {fitted_engine['fulldem'][:7]}")
          + "; the stored set is " + ("another" if stored_engine is None else
                                                f"that of engine fulldem {stored_engine['fulldem'][:7]}")
          + ": its bands are not compared with today's runs (until the layer is refitted to them). Recorded in the "
          f"layer against the runs it was fitted to: band coverage {recorded:.3g}")
    caveat = BANDS_CAVEAT.get(bands_draw_parameters(dprov["code_commit"], DATA_DIR.parent))  # none where it drew them
    if caveat:
        print(caveat)
    holdout_runs = []
elif not holdout_runs:
    print("the layer records no hold-out bands (its gate failed, or it was fitted with --band-samples 0)")
else:
    fig = Figure(figsize=(10, 3.2 * len(holdout_runs) + 0.5), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(holdout_runs), 1, squeeze=False).ravel())
    inside, total = 0, 0
    for ax, run in zip(axes, holdout_runs):
        observed = load_target(run, root, seed).means
        for k, column in enumerate(TARGET_COLUMNS):
            q = np.asarray(dprov["holdouts"][f"band_{run}_{column}"], dtype=float) / observed[column]
            ax.plot([k, k], [q[0], q[2]], lw=8, alpha=0.35, color="C1", solid_capstyle="butt",
                    label="90 % band / full" if k == 0 else None)
            ax.plot(k, q[1], "o", color="C1", label="band median / full" if k == 0 else None)
            inside += int(q[0] <= 1.0 <= q[2])
            total += 1
        ax.axhline(1.0, color="C0", label="full run (window mean)")
        ax.axhspan(0.8, 1.2, color="C0", alpha=0.08, label="the 20 % target")
        ax.set_xticks(range(len(TARGET_COLUMNS)), [c.replace("_", " ") for c in TARGET_COLUMNS])
        ax.set_yscale("log")
        ax.set_ylabel("reduced / full")
        ax.set_title(f"held out: {run}", fontsize="medium")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize="small", ncol=2)
    show(fig)
    recorded = dprov["holdouts"].get("band_coverage", math.nan)
    print(f"band coverage: {inside} of {total} held-out window means inside their 90 % bands (recorded in the "
          f"layer: {recorded:.3g}); an honest band holds about 90 %")
    drew = bands_draw_parameters(dprov["code_commit"], DATA_DIR.parent)
    if drew is not True:
        print(BANDS_CAVEAT[drew])

# %%
gate_words = ("Every level passes the identifiability gate;" if dprov["gate_passed"] else
              "The identifiability gate fails (the hold-outs are not scored);")
display(Markdown(
    f"**What the {dprov['closures']} calibration shows.** {gate_words} "
    f"{int(within.get(False, 0))} of {int(counts.get(False, 0))} fitted window means are within 10 % and "
    f"{int(within.get(True, 0))} of {int(counts.get(True, 0))} held-out ones within 20 %: the gate says the "
    "parameters are determined, not that the model is right. The whole level absorbs a model discrepancy of "
    f"{dprov['whole']['discrepancy']:.2g} (relative), which sets the bands' width; docs/guide/reduced-model.md says "
    "which closures are laws, which are measured and which are fitted, and what the set shows popbal still lacks."))
