# %% [markdown]
# # Paper cases: the seed paper's figures from the stored full runs, and the reduced model against them
#
# For the cubic, simple and deep cases of Jylhä & Jokilaakso (Heliyon 9 (2023) e21570): the paper's figures drawn
# from the stored full-engine reference runs in `data/reference/<case>/` (`analysis.figures`, one function per
# figure), then the reduced model (`popbal`) run on the same preset over the same time and compared with the full run
# column by column (`analysis.compare`). A case without a stored reference is skipped with a note.
#
# The reduced runs are written into `reduced/<case>/` beside this report (the folder it runs in).
# `quick = True` compares over the first 10 s only (a few seconds per case).
#
# Render: `settler report paper_cases --out runs/reports`.

# %% tags=["parameters"]
quick = False
cases = ["cubic", "simple", "deep"]
# folder of the stored reference runs (empty: the data folder's reference/)
references = ""

# %%
from pathlib import Path

import pandas as pd
from IPython.display import Markdown, display

import popbal
from analysis import figures
from analysis.compare import compare, comparison_figure
from analysis.reference import available_references
from analysis.report import show
from analysis.runs import load_run
from settler.cases import load_case
from settler.paths import DATA_DIR

root = Path(references) if references else DATA_DIR / "reference"
present = [name for name in cases if name in available_references(root)]
missing = [name for name in cases if name not in present]
QUICK_END = 10.0  # [s] simulated time of the reduced runs in quick mode
print(f"stored references in {root}: {', '.join(present) or 'none'}")
if missing:
    display(Markdown(f"**Skipped (no stored reference in `{root}`): {', '.join(missing)}.** Store one with "
                     "`python -m analysis.reference RUN CASE_NAME` after `settler full CASE --out RUN`."))

# %% [markdown]
# ## The stored full runs

# %%
summary = []
for name in present:
    run = load_run(root / name)
    last = run.timeseries.iloc[-1]
    summary.append({"case": name, "simulated [s]": last.time, "droplets at the end": last.droplet_count,
                    "mean diameter [mm]": last.mean_diameter * 1e3, "settled / fed": last.mass_settled / last.mass_fed,
                    "wall time [h]": run.reference.get("wall_time", float("nan")) / 3600.0,
                    "command": run.reference.get("command", "")})
pd.DataFrame(summary)

# %% [markdown]
# ## The paper's figures
#
# Droplet counts (Fig. 15), mean diameter and centreline velocity (Fig. 11), mean settling velocity (Fig. 16),
# droplets in a slab on the central plane by size and by speed (Figs. 8, 9, 12, 17, 18), the slag flow on that plane
# (Fig. 10), density and speed against height (Figs. 20, 21), and the channel; snapshot figures at the last stored
# snapshot. A figure whose inputs the reference lacks is listed with the reason.

# %%
for name in present:
    display(Markdown(f"### {name}"))
    for figure, draw in figures.figure_functions().items():
        try:
            show(draw(root / name))
        except figures.NoData as reason:
            print(f"{name}: {figure} skipped: {reason}")

# %% [markdown]
# ## Full against reduced
#
# The reduced model runs on the preset of the same name (with its calibration, if the preset has one) over the
# reference's time span; case keys in which the preset differs from the reference's resolved case are listed (the
# engine's own run-control keys aside). Errors: relative error of the window mean, |mean_reduced - mean_full| /
# |mean_full|, per column over the quarters of the common span and its last third (`steady`).


# %%
def differing_keys(preset, stored) -> list[str]:
    """Keys of the resolved cases that differ, outside the engines' own sections."""
    a, b = preset.to_dict(), stored.to_dict()
    return [f"{section}.{key}: preset {a[section].get(key)!r}, reference {b.get(section, {}).get(key)!r}"
            for section in a if section not in ("fulldem", "popbal", "case")
            for key in a[section] if a[section].get(key) != b.get(section, {}).get(key)]


steady = {}
for name in present:
    full = load_run(root / name)
    end = float(full.timeseries.time.iloc[-1])
    if quick:
        end = min(end, QUICK_END)
    model = popbal.setup(name)
    result = popbal.run(model, end_time=end, output_interval=min(0.5, end / 10), progress=False)
    folder = result.save(Path("reduced") / name)
    display(Markdown(f"### {name}: reduced run to {end:g} s in {result.wall_time:.1f} s wall (`{folder}`)"))
    for line in differing_keys(load_case(name), full.case) or ["no case key differs from the reference's"]:
        print(line)
    comparison = compare(full, folder)
    show(comparison_figure(comparison))
    errors = comparison.errors.pivot(index="column", columns="window", values="relative_error")
    steady[name] = comparison.steady_errors()
    display(errors.style.format("{:.1%}", na_rep="–"))
    for column, reason in comparison.skipped.items():
        print(f"{column} not compared: {reason}")

# %% [markdown]
# ## Steady-window errors, all cases

# %%
pd.DataFrame(steady).style.format("{:.1%}", na_rep="–") if steady else print("no case compared")
