"""Figures of one snapshot: droplets on the central x-z slab coloured by diameter or speed (seed Figs. 8, 9, 12,
17, 18), the slag flow on that plane (Fig. 10), and every droplet's density or speed against its height (Figs. 20,
21). Each takes ``time`` [s] (the snapshot nearest it is drawn; None: the last) and ``ax`` (the caller's Axes;
None: a new Figure) and returns the Figure."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from . import paper
from .inputs import NoData, _case, _case_name, _finite, _need_case, axes, read_droplets, read_slag

#: Slab of :func:`slice_droplets`: half-thickness = max(SLAB_DIAMETERS mean diameters, SLAB_DEPTH_FRACTION x depth).
SLAB_DIAMETERS = 2.0
SLAB_DEPTH_FRACTION = 0.02
#: Largest number of arrows along each axis of :func:`slice_slag` (the grid is subsampled to this).
QUIVER_ARROWS = 20


def _droplets_present(run, time):
    t, frame = read_droplets(run, time)
    if frame.empty:
        raise NoData(f"no droplets in the snapshot at t = {t:g} s")
    return t, frame


def slab_half_thickness(diameter, depth) -> float:
    """Half-thickness [m] of the slab of :func:`slice_droplets`: max(SLAB_DIAMETERS x the number-mean of
    ``diameter`` [m], SLAB_DEPTH_FRACTION x ``depth`` [m])."""
    d = np.asarray(diameter, dtype=float)
    mean = float(np.nanmean(d)) if d.size and np.isfinite(d).any() else 0.0
    return max(SLAB_DIAMETERS * mean, SLAB_DEPTH_FRACTION * float(depth))


def slab(frame: pd.DataFrame, y_centre: float, depth: float) -> tuple[pd.DataFrame, float]:
    """The droplets of ``frame`` (from :func:`read_droplets`) whose centre lies within the slab abs(y - y_centre) <=
    half-thickness (:func:`slab_half_thickness` of all the frame's diameters and ``depth``), and that half-thickness
    [m]."""
    half = slab_half_thickness(frame["diameter"], depth)
    return frame[np.abs(frame["y"] - y_centre) <= half], half


#: Width [pt] the larger side of the box is drawn at in :func:`slice_droplets` (about 5 inches).
SLICE_BOX_POINTS = 360.0
#: Width [pt] of the largest droplet's marker at least (markers are drawn to scale where that is wider).
LARGEST_MARKER_POINTS = 4.0


def _marker_area(diameter, largest, box):
    """Scatter marker areas [pt^2] for droplets of ``diameter`` [m] (the largest ``largest`` [m]) in a box whose
    larger side is ``box`` [m]: widths proportional to diameter, to the scale of the axes where the largest marker
    is then at least LARGEST_MARKER_POINTS wide, else enlarged to that; none under 1 pt."""
    scale = max(SLICE_BOX_POINTS / float(box), LARGEST_MARKER_POINTS / max(float(largest), 1e-300))  # pt per m
    return np.maximum(scale * np.asarray(diameter, dtype=float), 1.0) ** 2


def slice_droplets(run, time=None, quantity="diameter", ax=None) -> Figure:
    """Seed Figs. 8, 9, 12, 17, 18: the droplets whose centre lies in a slab around the central x-z plane
    (y = the inlet centre's y, half-thickness :func:`slab_half_thickness`), drawn at their x, z [mm] with marker
    width proportional to diameter (to scale, unless that would draw the largest under LARGEST_MARKER_POINTS),
    coloured by ``quantity``: "diameter" [mm] or "velocity" (downward speed, -w, [mm/s]). Snapshot nearest ``time``
    [s] (None: the last)."""
    if quantity not in ("diameter", "velocity"):
        raise ValueError(f"quantity = {quantity!r}: allowed: 'diameter', 'velocity'")
    case = _need_case(run, "the inlet centre and the box")
    t, frame = _droplets_present(run, time)
    g = case.geometry
    y0 = case.inlet_center[1]
    inside, half = slab(frame, y0, g.depth)
    fig, (ax,) = axes(ax, 1, _slice_size(g.width, g.height))
    if quantity == "diameter":
        colour, label, cmap = 1e3 * inside["diameter"], "droplet diameter [mm]", "viridis"
    else:
        colour, label, cmap = 1e3 * inside["settling_velocity"], "downward speed [mm/s]", "plasma"
    points = ax.scatter(1e3 * inside["x"], 1e3 * inside["z"], c=colour, cmap=cmap,
                        s=_marker_area(inside["diameter"], frame["diameter"].max(), max(g.width, g.height)),
                        linewidths=0)
    fig.colorbar(points, ax=ax, label=label, shrink=0.85)
    ax.set_xlim(0.0, 1e3 * g.width)
    ax.set_ylim(0.0, 1e3 * g.height)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("height z [mm]")
    ax.set_title(f"{_case_name(run)}: droplet {'diameters' if quantity == 'diameter' else 'speeds'}, t = {t:g} s\n"
                 f"{len(inside)} of {len(frame)} droplets with |y − {1e3 * y0:g} mm| ≤ {1e3 * half:.3g} mm",
                 fontsize="medium")
    return fig


def _slice_size(width, height) -> tuple[float, float]:
    """Figure size [in] of an x-z view of a box ``width`` x ``height`` [m] with a colour bar: tall boxes, tall."""
    return (7, 6.2) if height <= 1.5 * width else (5, 8.5)


def slice_slag(run, time=None, ax=None) -> Figure:
    """Seed Fig. 10: the slag flow on the central x-z plane (y = the inlet centre's y; the cell layer nearest to it,
    or the mean of the two equally near): colour = speed abs(u) [mm/s], arrows = the in-plane velocity (u, w),
    subsampled to at most QUIVER_ARROWS per axis, white with a dark edge and a key giving their scale. Axes x, z
    [mm]. Snapshot nearest ``time`` [s] (None: the last)."""
    case = _need_case(run, "the inlet centre")
    t, centres, velocity = read_slag(run, time)
    y0 = case.inlet_center[1]
    distance = np.abs(centres[:, 1] - y0)
    spacing = _spacing(centres)
    layer = distance <= distance.min() + 1e-6 * spacing
    frame = pd.DataFrame({"i": np.rint(centres[layer, 0] / spacing).astype(int),
                          "k": np.rint(centres[layer, 2] / spacing).astype(int),
                          "x": centres[layer, 0], "z": centres[layer, 2], "u": velocity[layer, 0],
                          "v": velocity[layer, 1], "w": velocity[layer, 2]}).groupby(["i", "k"]).mean()
    grid = {c: frame[c].unstack("i").to_numpy() for c in ("x", "z", "u", "v", "w")}  # rows z, columns x
    speed = 1e3 * np.sqrt(grid["u"] ** 2 + grid["v"] ** 2 + grid["w"] ** 2)
    fig, (ax,) = axes(ax, 1, _slice_size(np.ptp(centres[:, 0]) + spacing, np.ptp(centres[:, 2]) + spacing))
    mesh = ax.pcolormesh(1e3 * grid["x"], 1e3 * grid["z"], speed, shading="nearest", cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="slag speed |u| [mm/s]", shrink=0.85)
    step = [max(1, int(math.ceil(n / QUIVER_ARROWS))) for n in speed.shape]
    sub = (slice(None, None, step[0]), slice(None, None, step[1]))
    largest = float(np.nanmax(np.hypot(grid["u"], grid["w"])))
    if largest > 0.0:  # slag at rest: no arrows (quiver cannot scale them)
        arrows = ax.quiver(1e3 * grid["x"][sub], 1e3 * grid["z"][sub], 1e3 * grid["u"][sub], 1e3 * grid["w"][sub],
                           color="white", edgecolor="black", linewidth=0.6, width=0.006)
        key = float(f"{1e3 * largest / 2:.1g}")  # a round speed about half the largest [mm/s]
        ax.quiverkey(arrows, 0.82, 1.025, key, f"{key:g} mm/s", labelpos="E", coordinates="axes", color="black")
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("height z [mm]")
    ax.set_title(f"{_case_name(run)}: slag flow at y = {1e3 * float(centres[layer, 1].mean()):.3g} mm, t = {t:g} s",
                 fontsize="medium", loc="left")
    return fig


def _spacing(centres) -> float:
    """The grid spacing [m]: the smallest gap between distinct cell-centre coordinates (1 m if there is none)."""
    gaps = [np.diff(np.unique(centres[:, a])) for a in range(3)]
    gaps = np.concatenate([g[g > 0] for g in gaps])
    return float(gaps.min()) if gaps.size else 1.0


def _height_scatter(run, time, column, scale, ylabel, what, ax=None):
    t, frame = _droplets_present(run, time)
    if not _finite(frame, column):
        raise NoData(f"the droplets at t = {t:g} s have no {column}")
    fig, (ax,) = axes(ax, 1, (7, 4.6))
    size = float(np.clip(4000.0 / len(frame), 2.0, 16.0))  # small markers for a crowd, visible ones for a few
    ax.scatter(1e3 * frame["z"], scale * frame[column], s=size, alpha=0.6, linewidths=0)
    ax.set_xlabel("height z [mm]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.set_title(f"{_case_name(run)}: {what} of {len(frame)} droplets, t = {t:g} s", fontsize="medium")
    return fig


def density_height(run, time=None, ax=None) -> Figure:
    """Seed Fig. 20: every droplet's density [kg/m^3] against its height z [mm], with the paper's range of matte
    densities (:data:`paper.DENSITY_RANGE`) where the run's reactions are on. Snapshot nearest ``time`` [s] (None:
    the last)."""
    fig = _height_scatter(run, time, "density", 1.0, "droplet density [kg/m³]", "density vs height", ax)
    case = _case(run)
    if case is not None and case.reaction.enabled:
        axis = fig.axes[0] if ax is None else ax
        paper.draw_density_range(axis)
        axis.legend(fontsize="small", loc="lower right")
    return fig


def velocity_height(run, time=None, ax=None) -> Figure:
    """Seed Fig. 21: every droplet's downward speed (-w) [mm/s] against its height z [mm]. Snapshot nearest
    ``time`` [s] (None: the last)."""
    return _height_scatter(run, time, "settling_velocity", 1e3, "downward speed [mm/s]", "settling speed vs height",
                           ax)


