# %% [markdown]
# # Verification: Stokes, hindered settling, falling cloud, Smoluchowski and mass accounting
#
# Both engines against independent references: analytic solutions (Stokes with the wall factor, Richardson-Zaki,
# Nitsche-Batchelor less Hasimoto's periodic images, the Smoluchowski solutions of Scott and McLeod, the through-flow
# share w / (u + w)) and conservation of mass. The set-ups are the tests' (`fulldem/verification.py`,
# `popbal/smoluchowski.py`, rows built by `analysis/verification.py`); each row gives the tolerance the test suite
# holds that check to.
#
# `quick = True` runs the default-tier set in a minute or two (and the falling cloud at R = 3 cells instead of 4, to
# save time: not a tested configuration); `quick = False` runs every set-up, the slow tier included (about half an
# hour on 2 cores), and draws a cloud turning into a torus.
#
# Render: `settler report verification --out runs/reports` (add `--param quick=true` for the short version).

# %% tags=["parameters"]
quick = False

# %%
import time

from tqdm import tqdm

from analysis import verification as v
from analysis.reference import available_references
from analysis.report import show
from settler.paths import DATA_DIR

started = time.perf_counter()
small = "36 x 36 x 72 mm"
large = dict(width=0.048, height=0.144, fill=0.132)
checks = [(v.stokes_check, {}), (v.popbal_stokes_check, {}), (v.hindered_check, dict(phi=0.1)),
          (v.homogeneous_check, dict(phi=0.1)), (v.smoluchowski_check, dict(name="constant")),
          (v.smoluchowski_check, dict(name="sum")), (v.smoluchowski_check, dict(name="product")),
          (v.popbal_mass_check, {}), (v.outlet_band_check, {})]
if quick:
    checks.append((v.cloud_check, dict(n_a_over_r=4.0, cells_per_radius=3)))
else:
    checks += [(v.stokes_check, dict(diameter=2e-3, tolerance=0.03)), (v.stokes_check, dict(kernel="direct")),
               (v.stokes_check, dict(diameter=2e-3, kernel="direct", tolerance=0.03))]
    checks += [(v.hindered_check, dict(phi=phi)) for phi in (0.05, 0.2)]
    checks += [(v.hindered_check, dict(phi=phi, t_end=5.0, **large)) for phi in (0.05, 0.1, 0.2)]
    checks += [(v.homogeneous_check, dict(phi=phi)) for phi in (0.05, 0.2)]
    checks += [(v.cloud_check, dict(n_a_over_r=nar)) for nar in (2.0, 4.0, 5.0, 10.0)]
    checks += [(v.cloud_check, dict(n_a_over_r=4.0, cells_per_radius=6, cell=20e-3 / 6, diameter=1e-3)),
               (v.cloud_check, dict(n_a_over_r=4.0, box_radii=12))]
    checks += [(v.smoluchowski_check, dict(name=name, sections_per_doubling=6)) for name in ("constant", "sum",
                                                                                             "product")]

# %% [markdown]
# ## The checks
#
# `error` is the relative error the tolerance applies to (measured / reference - 1; for mass accounting the largest
# imbalance relative to the matte fed). Velocities in m/s; `wall` in seconds on this machine.

# %%
results = [function(**keywords) for function, keywords in tqdm(checks, desc="checks")]
references = DATA_DIR / "reference"
results += [v.stored_run_mass_check(references / name) for name in available_references(references)]
frame = v.table(results)
frame.style.format({"measured": "{:.4g}", "reference": "{:.4g}", "error": "{:+.3g}", "tolerance": "{:.3g}",
                    "wall": "{:.1f}"}).hide(axis="index")

# %%
outside = frame[~frame.passed]
print(f"{len(frame) - len(outside)} of {len(frame)} checks within their tolerance "
      f"({time.perf_counter() - started:.0f} s in all).")
for row in outside.itertuples():
    print(f"outside: {row.check}, {row.case}: error {row.error:+.3f}, tolerance {row.tolerance:g}")

# %% [markdown]
# Known discrepancy (full run only): in the tall 48 x 48 x 144 mm column at phi = 0.2 the front runs about 26 %
# ahead of Richardson-Zaki (a strict xfail in the slow tests; box-scale convection, see
# `reports/fulldem_verification.md`). The homogeneous suspensions settle 7-13 % below it and the clouds 11-12 % below
# the box-corrected reference at R = 4 cells: the smoothing kernel (discussion in the same file).

# %% [markdown]
# ## Smoluchowski moments over time
#
# popbal's cell-average solver at ratio 2^(1/3) and 2^(1/6) between sections: relative errors of M0 and M2 at five
# times up to 95 % aggregation (the product kernel to tau = 0.4, before gelation), and the drift of the mass moment.

# %%
import pandas as pd
from popbal.smoluchowski import KERNELS

ratios = (3,) if quick else (3, 6)
moments = pd.concat({(name, q): v.smoluchowski_errors(name, q) for name in KERNELS for q in ratios},
                    names=["kernel", "sections per doubling", "row"]).droplevel("row")
moments.style.format({"tau": "{:.3g}", "m0_error": "{:+.2e}", "m2_error": "{:+.2e}", "m1_drift": "{:+.1e}"})

# %% [markdown]
# ## A falling cloud turns into a torus
#
# N a/R = 5, R = 4 cells, periodic 8 R cube, cloud Reynolds number 1, run for 14 settling times R / U_St: side views
# (all droplets, and a slice through the centre), top views, and the centroid velocity against the references. Only
# with `quick = False` (a few minutes).

# %%
if quick:
    print("skipped in quick mode (quick = True): render with --param quick=false for the torus")
else:
    show(v.torus_figure(*v.torus_run(5.0, 14.0, 1.0)))
