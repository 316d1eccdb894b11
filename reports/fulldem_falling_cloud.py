"""A falling cloud of droplets in the coupled engine turns into a torus: the mechanism behind channeling.

    python reports/fulldem_falling_cloud.py [--n-a-over-r 5] [--duration 14] [--reynolds 1] [--out PATH]

Runs the set-up of the falling-cloud verification (fulldem/verification.py: N droplets in a ball of
radius R = 4 cells, periodic cube of side 8 R, Stokes-regime cloud) for ``--duration`` settling times R / U_St and
writes reports/figures/fulldem_falling_cloud.png: side views (all droplets, and a slice |y - y_c| < R/4 through the
cloud's centre) and top views at several times, positions relative to the cloud's median in units of R,
and the centroid velocity against the reference (Nitsche & Batchelor 1997, less Hasimoto's image term) beside it.
Expect a few minutes on 2 cores. Numbers: reports/fulldem_verification.md.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fulldem.verification import Unwrapper, falling_cloud  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def run(n_a_over_r, duration, reynolds, snapshots=6, seed=7):
    """Run the cloud for ``duration`` single-droplet settling times R / U_St; returns the cloud, the centroid series
    and ``snapshots`` (time [s], fall distance [R], unwrapped positions [m]) evenly spaced in time."""
    cloud = falling_cloud(n_a_over_r, diameter=1e-3, reynolds=reynolds, seed=seed)
    sim = cloud.sim
    follow = Unwrapper(sim)
    start = follow.position[:, 2].mean()
    marks = list(np.linspace(0.0, duration * cloud.radius / cloud.stokes, snapshots))
    shots, times, centroid = [], [0.0], [start]
    clock = time.time()
    while marks:
        if sim.time >= marks[0] - 1e-9:
            fallen = (start - follow.position[:, 2].mean()) / cloud.radius
            shots.append((sim.time, fallen, follow.position.copy()))
            marks.pop(0)
            print(f"t = {sim.time:7.1f} s  fallen {fallen:5.1f} R  ({time.time() - clock:.0f} s wall)", flush=True)
            continue
        sim.step()
        follow.update()
        times.append(sim.time)
        centroid.append(follow.position[:, 2].mean())
    return cloud, np.array(times), np.array(centroid), shots


def plot(cloud, times, centroid, shots, path):
    radius = cloud.radius
    count = len(shots)
    fig, axes = plt.subplots(3, count + 1, figsize=(2.3 * (count + 1), 7.4), constrained_layout=True,
                             gridspec_kw=dict(width_ratios=[1] * count + [1.5]))
    for j, (t, fallen, positions) in enumerate(shots):
        rel = (positions - np.median(positions, axis=0)) / radius
        near = np.abs(rel[:, 1]) < 0.25
        core = np.abs(rel[:, 2]) < 1.5
        axes[0, j].scatter(rel[:, 0], rel[:, 2], s=1.5, c="k", lw=0)
        axes[1, j].scatter(rel[near, 0], rel[near, 2], s=4, c="C3", lw=0)
        axes[2, j].scatter(rel[core, 0], rel[core, 1], s=1.5, c="C0", lw=0)
        axes[0, j].set_title(f"fallen {fallen:.1f} R\nt U$_{{St}}$/R = {t * cloud.stokes / radius:.1f}", fontsize=8)
        for i, (xlabel, ylabel, ylim) in enumerate([("x/R", "z/R", (-3.0, 2.0)), ("x/R", "z/R", (-3.0, 2.0)),
                                                     ("x/R", "y/R", (-2.2, 2.2))]):
            ax = axes[i, j]
            ax.set_xlim(-2.2, 2.2)
            ax.set_ylim(*ylim)
            ax.set_aspect("equal")
            ax.tick_params(labelsize=7)
            ax.set_xlabel(xlabel, fontsize=7)
            if j == 0:
                ax.set_ylabel(ylabel, fontsize=7)
    axes[0, 0].text(-2.1, 1.5, "side view", fontsize=7)
    axes[1, 0].text(-2.1, 1.5, "slice |y| < R/4", fontsize=7)
    axes[2, 0].text(-2.1, 1.8, "top view, |z| < 1.5 R", fontsize=7)
    velocity = -np.gradient(centroid, times)
    gs = axes[0, -1].get_gridspec()
    for ax in axes[:, -1]:
        ax.remove()
    ax = fig.add_subplot(gs[:, -1])
    fallen = (centroid[0] - centroid) / radius
    ax.plot(fallen, velocity / cloud.stokes, color="k", lw=1, label="centroid (fulldem)")
    ax.axhline(cloud.nitsche_batchelor() / cloud.stokes, color="C1", ls="--", lw=1,
               label="1 + 1.2 N a/R (unbounded)")
    ax.axhline(cloud.reference() / cloud.stokes, color="C2", ls=":", lw=1.5, label="less box images (Hasimoto)")
    ax.axhline(1.0, color="0.5", lw=0.8, label="single droplet")
    ax.set_xlabel("fall distance / R", fontsize=8)
    ax.set_ylabel("cloud velocity / U$_{St}$", fontsize=8)
    ax.set_ylim(0, 1.15 * cloud.nitsche_batchelor() / cloud.stokes)
    ax.legend(fontsize=7, loc="lower right")
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    fig.suptitle(f"Falling cloud: N = {cloud.count} droplets of {cloud.diameter * 1e3:.1f} mm, N a/R = "
                 f"{cloud.n_a_over_r:.1f}, R = 4 cells, periodic {cloud.box / radius:.0f} R cube, cloud Re = "
                 f"{cloud.reynolds(float(np.median(velocity[len(velocity) // 4:]))):.2f}", fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    print(f"wrote {path}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-a-over-r", type=float, default=5.0)
    parser.add_argument("--duration", type=float, default=14.0, help="run time in settling times R / U_St")
    parser.add_argument("--reynolds", type=float, default=1.0, help="Nitsche-Batchelor cloud Reynolds number")
    parser.add_argument("--out", type=Path, default=ROOT / "reports" / "figures" / "fulldem_falling_cloud.png")
    args = parser.parse_args(argv)
    plot(*run(args.n_a_over_r, args.duration, args.reynolds), args.out)


if __name__ == "__main__":
    main()
