"""Pictures of a run, written beside its outputs: the time series and a side view of the droplets.

Plotting stays apart from running: these functions read what a run wrote (or take arrays) and draw.
"""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib


matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from settler.output import atomic_write_bytes, read_time_series  # noqa: E402


def _save(fig, path):
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def plot_time_series(out_dir, title=""):
    """timeseries.png: droplet count, diameters, settling velocities and the matte mass accounting over time."""
    out_dir = Path(out_dir)
    ts = read_time_series(out_dir / "timeseries.csv")
    t = ts["time"]
    fig, ax = plt.subplots(1, 4, figsize=(17, 3.6))
    ax[0].plot(t, ts["droplet_count"])
    ax[0].set_ylabel("droplets in slag [-]")
    ax[1].plot(t, 1e6 * ts["mean_diameter"], label="number mean")
    ax[1].plot(t, 1e6 * ts["sauter_diameter"], label="Sauter d32")
    ax[1].set_ylabel("diameter [µm]")
    ax[1].legend()
    ax[2].plot(t, 1e3 * ts["mean_settling_velocity"], label="mean")
    ax[2].plot(t, 1e3 * ts["centreline_settling_velocity"], label="centreline, mid-height")
    ax[2].set_ylabel("settling velocity [mm/s]")
    ax[2].legend()
    for column, label in (("mass_fed", "fed"), ("mass_in_slag", "in slag"), ("mass_settled", "settled"),
                          ("mass_lost", "lost")):
        ax[3].plot(t, 1e3 * ts[column], label=label)
    ax[3].set_ylabel("matte mass [g]")
    ax[3].legend()
    for a in ax:
        a.set_xlabel("time [s]")
        a.grid(alpha=0.3)
    fig.suptitle(title)
    _save(fig, out_dir / "timeseries.png")


def plot_droplets(path, position, diameter, velocity, box_lower, box_upper, title=""):
    """A side view (x-z) and a top view (x-y) of the droplets, coloured by settling velocity [mm/s]."""
    fig, ax = plt.subplots(1, 2, figsize=(11, 5))
    down = -1e3 * velocity[:, 2] if len(velocity) else np.zeros(0)
    size = np.clip((diameter / 5e-4) ** 2 * 2.0, 0.5, 30.0)
    for a, (i, j, name) in zip(ax, ((0, 2, "side view (x-z)"), (0, 1, "top view (x-y)"))):
        sc = a.scatter(position[:, i], position[:, j], s=size, c=down, cmap="viridis", linewidths=0)
        a.set_xlim(box_lower[i], box_upper[i])
        a.set_ylim(box_lower[j], box_upper[j])
        a.set_aspect("equal")
        a.set_xlabel("xyz"[i] + " [m]")
        a.set_ylabel("xyz"[j] + " [m]")
        a.set_title(name)
    fig.colorbar(sc, ax=ax, label="settling velocity [mm/s]", shrink=0.8)
    fig.suptitle(title)
    _save(fig, path)
