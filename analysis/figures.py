"""The seed paper's figures (Jylhä & Jokilaakso, Heliyon 9 (2023) e21570) drawn from a stored run folder.

A run folder is what ``settler full CASE --out RUN`` writes (SI units throughout): ``timeseries.csv`` (columns of
:data:`settler.output.TIME_SERIES`), ``snapshots.pvd`` listing ``droplets_NNNNN.vtu`` (part 0) and
``fluid_NNNNN.vtu`` (part 1) per snapshot time, ``channel_profile.csv``, ``case.toml`` and ``metadata.json``.
This module reads those files only (pandas, NumPy, meshio, matplotlib); it never imports an engine, so it works on
a machine where none is built, on a finished run, a stopped one or one still running.

One function per figure returns a :class:`matplotlib.figure.Figure` (made without pyplot, so drawing needs no
display and no backend is switched; PNGs are written by the Agg canvas):

=================================  =====================================================================  ===========
function                           what                                                                   seed paper
=================================  =====================================================================  ===========
:func:`droplet_counts`             total, coalesced and never-coalesced droplets vs time                  Fig. 15
:func:`centre_diameter_velocity`   mean diameter and centreline settling velocity vs time                 Fig. 11
:func:`settling_velocity`          mean settling velocity vs time                                         Fig. 16
:func:`slice_droplets`             droplets in a thin slab around the central x-z plane, coloured by      Figs. 8, 9,
                                   diameter or downward speed                                             12, 17, 18
:func:`slice_slag`                 slag speed and in-plane arrows on the central x-z plane                Fig. 10
:func:`density_height`             every droplet's density vs its height                                  Fig. 20
:func:`velocity_height`            every droplet's downward speed vs its height                           Fig. 21
:func:`channel`                    channel radius and axis velocity vs time, and vs height                (ours)
=================================  =====================================================================  ===========

:func:`render_all` writes them all as PNGs (``settler figures RUN --out DIR`` calls it). A figure whose inputs
are missing (an old or partial run, a snapshot without droplets, a column that is all NaN) raises :class:`NoData`
with a one-line reason; :func:`render_all` records that reason and goes on with the others.

Snapshot figures take ``time`` [s]: the snapshot nearest to it is drawn (default: the last one); the title gives
the snapshot's own time. The central plane is y = the inlet centre's y (``geometry.inlet_center`` of ``case.toml``,
default the middle of the depth).
"""

from __future__ import annotations

import argparse
import io
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from settler.output import atomic_write_bytes, read_time_series

from .files import NoData, check_run, droplets_file, pick_snapshot, slag_file, snapshot_files


#: The files :func:`render_all` writes: figure name -> PNG file name (the seed paper's figure number where it has one).
FIGURE_FILES = {
    "droplet_counts": "fig15_droplet_counts.png",
    "centre_diameter_velocity": "fig11_centre_diameter_velocity.png",
    "settling_velocity": "fig16_settling_velocity.png",
    "slice_diameter": "slice_diameter.png",
    "slice_velocity": "slice_velocity.png",
    "slice_slag": "fig10_slice_slag.png",
    "density_height": "fig20_density_height.png",
    "velocity_height": "fig21_velocity_height.png",
    "channel": "channel.png",
    "zones": "zones.png",
}
#: Resolution of the PNGs of :func:`render_all` [dots per inch].
DPI = 120
#: Slab of :func:`slice_droplets`: half-thickness = max(SLAB_DIAMETERS mean diameters, SLAB_DEPTH_FRACTION x depth).
SLAB_DIAMETERS = 2.0
SLAB_DEPTH_FRACTION = 0.02
#: Largest number of arrows along each axis of :func:`slice_slag` (the grid is subsampled to this).
QUIVER_ARROWS = 20


# ------------------------------------------------------------------------------------------------------- readers
def _reference(run):
    """The stored reference (analysis.reference) if ``run`` is a ``data/reference/<case>`` folder, else None."""
    folder = check_run(run)
    if not ((folder / "snapshots.npz").is_file() and (folder / "reference.json").is_file()):
        return None
    from .reference import load_reference

    return load_reference(folder.name, folder.parent)


def _reference_snapshot(reference, time):
    """(index, time [s]) of a stored reference's snapshot nearest ``time`` (None: the last)."""
    times = np.asarray(reference.snapshot_times, dtype=float)
    if times.size == 0:
        raise NoData("no snapshots stored in this reference")
    if time is None:
        k = times.size - 1
    else:
        time = float(time)
        if not math.isfinite(time):
            raise ValueError(f"time = {time!r}: give a finite snapshot time [s]")
        k = int(min(range(times.size), key=lambda q: (abs(times[q] - time), -times[q])))
    return k, float(times[k])


def read_droplets(run, time=None) -> tuple[float, pd.DataFrame]:
    """The droplets of the snapshot nearest ``time`` [s] (None: the last): (its time [s], DataFrame).

    Columns (SI units, one row per droplet): x, y, z [m] (centre), diameter [m], u, v, w [m/s] (velocity),
    settling_velocity [m/s] (= -w, downward positive), density [kg/m^3], age [s], and where the file holds them
    ident [-] and merged (1.0 if the droplet was formed by coalescence, else 0.0; newer runs only). A snapshot
    without droplets gives an empty frame with these columns. Raises NoData if there is no such snapshot file.
    """
    reference = _reference(run)
    if reference is not None:  # a stored reference: its float32 snapshots
        k, t = _reference_snapshot(reference, time)
        return t, reference.droplets(k)
    t, path = pick_snapshot(run, time, 0)
    return t, droplets_file(path)


def read_slag(run, time=None) -> tuple[float, np.ndarray, np.ndarray]:
    """The slag grid of the snapshot nearest ``time`` [s] (None: the last): (its time [s], cell centres (n, 3) [m],
    cell velocity (n, 3) [m/s]). A cell's centre is the mean of its 8 corner points. Raises NoData if there is no
    such snapshot file or it holds no hexahedra with a velocity."""
    reference = _reference(run)
    if reference is not None:  # a stored reference keeps the central x-z plane only
        k, t = _reference_snapshot(reference, time)
        x, z, velocity = reference.slag(k)
        if len(x) == 0:
            raise NoData(f"the stored snapshot at t = {t:g} s has no slag plane")
        centres = np.column_stack([x, np.full(len(x), reference.slag_plane_y(k)), z]).astype(float)
        return t, centres, np.asarray(velocity, dtype=float).reshape(-1, 3)
    t, path = pick_snapshot(run, time, 1)
    centres, velocity = slag_file(path)
    return t, centres, velocity


def _time_series(run) -> pd.DataFrame:
    path = check_run(run) / "timeseries.csv"
    if not path.is_file():
        raise NoData("no timeseries.csv")
    frame = read_time_series(path)
    if "time" not in frame or frame.empty:
        raise NoData("timeseries.csv has no rows" if "time" in frame else "timeseries.csv has no time column")
    return frame


def _channel_profile(run) -> pd.DataFrame:
    path = check_run(run) / "channel_profile.csv"
    if not path.is_file():
        raise NoData("no channel_profile.csv")
    try:
        from settler.output import read_channel_profile
    except ImportError:  # an older settler: the same CSV reading
        def read_channel_profile(p):
            return pd.read_csv(p, comment="#")
    return read_channel_profile(path)


def _case(run):
    """The run's resolved case from ``case.toml``, or None if it is missing or cannot be read."""
    from settler.cases import CaseError, load_case

    path = check_run(run) / "case.toml"
    if not path.is_file():
        return None
    try:
        return load_case(path)
    except (CaseError, OSError, ValueError):
        return None


def _case_name(run) -> str:
    case = _case(run)
    return case.case.name if case is not None and getattr(case.case, "name", None) else Path(run).resolve().name


def _need_case(run, what):
    case = _case(run)
    if case is None:
        raise NoData(f"no readable case.toml (needed for {what})")
    return case


def _finite(frame, column) -> bool:
    return column in frame and bool(np.isfinite(frame[column].to_numpy(dtype=float)).any())


def _need_columns(frame, columns, figure):
    present = [c for c in columns if _finite(frame, c)]
    if not present:
        raise NoData(f"timeseries.csv has no values of {', '.join(columns)} (needed for {figure})")
    return present


# ----------------------------------------------------------------------------------------- time-series figures
def droplet_counts(run) -> Figure:
    """Seed Fig. 15: droplets in the slag vs time [s]: all of them, those formed by coalescence and those that never
    coalesced (columns droplet_count, coalesced_count, uncoalesced_count; a column that is all NaN is left out)."""
    ts = _time_series(run)
    labels = {"droplet_count": "all droplets", "coalesced_count": "formed by coalescence",
              "uncoalesced_count": "never coalesced"}
    present = _need_columns(ts, list(labels), "the droplet counts")
    fig = Figure(figsize=(7, 4.2), layout="constrained")
    ax = fig.add_subplot()
    for column in present:
        ax.plot(ts["time"], ts[column], label=labels[column])
    ax.set_xlabel("time [s]")
    ax.set_ylabel("droplets in the slag [-]")
    ax.legend()
    ax.grid(alpha=0.3)
    ax.set_title(f"{_case_name(run)}: droplets in the slag, t = 0–{ts['time'].iloc[-1]:g} s")
    return fig


def centre_diameter_velocity(run) -> Figure:
    """Seed Fig. 11: number-mean droplet diameter [mm] (and Sauter d32) and the centreline settling velocity [mm/s]
    (droplets within one inlet radius of the inlet axis at mid-height, downward positive) vs time [s], two panels."""
    ts = _time_series(run)
    _need_columns(ts, ["mean_diameter", "centreline_settling_velocity"], "the diameter and centre velocity")
    fig = Figure(figsize=(7, 6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    for column, label in (("mean_diameter", "number mean"), ("sauter_diameter", "Sauter d32")):
        if _finite(ts, column):
            top.plot(ts["time"], 1e3 * ts[column], label=label)
    top.set_ylabel("droplet diameter [mm]")
    top.legend()
    if _finite(ts, "centreline_settling_velocity"):
        bottom.plot(ts["time"], 1e3 * ts["centreline_settling_velocity"], color="C3")
    else:
        bottom.text(0.5, 0.5, "no centreline velocity in timeseries.csv", ha="center", transform=bottom.transAxes)
    bottom.set_ylabel("centreline settling velocity\n(downward) [mm/s]")
    bottom.set_xlabel("time [s]")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    top.set_title(f"{_case_name(run)}: droplet size and velocity at the centre, t = 0–{ts['time'].iloc[-1]:g} s")
    return fig


def settling_velocity(run) -> Figure:
    """Seed Fig. 16: number-mean settling velocity of the droplets in the slag [mm/s] (downward positive) vs time
    [s] (column mean_settling_velocity)."""
    ts = _time_series(run)
    _need_columns(ts, ["mean_settling_velocity"], "the settling velocity")
    fig = Figure(figsize=(7, 4.2), layout="constrained")
    ax = fig.add_subplot()
    ax.plot(ts["time"], 1e3 * ts["mean_settling_velocity"])
    ax.set_xlabel("time [s]")
    ax.set_ylabel("mean settling velocity (downward) [mm/s]")
    ax.grid(alpha=0.3)
    ax.set_title(f"{_case_name(run)}: mean settling velocity, t = 0–{ts['time'].iloc[-1]:g} s")
    return fig


def channel(run, time=None) -> Figure:
    """The channel (our measure; the seed paper describes it in words, section 4): left, the channel radius [mm]
    (radius around the inlet axis holding half the droplet volume at mid-height) and the downward slag velocity
    on the axis there [mm/s] vs time [s] (timeseries.csv); right, both vs height [mm] at the snapshot nearest
    ``time`` (None: the last) from channel_profile.csv. A panel whose file or columns are missing says so; the
    figure is skipped (NoData) only if both are."""
    reasons = []
    try:
        ts = _time_series(run)
        _need_columns(ts, ["channel_radius", "channel_velocity"], "the channel")
    except NoData as exc:
        ts, reasons = None, [str(exc)]
    try:
        profile = _channel_profile(run)
        if profile.empty or "time" not in profile or "z" not in profile:
            raise NoData("channel_profile.csv has no rows")
    except NoData as exc:
        profile = None
        reasons.append(str(exc))
    if ts is None and profile is None:
        raise NoData("; ".join(reasons))
    fig = Figure(figsize=(12, 4.6), layout="constrained")
    left, right = fig.subplots(1, 2)
    name = _case_name(run)

    def two_axes(ax, axis, radius, velocity, vertical):
        """radius [m] and velocity [m/s] against ``axis`` (time [s] across, or height [mm] upwards)."""
        other = ax.twiny() if vertical else ax.twinx()

        def draw(a, values, **kw):
            return a.plot(values, axis, marker="o", **kw) if vertical else a.plot(axis, values, **kw)

        lines = draw(ax, 1e3 * radius, color="C0", label="channel radius")
        lines += draw(other, 1e3 * velocity, color="C3", label="axis slag velocity (downward)")
        (ax.set_xlabel if vertical else ax.set_ylabel)("channel radius [mm]", color="C0")
        (other.set_xlabel if vertical else other.set_ylabel)("axis slag velocity (downward) [mm/s]", color="C3")
        ax.legend(lines, [line.get_label() for line in lines], loc="best", fontsize="small")
        ax.grid(alpha=0.3)

    if ts is not None:
        two_axes(left, ts["time"], ts.get("channel_radius", np.nan * ts["time"]),
                 ts.get("channel_velocity", np.nan * ts["time"]), vertical=False)
        left.set_xlabel("time [s]")
        left.set_title(f"{name}: at mid-height, t = 0–{ts['time'].iloc[-1]:g} s", fontsize="medium")
    else:
        left.text(0.5, 0.5, reasons[0], ha="center", wrap=True, transform=left.transAxes)
        left.set_axis_off()
    if profile is not None:
        times = np.unique(profile["time"].to_numpy(dtype=float))
        t = times[-1] if time is None else times[np.argmin(np.abs(times - float(time)))]
        rows = profile[profile["time"] == t].sort_values("z")
        two_axes(right, 1e3 * rows["z"], rows.get("channel_radius", np.nan * rows["z"]),
                 rows.get("channel_velocity", np.nan * rows["z"]), vertical=True)
        right.set_ylabel("height above the bottom [mm]")
        right.set_title(f"{name}: profile at t = {t:g} s", fontsize="medium")
    else:
        right.text(0.5, 0.5, reasons[-1], ha="center", wrap=True, transform=right.transAxes)
        right.set_axis_off()
    return fig


def _table(run, name) -> pd.DataFrame | None:
    path = check_run(run) / name
    if not path.is_file():
        return None
    frame = pd.read_csv(path, comment="#")
    return frame if len(frame) else None


def zones(run) -> Figure:
    """The zone diagnostics of a full run (:data:`settler.output.ZONE_PROFILE`, ZONES, LIFT_BY_SIZE), profiles
    averaged over the snapshots of the last third of the run: the channel (core) radius and the return radius
    against height, with the column's equivalent radius sqrt(W D / pi); the slag's upward and downward volume flux
    against height; the roof layer's thickness and the droplets moving up against time; and the share of each size
    moving up. Skipped (NoData) for a run without zone files (popbal runs, runs made before they existed)."""
    profile, scalars, lift = (_table(run, n) for n in ("zone_profile.csv", "zones.csv", "lift_by_size.csv"))
    if profile is None or scalars is None:
        raise NoData("no zone_profile.csv / zones.csv (full runs write them at every snapshot)")
    channel_rows = _table(run, "channel_profile.csv")
    name = _case_name(run)
    end = float(profile["time"].max())
    late = profile[profile["time"] >= end * 2.0 / 3.0]
    mean = late.groupby("z").mean(numeric_only=True).reset_index()
    fig = Figure(figsize=(12, 8.5), layout="constrained")
    (radius_ax, flux_ax), (roof_ax, lift_ax) = fig.subplots(2, 2)
    window = f"t = {late['time'].min():g}–{end:g} s"
    if channel_rows is not None:
        core = channel_rows[channel_rows["time"] >= end * 2.0 / 3.0].groupby("z").mean(numeric_only=True)
        radius_ax.plot(1e3 * core["channel_radius"], 1e3 * core.index, "o-", color="C0", label="channel (core) radius")
    radius_ax.plot(1e3 * mean["return_radius"], 1e3 * mean["z"], "s-", color="C3", label="return radius (flow turns up)")
    case = _case(run)
    if case is not None:
        radius_ax.axvline(1e3 * math.sqrt(case.geometry.width * case.geometry.depth / math.pi), color="0.5", ls="--",
                          label="column radius sqrt(W D / pi)")
    radius_ax.set_xlabel("radius from the inlet axis [mm]")
    radius_ax.set_ylabel("height above the bottom [mm]")
    radius_ax.set_title(f"{name}: plume core and return flow, mean over {window}", fontsize="medium")
    radius_ax.legend(fontsize="small")
    flux_ax.plot(1e6 * mean["upward_slag_flux"], 1e3 * mean["z"], "o-", color="C1", label="upward")
    flux_ax.plot(1e6 * mean["downward_slag_flux"], 1e3 * mean["z"], "o-", color="C2", label="downward")
    flux_ax.set_xlabel("slag volume flux through the plane [cm^3/s]")
    flux_ax.set_ylabel("height above the bottom [mm]")
    flux_ax.set_title(f"slag flux, mean over {window}", fontsize="medium")
    flux_ax.legend(fontsize="small")
    roof_ax.plot(scalars["time"], 1e3 * scalars["roof_thickness"], "o-", color="C0", label="roof layer thickness")
    roof_ax.set_xlabel("time [s]")
    roof_ax.set_ylabel("roof layer thickness under the inlet [mm]", color="C0")
    other = roof_ax.twinx()
    other.plot(scalars["time"], scalars["rising_count"], "s-", color="C3", label="droplets moving up")
    other.set_ylabel("droplets moving up (below the insertion layer)", color="C3")
    roof_ax.set_title("roof layer and lift-back", fontsize="medium")
    if lift is not None:
        late_lift = lift[lift["time"] >= end * 2.0 / 3.0]
        by = late_lift.groupby(["diameter_low", "diameter_high"])[["count", "rising_count"]].sum().reset_index()
        by = by[by["count"] > 0]
        centre = np.sqrt(by["diameter_low"].clip(lower=1e-6) * by["diameter_high"].replace(np.inf, np.nan)
                         .fillna(by["diameter_low"] * 2 ** (1 / 3)))
        lift_ax.semilogx(1e3 * centre, by["rising_count"] / by["count"], "o-")
        lift_ax.set_xlabel("droplet diameter [mm] (bin centre)")
        lift_ax.set_ylabel("share moving up [-]")
        lift_ax.set_title(f"droplets carried up by size, {window}", fontsize="medium")
    else:
        lift_ax.text(0.5, 0.5, "no lift_by_size.csv", ha="center", transform=lift_ax.transAxes)
        lift_ax.set_axis_off()
    for ax in (radius_ax, flux_ax, roof_ax, lift_ax):
        ax.grid(alpha=0.3)
    return fig


# ---------------------------------------------------------------------------------------------- snapshot figures
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
    """The droplets of ``frame`` (from :func:`read_droplets`) whose centre lies within the slab |y - y_centre| <=
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


def slice_droplets(run, time=None, quantity="diameter") -> Figure:
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
    fig = _slice_figure(g.width, g.height)
    ax = fig.add_subplot()
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


def _slice_figure(width, height) -> Figure:
    """A figure for an x-z view of a box ``width`` x ``height`` [m] with a colour bar: tall boxes get a tall one."""
    return Figure(figsize=(7, 6.2) if height <= 1.5 * width else (5, 8.5), layout="constrained")


def slice_slag(run, time=None) -> Figure:
    """Seed Fig. 10: the slag flow on the central x-z plane (y = the inlet centre's y; the cell layer nearest to it,
    or the mean of the two equally near): colour = speed |u| [mm/s], arrows = the in-plane velocity (u, w),
    subsampled to at most QUIVER_ARROWS per axis. Axes x, z [mm]. Snapshot nearest ``time`` [s] (None: the last)."""
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
    fig = _slice_figure(np.ptp(centres[:, 0]) + spacing, np.ptp(centres[:, 2]) + spacing)
    ax = fig.add_subplot()
    mesh = ax.pcolormesh(1e3 * grid["x"], 1e3 * grid["z"], speed, shading="nearest", cmap="viridis")
    fig.colorbar(mesh, ax=ax, label="slag speed |u| [mm/s]", shrink=0.85)
    step = [max(1, int(math.ceil(n / QUIVER_ARROWS))) for n in speed.shape]
    sub = (slice(None, None, step[0]), slice(None, None, step[1]))
    if np.nanmax(np.hypot(grid["u"], grid["w"])) > 0.0:  # slag at rest: no arrows (quiver cannot scale them)
        ax.quiver(1e3 * grid["x"][sub], 1e3 * grid["z"][sub], 1e3 * grid["u"][sub], 1e3 * grid["w"][sub],
                  color="white", alpha=0.85)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("height z [mm]")
    ax.set_title(f"{_case_name(run)}: slag flow at y = {1e3 * float(centres[layer, 1].mean()):.3g} mm, t = {t:g} s",
                 fontsize="medium")
    return fig


def _spacing(centres) -> float:
    """The grid spacing [m]: the smallest gap between distinct cell-centre coordinates (1 m if there is none)."""
    gaps = [np.diff(np.unique(centres[:, a])) for a in range(3)]
    gaps = np.concatenate([g[g > 0] for g in gaps])
    return float(gaps.min()) if gaps.size else 1.0


def _height_scatter(run, time, column, scale, ylabel, what):
    t, frame = _droplets_present(run, time)
    if not _finite(frame, column):
        raise NoData(f"the droplets at t = {t:g} s have no {column}")
    fig = Figure(figsize=(7, 4.6), layout="constrained")
    ax = fig.add_subplot()
    size = float(np.clip(4000.0 / len(frame), 2.0, 16.0))  # small markers for a crowd, visible ones for a few
    ax.scatter(1e3 * frame["z"], scale * frame[column], s=size, alpha=0.6, linewidths=0)
    ax.set_xlabel("height z [mm]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.set_title(f"{_case_name(run)}: {what} of {len(frame)} droplets, t = {t:g} s", fontsize="medium")
    return fig


def density_height(run, time=None) -> Figure:
    """Seed Fig. 20: every droplet's density [kg/m^3] against its height z [mm]. Snapshot nearest ``time`` [s]
    (None: the last)."""
    return _height_scatter(run, time, "density", 1.0, "droplet density [kg/m³]", "density vs height")


def velocity_height(run, time=None) -> Figure:
    """Seed Fig. 21: every droplet's downward speed (-w) [mm/s] against its height z [mm]. Snapshot nearest
    ``time`` [s] (None: the last)."""
    return _height_scatter(run, time, "settling_velocity", 1e3, "downward speed [mm/s]", "settling speed vs height")


# ------------------------------------------------------------------------------------------------------ all of them
def figure_functions(time=None) -> dict:
    """Figure name (key of :data:`FIGURE_FILES`) -> a function of the run folder that draws it (snapshot figures at
    the snapshot nearest ``time`` [s], None: the last)."""
    return {
        "droplet_counts": droplet_counts,
        "centre_diameter_velocity": centre_diameter_velocity,
        "settling_velocity": settling_velocity,
        "slice_diameter": lambda run: slice_droplets(run, time, "diameter"),
        "slice_velocity": lambda run: slice_droplets(run, time, "velocity"),
        "slice_slag": lambda run: slice_slag(run, time),
        "density_height": lambda run: density_height(run, time),
        "velocity_height": lambda run: velocity_height(run, time),
        "channel": lambda run: channel(run, time),
        "zones": zones,
    }


def render_all(run, out_dir, time=None) -> dict[str, Path | str]:
    """Draw every figure of the run folder ``run`` and write it as a PNG (:data:`DPI`) into ``out_dir`` (created),
    named as in :data:`FIGURE_FILES`; snapshot figures at the snapshot nearest ``time`` [s] (None: the last).

    Returns figure name -> the written path, or -> the one-line reason it was skipped (its inputs are missing or
    unreadable). Raises FileNotFoundError if ``run`` is not a run folder (no timeseries.csv and no snapshots.pvd).
    """
    run = check_run(run)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results: dict[str, Path | str] = {}
    for name, draw in figure_functions(time).items():
        try:
            fig = draw(run)
        except NoData as exc:
            results[name] = str(exc)
            continue
        except (OSError, ValueError, KeyError, ET.ParseError) as exc:  # an unreadable file of a partial run
            text = " ".join(str(exc).split())
            results[name] = f"an input could not be read ({type(exc).__name__}: {text[:160]})"
            continue
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png", dpi=DPI)
        fig.clear()  # made without pyplot: nothing to close, release its artists
        path = out_dir / FIGURE_FILES[name]
        atomic_write_bytes(path, buffer.getvalue())
        results[name] = path
    return results


# ------------------------------------------------------------------------------------------------ command line
def _finite_time(text):
    """--time: a finite number of seconds (argparse refuses anything else with exit status 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give a snapshot time in seconds") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"{text!r}: give a finite snapshot time in seconds")
    return value


def add_arguments(parser):
    """The arguments of ``settler figures`` (registered in :data:`settler.cli.TOOLS`)."""
    parser.add_argument("run", help="the output folder of a 'settler full' run (holding timeseries.csv and/or "
                                    "snapshots.pvd)")
    parser.add_argument("--out", metavar="DIR", default=None, help="folder to write the PNGs into (default: "
                                                                  "RUN/figures; created if missing)")
    parser.add_argument("--time", metavar="T", type=_finite_time, default=None,
                        help="snapshot time [s] of the snapshot figures: the nearest snapshot is drawn (default: "
                             "the last)")


def main(args) -> int:
    """``settler figures RUN [--out DIR] [--time T]``: every figure as a PNG; the exit status."""
    from settler.output import OutputError, prepare_output_folder

    try:
        run = check_run(args.run)
    except FileNotFoundError as exc:  # not a run: refused input (exit 2), not a failed run
        raise OutputError(str(exc)) from None
    # resume=True: only the checks (a file, not writable); the folder may hold anything, the run itself included
    out = prepare_output_folder(args.out if args.out is not None else Path(run) / "figures", resume=True)
    try:
        times = [t for t, _, _ in snapshot_files(run)] if args.time is not None else []
    except NoData:  # an unreadable snapshots.pvd: render_all says so for each snapshot figure
        times = []
    if times:
        nearest = min(times, key=lambda t: (abs(t - args.time), -t))
        if nearest != args.time:
            print(f"snapshot figures at t = {nearest:g} s, the snapshot nearest --time {args.time:g}")
    results = render_all(run, out, time=args.time)
    width = max(len(name) for name in results)
    for name, result in results.items():
        print(f"{name:<{width}s}  {result}" if isinstance(result, Path) else f"{name:<{width}s}  skipped: {result}")
    if not any(isinstance(result, Path) for result in results.values()):
        raise OutputError(f"{run}: no figure could be drawn (reasons above)")
    return 0
