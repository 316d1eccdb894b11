"""Verification checks of both engines as table rows, for the verification report (reports/verification.py).

Each ``*_check`` function runs one check and returns a :class:`Check`: what was measured, the independent reference
(an analytic solution or a conservation law), their relative error and the tolerance the test suite holds it to.
The set-ups are those of the tests -- fulldem's collective settling from :mod:`fulldem.cases`, popbal's
Smoluchowski solutions from :mod:`popbal.smoluchowski` -- so the report shows the numbers the tests assert.

* **Stokes**: a single droplet in quiescent slag (fulldem) reaches the terminal velocity of the case's drag law
  times the square-duct wall factor (Happel & Brenner); a single size in popbal's column arrives at the bottom after
  H / u_St.
* **Hindered settling**: the front of a uniform suspension descends at the Richardson-Zaki velocity U_St (1 -
  phi)^4.65; a periodic homogeneous suspension settles at it in the frame of zero volume flux.
* **Falling cloud**: a ball of droplets falls at U_St (1 + 1.2 N a/R - 2.837 N a/L) (Nitsche & Batchelor 1997, less
  Hasimoto's periodic images); :func:`torus_run` and :func:`torus_figure` show it turning into a torus.
* **Smoluchowski**: popbal's sectional solver against the constant, sum and product kernels' moments.
* **Mass accounting**: fed = in slag + settled + lost + reacted in popbal with every process on, in popbal's outlet
  band (w / (u + w) of a class's flux), and in the stored full runs.

This module calls the engines' public set-ups (it is the one place in ``analysis`` that runs an engine, besides
reduced runs for comparison). SI units throughout.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import pandas as pd


#: Case overrides of popbal's single-size checks: one size, no coalescence, no channel, no hindering, Stokes drag.
SINGLE_SIZE = {"feed.scale_std": 0.0, "coalescence.enabled": False, "popbal.channel_feed_fraction": 0.0,
               "popbal.channel_radius_factor": 0.0, "popbal.hindered_exponent": 0.0, "drag.law": "stokes",
               "popbal.height_cells": 20, "popbal.time_step": 5.0, "popbal.max_courant": 100.0,
               "popbal.output_interval": 50.0}


@dataclasses.dataclass
class Check:
    """One verification result. ``measured`` and ``reference`` in ``unit``; ``error`` the relative error [-] the
    tolerance applies to (for a conservation check: the largest relative imbalance, reference 0); ``wall`` [s]."""

    check: str
    case: str
    measured: float
    reference: float
    unit: str
    error: float
    tolerance: float
    wall: float
    note: str = ""

    @property
    def passed(self) -> bool:
        """Whether the error is within the tolerance."""
        return bool(abs(self.error) <= self.tolerance)


def ratio_error(measured: float, reference: float) -> float:
    """Relative error measured / reference - 1 [-]."""
    return measured / reference - 1.0


def table(checks) -> pd.DataFrame:
    """The checks as a DataFrame, one row each, with a ``passed`` column."""
    rows = [{**dataclasses.asdict(c), "passed": c.passed} for c in checks]
    return pd.DataFrame(rows, columns=[f.name for f in dataclasses.fields(Check)] + ["passed"])


# ------------------------------------------------------------------------------------------------------------ Stokes
def stokes_check(diameter=500e-6, kernel="filtered", tolerance=0.02) -> Check:
    """fulldem: a single droplet in the 0.2 m cube settles at the drag law's terminal velocity times the square-duct
    wall factor 1/(1 + 1.903 d/L) (tests/test_fulldem_stepper.py: 2 % at 500 um, 3 % at 2 mm)."""
    from settler.physics import square_duct_factor

    clock = time.perf_counter()
    from fulldem.cases.single_droplet import single_droplet

    walls = ["fulldem.near_wall=interior"] if kernel == "direct" else []  # the direct kernel's only near-wall form
    sim, velocity = single_droplet(diameter, extra=[f"fulldem.kernel={kernel}", *walls])
    reference = sim.terminal_velocity(diameter) * square_duct_factor(diameter / 0.2)
    return Check("Stokes, single droplet (fulldem)", f"d = {diameter * 1e6:.0f} um, 0.2 m cube, 1 cm cells, {kernel} "
                 "kernel", velocity, reference, "m/s", ratio_error(velocity, reference), tolerance,
                 time.perf_counter() - clock, "reference: terminal velocity x square-duct wall factor")


def popbal_stokes_check(tolerance=1e-6) -> Check:
    """popbal: a single size fed at the top of the simple case's column (Stokes drag, no channel, no coalescence)
    arrives at the bottom after H / u_St: once the front has passed, t - settled / feed rate is that arrival time."""
    import popbal
    from settler.physics import stokes_velocity

    clock = time.perf_counter()
    model = popbal.setup("simple", SINGLE_SIZE, popbal__end_time=3000.0)
    case = model.case
    velocity = stokes_velocity(case.feed.mean_diameter, case.matte.density, case.slag.density, case.slag_viscosity)
    ts = popbal.run(model, progress=False).timeseries
    late = ts[ts.time > 5 * case.geometry.height / velocity]
    arrival = (late.time - late.mass_settled / case.feed.mass_rate).to_numpy()
    reference = case.geometry.height / velocity
    worst = float(np.max(np.abs(arrival / reference - 1.0)))
    return Check("Stokes, single size (popbal)", f"simple column, d = {case.feed.mean_diameter * 1e6:.0f} um, "
                 "Stokes drag", float(arrival.mean()), reference, "s (arrival time)", worst, tolerance,
                 time.perf_counter() - clock, "reference: H / u_St")


# ------------------------------------------------------------------------------------------------ hindered settling
def hindered_check(phi, t_end=4.0, tolerance=0.15, **setup) -> Check:
    """fulldem: the front of a uniform suspension at volume fraction ``phi`` (the box of ``setup``, default 36 x 36
    x 72 mm) descends from 1 s to ``t_end`` [s] at the Richardson-Zaki velocity."""
    from fulldem.cases.suspensions import check_hindered
    from settler.physics import richardson_zaki_factor

    clock = time.perf_counter()
    ratio, record, sim, droplet_re = check_hindered(phi, t_end, **setup)
    u_rz = sim.terminal_velocity(float(sim.store.diameter[0])) * richardson_zaki_factor(phi)
    size = sim.grid.size * 1e3
    return Check("hindered settling, front (fulldem)", f"phi = {phi}, {record.count} droplets, box "
                 f"{size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm, t = 1-{t_end:g} s", ratio * u_rz, u_rz, "m/s",
                 ratio - 1.0, tolerance, time.perf_counter() - clock,
                 f"reference: U_St (1 - phi)^4.65; droplet Re {droplet_re:.2g}")


def homogeneous_check(phi, tolerance=0.15) -> Check:
    """fulldem: a random suspension in a periodic 48 mm cube settles, in the frame of zero volume flux, at the
    Richardson-Zaki velocity (mean over 0.5-1.5 s)."""
    from fulldem.cases.suspensions import check_homogeneous

    clock = time.perf_counter()
    sim, u_rz, speeds = check_homogeneous(phi)
    measured = float(np.mean(speeds))
    return Check("hindered settling, homogeneous (fulldem)", f"phi = {phi}, {sim.store.count} droplets, periodic "
                 "48 mm cube, t = 0.5-1.5 s", measured, u_rz, "m/s", ratio_error(measured, u_rz), tolerance,
                 time.perf_counter() - clock, "reference: U_St (1 - phi)^4.65")


# ---------------------------------------------------------------------------------------------------- falling cloud
def cloud_check(n_a_over_r=4.0, tolerance=0.25, **setup) -> Check:
    """fulldem: the centroid of a falling cloud (:func:`fulldem.cases.cloud.falling_cloud`, ``setup`` its keywords)
    from 5 to 8 viscous times R^2/nu, against U_St (1 + 1.2 N a/R - 2.837 N a/L)."""
    from fulldem.cases.cloud import check_cloud

    clock = time.perf_counter()
    cloud, speed, fallen, spread = check_cloud(n_a_over_r, **setup)
    cells = setup.get("cells_per_radius", 4)
    box = setup.get("box_radii", 8)
    return Check("falling cloud (fulldem)", f"N = {cloud.count}, N a/R = {cloud.n_a_over_r:.2f}, R = {cells} cells, "
                 f"periodic {box} R box, cloud Re {cloud.reynolds(speed):.2f}", speed, cloud.reference(), "m/s",
                 ratio_error(speed, cloud.reference()), tolerance, time.perf_counter() - clock,
                 f"unbounded Nitsche-Batchelor {cloud.nitsche_batchelor() / cloud.stokes:.2f} U_St; fallen "
                 f"{fallen:.1f} R; radius of gyration x {spread:.3f}")


def torus_run(n_a_over_r=5.0, duration=14.0, reynolds=1.0, snapshots=6, seed=7, progress=True):
    """Run the falling-cloud set-up (R = 4 cells, periodic 8 R cube, 1 mm droplets) for ``duration`` settling
    times R / U_St. Returns (the Cloud, times [s], unwrapped centroid heights [m], ``snapshots`` tuples of (time
    [s], fall distance [R], unwrapped positions (N, 3) [m]) evenly spaced in time)."""
    from tqdm import tqdm

    from fulldem.cases.cloud import Unwrapper, falling_cloud

    cloud = falling_cloud(n_a_over_r, diameter=1e-3, reynolds=reynolds, seed=seed)
    sim = cloud.sim
    follow = Unwrapper(sim)
    start = follow.position[:, 2].mean()
    end = duration * cloud.radius / cloud.stokes
    marks = list(np.linspace(0.0, end, snapshots))
    shots, times, centroid = [], [0.0], [start]
    # a bar redrawn at most every 5 s: in a notebook every redraw is kept in the cell's output
    with tqdm(total=end, unit="s", desc="falling cloud", disable=not progress, mininterval=5.0) as bar:
        while marks:
            if sim.time >= marks[0] - 1e-9:
                shots.append((sim.time, (start - follow.position[:, 2].mean()) / cloud.radius,
                              follow.position.copy()))
                marks.pop(0)
                continue
            before = sim.time
            sim.step()
            follow.update()
            times.append(sim.time)
            centroid.append(follow.position[:, 2].mean())
            bar.update(sim.time - before)
    return cloud, np.array(times), np.array(centroid), shots


def torus_figure(cloud, times, centroid, shots):
    """Side views (all droplets; a slice |y - y_c| < R/4), top views (|z - z_c| < 1.5 R) at each snapshot,
    positions relative to the cloud's median in units of R, and the centroid velocity against the references
    beside them. Returns a matplotlib Figure (made without pyplot)."""
    from matplotlib.figure import Figure

    radius = cloud.radius
    count = len(shots)
    fig = Figure(figsize=(2.3 * (count + 1), 7.4), layout="constrained")
    grid = fig.add_gridspec(3, count + 1, width_ratios=[1] * count + [1.5])
    for j, (t, fallen, positions) in enumerate(shots):
        rel = (positions - np.median(positions, axis=0)) / radius
        views = [(np.ones(len(rel), bool), (0, 2), "k", 1.5, (-3.0, 2.0), "side view, all droplets\nz/R"),
                 (np.abs(rel[:, 1]) < 0.25, (0, 2), "C3", 4.0, (-3.0, 2.0), "side view, slice |y| < R/4\nz/R"),
                 (np.abs(rel[:, 2]) < 1.5, (0, 1), "C0", 1.5, (-2.2, 2.2), "top view, |z| < 1.5 R\ny/R")]
        for i, (keep, (a, b), colour, size, ylim, ylabel) in enumerate(views):
            ax = fig.add_subplot(grid[i, j])
            ax.scatter(rel[keep, a], rel[keep, b], s=size, c=colour, lw=0)
            ax.set_xlim(-2.2, 2.2)
            ax.set_ylim(*ylim)
            ax.set_aspect("equal")
            ax.tick_params(labelsize=7)
            ax.set_xlabel("x/R", fontsize=7)
            if j == 0:
                ax.set_ylabel(ylabel, fontsize=7)
            if i == 0:
                ax.set_title(f"fallen {fallen:.1f} R\nt U$_{{St}}$/R = {t * cloud.stokes / radius:.1f}", fontsize=8)
    ax = fig.add_subplot(grid[:, -1])
    velocity = -np.gradient(centroid, times)
    ax.plot((centroid[0] - centroid) / radius, velocity / cloud.stokes, color="k", lw=1, label="centroid (fulldem)")
    ax.axhline(cloud.nitsche_batchelor() / cloud.stokes, color="C1", ls="--", lw=1, label="1 + 1.2 N a/R (unbounded)")
    ax.axhline(cloud.reference() / cloud.stokes, color="C2", ls=":", lw=1.5, label="less box images (Hasimoto)")
    ax.axhline(1.0, color="0.5", lw=0.8, label="single droplet")
    ax.set_xlabel("fall distance / R", fontsize=8)
    ax.set_ylabel("cloud velocity / U$_{St}$", fontsize=8)
    ax.set_ylim(0, 1.15 * cloud.nitsche_batchelor() / cloud.stokes)
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(alpha=0.3)
    fig.suptitle(f"Falling cloud: N = {cloud.count} droplets of {cloud.diameter * 1e3:.1f} mm, N a/R = "
                 f"{cloud.n_a_over_r:.1f}, R = 4 cells, periodic {cloud.box / radius:.0f} R cube", fontsize=9)
    return fig


# ----------------------------------------------------------------------------------------------------- Smoluchowski
def smoluchowski_errors(name: str, sections_per_doubling: int) -> pd.DataFrame:
    """popbal's cell-average solver on a registered kernel (:data:`popbal.smoluchowski.KERNELS`) from the
    exponential initial condition, at five times up to 95 % aggregation: per time tau [-], the relative errors of
    M0 and M2 against the analytic moments and the drift of M1 (mass) from its start [-]."""
    from popbal.smoluchowski import KERNELS, solve

    entry = KERNELS[name]
    taus = np.linspace(0.0, entry.aggregation_95, 6)[1:]
    solution = solve(name, sections_per_doubling, taus)
    m1 = solution.moment(1)
    return pd.DataFrame({"tau": taus,
                         "m0_error": solution.moment(0) / np.array([entry.zeroth_moment(t) for t in taus]) - 1.0,
                         "m2_error": solution.moment(2) / np.array([entry.second_moment(t) for t in taus]) - 1.0,
                         "m1_drift": m1 / m1[0] - 1.0})


def smoluchowski_check(name: str, sections_per_doubling: int = 3, tolerance=0.05) -> Check:
    """The largest M0 and M2 error of :func:`smoluchowski_errors` (the issue asks for 5 % at ratio 2^(1/3) up to
    95 % aggregation); measured and reference are M2 / (N0 v0^2) at the last time."""
    from popbal.smoluchowski import KERNELS

    clock = time.perf_counter()
    errors = smoluchowski_errors(name, sections_per_doubling)
    entry = KERNELS[name]
    tau = float(errors.tau.iloc[-1])
    reference = entry.second_moment(tau)
    worst = float(np.abs(errors[["m0_error", "m2_error"]].to_numpy()).max())
    return Check("Smoluchowski (popbal)", f"{name} kernel, ratio 2^(1/{sections_per_doubling}), tau up to {tau:.3g}",
                 reference * (1.0 + float(errors.m2_error.iloc[-1])), reference, "M2 / (N0 v0^2)", worst, tolerance,
                 time.perf_counter() - clock, f"{entry.source}; mass drift {np.abs(errors.m1_drift).max():.1e}")


# --------------------------------------------------------------------------------------------------- mass accounting
def balance_error(timeseries: pd.DataFrame) -> float:
    """Largest |fed - in slag - settled - lost - reacted| / fed of a time series [-]."""
    from settler.output import mass_balance_error

    ts = timeseries
    fed = ts.mass_fed.to_numpy()
    error = mass_balance_error(fed, ts.mass_in_slag, ts.mass_settled, ts.mass_lost, ts.mass_reacted)
    return float(np.nanmax(np.abs(np.where(fed > 0.0, error, 0.0)))) if len(ts) else math.nan


def popbal_mass_check(end_time=20.0, tolerance=1e-10) -> Check:
    """popbal, deep case with coalescence, reaction, outlet, hindering and both zones on: the mass balance closes to
    round-off (tests/test_popbal_verification.py)."""
    import popbal

    clock = time.perf_counter()
    result = popbal.run("deep", popbal__end_time=end_time, popbal__height_cells=20, popbal__output_interval=2.0,
                        popbal__channel_feed_fraction=0.6, popbal__time_step=0.1, progress=False)
    last = result.timeseries.iloc[-1]
    error = balance_error(result.timeseries)
    fed = last.mass_fed
    return Check("mass accounting (popbal)", f"deep, {end_time:g} s, every process on", error, 0.0,
                 "- (largest imbalance / fed)", error, tolerance, time.perf_counter() - clock,
                 f"of the fed: settled {last.mass_settled / fed:.3f}, lost {last.mass_lost / fed:.2e}, reacted "
                 f"{last.mass_reacted / fed:.3f}")


def outlet_band_check(tolerance=1e-6) -> Check:
    """popbal, vertical slag flow (cubic case, one size): at steady state the outlet band takes w / (u + w) of the
    class's flux."""
    import popbal

    clock = time.perf_counter()
    model = popbal.setup("cubic", SINGLE_SIZE, popbal__end_time=4000.0)
    ts = popbal.run(model, progress=False).timeseries
    u, w = model.velocity_table[0, 0], model.downflow.max()
    rate = np.diff(ts.mass_lost.to_numpy())[-5:] / np.diff(ts.time.to_numpy())[-5:] / model.case.feed.mass_rate
    reference = w / (u + w)
    return Check("outlet band loss (popbal)", "cubic, one size, vertical slag flow, steady", float(rate.mean()),
                 reference, "- (lost / fed)", float(np.max(np.abs(rate / reference - 1.0))), tolerance,
                 time.perf_counter() - clock, "reference: w / (u + w)")


def stored_run_mass_check(run, tolerance=1e-9) -> Check:
    """A stored run (a :class:`analysis.runs.Run` or its folder): its time series' mass balance closes."""
    from .runs import load_run

    clock = time.perf_counter()
    run = load_run(run)
    error = balance_error(run.timeseries)
    end = float(run.timeseries.time.iloc[-1])
    return Check(f"mass accounting ({run.engine or 'stored run'})", f"{run.name}, stored run to {end:.0f} s", error,
                 0.0, "- (largest imbalance / fed)", error, tolerance, time.perf_counter() - clock,
                 f"{run.folder}")
