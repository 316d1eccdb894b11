"""Figures of a run's time series and profiles: droplet counts (seed Fig. 15), size and centre velocity (Fig. 11),
settling velocity (Fig. 16), the channel and the zone diagnostics. Each takes ``ax`` (draw into the caller's Axes,
to overlay runs; None: a new Figure) and ``label`` (what the run is called in the legend; default: its case name
when drawn into given axes, nothing otherwise) and returns the Figure."""

from __future__ import annotations

import math

import numpy as np
from matplotlib.figure import Figure

from . import paper
from .inputs import NoData, _case, _case_name, _channel_profile, _finite, _need_columns, _table, _time_series, axes


def _prefix(run, ax, label):
    """The legend prefix of a run: ``label``, else its case name when drawn into given axes, else nothing."""
    if label is None:
        label = _case_name(run) if ax is not None else ""
    return f"{label}: " if label else ""


def droplet_counts(run, ax=None, label=None) -> Figure:
    """Seed Fig. 15: droplets in the slag vs time [s]: all of them, those formed by coalescence and those that never
    coalesced (columns droplet_count, coalesced_count, uncoalesced_count; a column that is all NaN is left out),
    with the paper's steady count (:data:`paper.STEADY_COUNT`) for the simple and cubic cases."""
    ts = _time_series(run)
    labels = {"droplet_count": "all droplets", "coalesced_count": "formed by coalescence",
              "uncoalesced_count": "never coalesced"}
    present = _need_columns(ts, list(labels), "the droplet counts")
    fig, (axis,) = axes(ax, 1, (7, 4.2))
    prefix = _prefix(run, ax, label)
    for column in present:
        axis.plot(ts["time"], ts[column], label=prefix + labels[column])
    paper.draw_steady_count(axis, _case_name(run))
    axis.set_xlabel("time [s]")
    axis.set_ylabel("droplets in the slag [-]")
    axis.legend(fontsize="small")
    axis.grid(alpha=0.3)
    axis.set_title(f"{_case_name(run)}: droplets in the slag, t = 0–{ts['time'].iloc[-1]:g} s")
    return fig


def centre_diameter_velocity(run, ax=None, label=None) -> Figure:
    """Seed Fig. 11: number-mean droplet diameter [mm] (and Sauter d32) with the run's coalescence size limit, and
    the centreline settling velocity [mm/s] (droplets within one inlet radius of the inlet axis at mid-height,
    downward positive) vs time [s]: two panels (``ax``: two Axes, top and bottom)."""
    ts = _time_series(run)
    _need_columns(ts, ["mean_diameter", "centreline_settling_velocity"], "the diameter and centre velocity")
    fig, (top, bottom) = axes(ax, 2, (7, 6), nrows=2, ncols=1, sharex=True)
    prefix = _prefix(run, ax, label)
    for column, name in (("mean_diameter", "number mean"), ("sauter_diameter", "Sauter d32")):
        if _finite(ts, column):
            top.plot(ts["time"], 1e3 * ts[column], label=prefix + name)
    case = _case(run)
    if case is not None and case.coalescence.enabled:
        paper.draw_size_limit(top, case.coalescence.size_limit)
    top.set_ylabel("droplet diameter [mm]")
    top.legend(fontsize="small")
    if _finite(ts, "centreline_settling_velocity"):
        bottom.plot(ts["time"], 1e3 * ts["centreline_settling_velocity"], label=prefix + "centreline")
    else:
        bottom.text(0.5, 0.5, "no centreline velocity in timeseries.csv", ha="center", transform=bottom.transAxes)
    bottom.set_ylabel("centreline settling velocity\n(downward) [mm/s]")
    bottom.set_xlabel("time [s]")
    for a in (top, bottom):
        a.grid(alpha=0.3)
    top.set_title(f"{_case_name(run)}: droplet size and velocity at the centre, t = 0–{ts['time'].iloc[-1]:g} s")
    return fig


def settling_velocity(run, ax=None, label=None) -> Figure:
    """Seed Fig. 16: number-mean settling velocity of the droplets in the slag [mm/s] (downward positive) vs time
    [s] (column mean_settling_velocity)."""
    ts = _time_series(run)
    _need_columns(ts, ["mean_settling_velocity"], "the settling velocity")
    fig, (axis,) = axes(ax, 1, (7, 4.2))
    axis.plot(ts["time"], 1e3 * ts["mean_settling_velocity"], label=_prefix(run, ax, label).rstrip(": ") or None)
    axis.set_xlabel("time [s]")
    axis.set_ylabel("mean settling velocity (downward) [mm/s]")
    axis.grid(alpha=0.3)
    if ax is not None:
        axis.legend(fontsize="small")
    axis.set_title(f"{_case_name(run)}: mean settling velocity, t = 0–{ts['time'].iloc[-1]:g} s")
    return fig


def channel(run, time=None, ax=None, label=None) -> Figure:
    """The channel (our measure; the seed paper describes it in words, section 4): left, the channel radius [mm]
    (radius around the inlet axis holding half the droplet volume at mid-height) and the downward slag velocity
    on the axis there [mm/s] vs time [s] (timeseries.csv); right, both vs height [mm] at the snapshot nearest
    ``time`` (None: the last) from channel_profile.csv (``ax``: two Axes, left and right). A panel whose file or
    columns are missing says so; the figure is skipped (NoData) only if both are."""
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
    fig, (left, right) = axes(ax, 2, (12, 4.6), nrows=1, ncols=2)
    name = _case_name(run)
    prefix = _prefix(run, ax, label)

    def two_axes(ax, axis, radius, velocity, vertical):
        """radius [m] and velocity [m/s] against ``axis`` (time [s] across, or height [mm] upwards)."""
        other = ax.twiny() if vertical else ax.twinx()

        def draw(a, values, **kw):
            return a.plot(values, axis, marker="o", **kw) if vertical else a.plot(axis, values, **kw)

        lines = draw(ax, 1e3 * radius, color="C0", label=prefix + "channel radius")
        lines += draw(other, 1e3 * velocity, color="C3", label=prefix + "axis slag velocity (downward)")
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



def zones(run, ax=None) -> Figure:
    """The zone diagnostics of a full run (:data:`settler.output.ZONE_PROFILE`, ZONES, LIFT_BY_SIZE), profiles
    averaged over the snapshots of the last third of the run: the channel (core) radius and the return radius
    against height, with the column's equivalent radius sqrt(W D / pi); the slag's upward and downward volume flux
    against height; the roof layer's thickness and the droplets moving up against time; and the share of each size
    moving up (``ax``: four Axes in that order). Skipped (NoData) for a run without zone files (popbal runs, runs
    made before they existed)."""
    profile, scalars, lift = (_table(run, n) for n in ("zone_profile.csv", "zones.csv", "lift_by_size.csv"))
    if profile is None or scalars is None:
        raise NoData("no zone_profile.csv / zones.csv (full runs write them at every snapshot)")
    channel_rows = _table(run, "channel_profile.csv")
    name = _case_name(run)
    end = float(profile["time"].max())
    late = profile[profile["time"] >= end * 2.0 / 3.0]
    mean = late.groupby("z").mean(numeric_only=True).reset_index()
    fig, (radius_ax, flux_ax, roof_ax, lift_ax) = axes(ax, 4, (12, 8.5), nrows=2, ncols=2)
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
    flux_ax.set_xlabel("slag volume flux through the plane [cm³/s]")
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


