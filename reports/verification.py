# %% [markdown]
# # Verification: Stokes, hindered settling, falling cloud, Smoluchowski and mass accounting
#
# Both engines against independent references: analytic solutions (Stokes with the wall factor, Richardson-Zaki,
# Nitsche-Batchelor less Hasimoto's periodic images, the Smoluchowski solutions of Scott and McLeod, the through-flow
# share w / (u + w)) and conservation of mass. The set-ups are the tests' (`fulldem/cases/`,
# `popbal/smoluchowski.py`, rows built by `analysis/verification.py`); each row gives the tolerance the test suite
# holds that check to. `error` is the relative error the tolerance applies to (measured / reference - 1; for mass
# accounting the largest imbalance relative to the matte fed); velocities in m/s, `wall` in seconds.
#
# `quick = True` runs the default-tier set in under a minute (the falling cloud at R = 3 cells instead of 4, to save
# time: not a tested configuration); `quick = False` runs every set-up, the slow tier included (about half an hour on
# 2 cores; its slowest cell takes up to ten minutes), and draws a cloud turning into a torus.
#
# Render: `settler report verification --out runs/reports --timeout 1800` (add `--param quick=true` for the short
# version).

# %% tags=["parameters"]
quick = False

# %%
import time

import pandas as pd
from tqdm import tqdm

from analysis import verification as v
from analysis.reference import available_references
from analysis.report import show
from popbal.smoluchowski import KERNELS
from settler.paths import DATA_DIR


started = time.perf_counter()
results = []
FORMATS = {"measured": "{:.4g}", "reference": "{:.4g}", "error": "{:+.3g}", "tolerance": "{:.3g}", "wall": "{:.1f}"}


def run(checks, what):
    """Run (function, keywords) pairs with a progress bar; keep and return their rows as a styled table."""
    rows = [function(**keywords) for function, keywords in tqdm(checks, desc=what)]
    results.extend(rows)
    return v.table(rows).style.format(FORMATS).hide(axis="index")


# %% [markdown]
# ## Stokes: a single droplet
#
# fulldem: a droplet released in quiescent slag in a closed 0.2 m cube reaches the drag law's terminal velocity times
# the square-duct wall factor 1 / (1 + 1.903 d/L). popbal: one size fed at the top of a column arrives after H / u_St.

# %%
stokes = [(v.stokes_check, {}), (v.popbal_stokes_check, {})]
if not quick:
    stokes += [(v.stokes_check, dict(diameter=2e-3, tolerance=0.03)), (v.stokes_check, dict(kernel="direct")),
               (v.stokes_check, dict(diameter=2e-3, kernel="direct", tolerance=0.03))]
run(stokes, "Stokes")

# %% [markdown]
# ## Hindered settling
#
# The front of a uniform suspension of 2 mm droplets (the height with 5 % of them above it) descends at the
# Richardson-Zaki velocity U_St (1 - phi)^4.65; a periodic homogeneous suspension settles at it in the frame of zero
# volume flux.

# %%
large = dict(width=0.048, height=0.144, fill=0.132)
hindered = [(v.hindered_check, dict(phi=0.1)), (v.homogeneous_check, dict(phi=0.1))]
if not quick:
    hindered += [(v.hindered_check, dict(phi=phi)) for phi in (0.05, 0.2)]
    hindered += [(v.hindered_check, dict(phi=phi, t_end=5.0, **large)) for phi in (0.05, 0.1, 0.2)]
    hindered += [(v.homogeneous_check, dict(phi=phi)) for phi in (0.05, 0.2)]
run(hindered, "hindered settling")

# %% [markdown]
# Known discrepancy (full run only): in the tall 48 x 48 x 144 mm column at phi = 0.2 the front runs about 26 %
# ahead of Richardson-Zaki (a strict xfail in the slow tests; box-scale convection, see
# `reports/fulldem_verification.md`). The homogeneous suspensions settle 7-13 % below it: the resolved flow counts
# again part of the hindrance the drag closure already holds.

# %% [markdown]
# ## Falling cloud
#
# A ball of N droplets falls at U_St (1 + 1.2 N a/R - 2.837 N a/L): Nitsche & Batchelor's unbounded cloud less the
# periodic box's images (Hasimoto). Centroid velocity from 5 to 8 viscous times R^2/nu.

# %%
if quick:
    clouds = [(v.cloud_check, dict(n_a_over_r=4.0, cells_per_radius=3))]
else:
    clouds = [(v.cloud_check, dict(n_a_over_r=nar)) for nar in (2.0, 4.0, 5.0, 10.0)]
    clouds += [(v.cloud_check, dict(n_a_over_r=4.0, cells_per_radius=6, cell=20e-3 / 6, diameter=1e-3)),
               (v.cloud_check, dict(n_a_over_r=4.0, box_radii=12))]
run(clouds, "falling cloud")

# %% [markdown]
# The clouds fall 11-12 % below the box-corrected reference at R = 4 cells and 4 % below at R = 6 cells: the Gaussian
# smoothing kernel of width R/4 (R/6) lowers the collective part.
#
# ### A falling cloud turns into a torus
#
# N a/R = 5, R = 4 cells, periodic 8 R cube, cloud Reynolds number 1, run for 14 settling times R / U_St: side views
# (all droplets, and a slice through the centre), top views, and the centroid velocity against the references. Only
# with `quick = False` (a few minutes).

# %%
if quick:
    print("torus skipped in quick mode (quick = True): render with --param quick=false to draw it")
else:
    show(v.torus_figure(*v.torus_run(5.0, 14.0, 1.0)))

# %% [markdown]
# ## Smoluchowski coagulation
#
# popbal's cell-average sectional solver against the constant (Scott), sum (Golovin) and product (McLeod) kernels'
# moments from an exponential start, at five times up to 95 % aggregation (the product kernel to tau = 0.4, before
# gelation); the table below the checks gives the errors at each time and the drift of the mass moment.

# %%
ratios = (3,) if quick else (3, 6)
run([(v.smoluchowski_check, dict(name=name, sections_per_doubling=q)) for q in ratios for name in KERNELS],
    "Smoluchowski")

# %%
moments = pd.concat({(name, q): v.smoluchowski_errors(name, q) for name in KERNELS for q in ratios},
                    names=["kernel", "sections per doubling", "row"]).droplevel("row")
moments.style.format({"tau": "{:.3g}", "m0_error": "{:+.2e}", "m2_error": "{:+.2e}", "m1_drift": "{:+.1e}"})

# %% [markdown]
# ## Mass accounting
#
# fed = in slag + settled + lost + reacted: in popbal with every process on, in popbal's outlet band (which takes
# exactly w / (u + w) of a size class's flux), and in every stored full run in `data/reference/`.

# %%
references = DATA_DIR / "reference"
mass = [(v.popbal_mass_check, {}), (v.outlet_band_check, {})]
mass += [(v.stored_run_mass_check, dict(run=references / name)) for name in available_references(references)]
run(mass, "mass accounting")

# %% [markdown]
# ## Summary

# %%
frame = v.table(results)
outside = frame[~frame.passed]
print(f"{len(frame) - len(outside)} of {len(frame)} checks within their tolerance "
      f"({time.perf_counter() - started:.0f} s in all).")
for row in outside.itertuples():
    print(f"outside: {row.check}, {row.case}: error {row.error:+.3f}, tolerance {row.tolerance:g}")
