"""Where a full run's droplets are at each height: the plume's core, its skirt and the return flow (SI units).

popbal holds a band's droplets in two zones, the channel (radius R_c) and the outer zone; a full run's plume is no
uniform disk. Over a run's steady window (its last third if none; :func:`analysis.steady.window_snapshots`), in each
droplet snapshot and each of the :data:`settler.output.PROFILE_BANDS` height bands, the band's droplets are split by
their distance r from the inlet axis:

- **core**, r < a: a the band's half-volume radius in that snapshot, computed from its droplets as
  ``channel_profile.csv``'s ``channel_radius`` is (:func:`settler.output.half_volume_radius`), so the core holds half
  the band's droplet volume by definition;
- **skirt**, a <= r < r_0: r_0 the ``return_radius`` of ``zone_profile.csv`` at that time and band, where the
  ring-averaged slag turns from down to up: droplets outside the core in the plume's downflow;
- **return**, r >= max(a, r_0): droplets in the rising slag (where r_0 < a, as in simple and cubic, the skirt is
  empty and the core reaches into the return flow; where the band has no r_0, the skirt takes everything beyond a).

For each: the droplet volume per metre of height [m^3/m] (the band's volume over its height, mean over the window's
snapshots) and the volume-weighted mean downward velocity [m/s] (sum of volume x -w over sum of volume), beside the
axis velocity of ``channel_profile.csv`` at the same times. Against the feed Q [m^3/s], load x velocity / Q is each
part's share of the feed's downward flux. ``python -m analysis.plume_zones RUN...`` prints the table, as shares and
multiples of the axis velocity; :func:`write_plume_zones` stores it beside a reference run (:data:`PLUME_ZONES_FILE`,
written by ``python -m analysis.reference_set``).

What it measures (2026-12-06, the remade training runs' last snapshots, docs/guide/reduced-model.md): in every run of
the demo's families the core moves at 0.75-1.0 times the axis velocity, the skirt holds 5-18 % of the volume at
0.3-0.7 times it, and the return flow 32-45 %, suspended (mean velocity within 4 % of the axis velocity of zero);
in deep's columns the plume fills r < r_0 and the return flow holds nothing.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from .files import read_window_header, window_header

#: The stored table's name beside a reference run.
PLUME_ZONES_FILE = "plume_zones.csv"
#: The parts of a band, inside out.
PARTS = ("core", "skirt", "return")
#: Its columns: name -> (unit, meaning).
PLUME_ZONES_UNITS = {
    "z": ("m", "height of the band's centre above the bottom"),
    "axis_velocity": ("m/s", "downward slag velocity on the inlet axis (channel_profile.csv), mean over the snapshots"),
    "core_load": ("m^3/m", "droplet volume per height within the band's half-volume radius a"),
    "skirt_load": ("m^3/m", "droplet volume per height between a and the return radius r_0"),
    "return_load": ("m^3/m", "droplet volume per height beyond max(a, r_0)"),
    "core_velocity": ("m/s", "volume-weighted mean downward velocity of the core's droplets (NaN: none)"),
    "skirt_velocity": ("m/s", "the same in the skirt"),
    "return_velocity": ("m/s", "the same in the return flow"),
}


#: The bands a summary takes: the middle four of ten (the ends are where the slag turns); analysis.plume_force's too.
MIDDLE_BANDS = slice(3, 7)


def split_band(r, volume, down, core_radius: float, return_radius: float) -> dict[str, tuple[float, float]]:
    """{part: (volume [m^3], volume x downward velocity [m^4/s])} of one band's droplets at distances ``r`` [m] from
    the axis with ``volume`` [m^3] and downward velocity ``down`` [m/s], split at ``core_radius`` a and
    ``return_radius`` r_0 [m] (NaN: no return flow in the band, everything beyond a is skirt)."""
    r, volume, down = (np.asarray(x, dtype=float) for x in (r, volume, down))
    outer = max(core_radius, return_radius) if math.isfinite(return_radius) else math.inf
    masks = {"core": r < core_radius, "skirt": (r >= core_radius) & (r < outer), "return": r >= outer}
    return {part: (float(volume[m].sum()), float((volume[m] * down[m]).sum())) for part, m in masks.items()}


def snapshot_rows(profile: pd.DataFrame, name: str, time: float) -> pd.DataFrame:
    """The rows of a run's height profile ``name`` (``channel_profile.csv``, ``zone_profile.csv``) at a snapshot's
    ``time`` [s]; ValueError naming the file where it has none."""
    rows = profile[np.isclose(profile["time"], time, rtol=0.0, atol=1e-6)]
    if rows.empty:
        raise ValueError(f"{name}: no row at the snapshot time {time:g} s (written at every snapshot by the full engine)")
    return rows


def band_value(rows: pd.DataFrame, name: str, column: str, time: float, centre: float, bands: int) -> float:
    """``column`` of the profile ``rows`` (:func:`snapshot_rows`) in the band centred at ``centre`` [m]; ValueError
    naming the file where the profile has no such band (its bands differ from ``bands`` equal bands)."""
    value = rows.loc[np.isclose(rows["z"], centre, rtol=1e-9, atol=1e-12), column]
    if value.empty:
        raise ValueError(f"{name}: no row at {time:g} s for the band centred at z = {centre:g} m (the profiles' bands "
                         f"differ from {bands} equal bands of the height)")
    return float(value.iloc[0])


def axis_window(run, window, files, what: str):
    """(run, window, snapshot times, folder) of a full run folder or :class:`analysis.Run` for a measure around its
    inlet axis over ``window`` (default: its steady window, else its last third). ValueError naming the run where its
    inlet is a slot (``what`` says what is measured around one axis), the window holds no droplet snapshot or the run
    lacks one of ``files``."""
    from .runs import load_run
    from .steady import window_snapshots

    run = run if hasattr(run, "timeseries") else load_run(run)
    if run.case.inlet_is_slot:
        raise ValueError(f"{run.folder}: a slot inlet feeds a row of plumes; {what} around one inlet axis (a disk "
                         "inlet)")
    window, times = window_snapshots(run, window)
    if not times:
        held = len(run.snapshot_times())
        raise ValueError(f"{run.folder}: no droplet snapshot within {window[0]:g}-{window[1]:g} s"
                         + (" (it stores none)" if held == 0 else
                            f" (it keeps {held}; give the run folder or another window)"))
    folder = Path(run.folder)
    missing = [n for n in files if not (folder / n).is_file()]
    if missing:
        raise ValueError(f"{folder}: no {', '.join(missing)} (the full engine's zone diagnostics)")
    return run, window, times, folder


def write_window_table(path: Path, units: dict, table: pd.DataFrame, meta: dict) -> Path:
    """Write a measure's ``table`` to ``path`` atomically: its units line, the window and the snapshots of ``meta``
    in the header, numbers to float32's 7 digits."""
    from settler.output import atomic_write_text, units_line

    header = units_line(units) + window_header(meta["window"], meta["snapshots"], {})
    atomic_write_text(path, header + table.to_csv(index=False, float_format="%.7g"))
    return path


def zone_table(snapshots, channel: pd.DataFrame, zones: pd.DataFrame, height: float, axis: tuple[float, float],
               bands: int | None = None) -> pd.DataFrame:
    """The table of :data:`PLUME_ZONES_UNITS` from ``snapshots`` [(time [s], droplets DataFrame with x, y, z [m],
    diameter [m], w [m/s])], the run's ``channel`` and ``zones`` profiles (``channel_profile.csv``,
    ``zone_profile.csv``) and the inlet ``axis`` (x, y) [m], in the profiles' bands over ``height`` [m]. ValueError
    naming the file where a snapshot's time, or a band at it, has no profile row."""
    from settler.output import PROFILE_BANDS, band_edges, half_volume_radius

    edges = band_edges(height, bands or PROFILE_BANDS)
    sums = {part: np.zeros((len(edges) - 1, 2)) for part in PARTS}
    axis_sum = np.zeros(len(edges) - 1)
    for time, frame in snapshots:
        rows_c = snapshot_rows(channel, "channel_profile.csv", time)
        rows_z = snapshot_rows(zones, "zone_profile.csv", time)
        z = frame["z"].to_numpy(dtype=float)
        r = np.hypot(frame["x"].to_numpy(dtype=float) - axis[0], frame["y"].to_numpy(dtype=float) - axis[1])
        volume = np.pi / 6.0 * frame["diameter"].to_numpy(dtype=float) ** 3
        down = -frame["w"].to_numpy(dtype=float)
        for b, (low, high) in enumerate(zip(edges[:-1], edges[1:])):
            inside = (z >= low) & (z < high)
            centre = 0.5 * (low + high)
            r0 = band_value(rows_z, "zone_profile.csv", "return_radius", time, centre, len(edges) - 1)
            axis_sum[b] += band_value(rows_c, "channel_profile.csv", "channel_velocity", time, centre, len(edges) - 1)
            if not inside.any():
                continue
            a = half_volume_radius(r[inside], volume[inside])
            split = split_band(r[inside], volume[inside], down[inside], a, r0)
            for part in PARTS:
                sums[part][b] += split[part]
    count, dz = len(snapshots), edges[1] - edges[0]
    table = {"z": 0.5 * (edges[:-1] + edges[1:]), "axis_velocity": axis_sum / count}
    for part in PARTS:
        table[f"{part}_load"] = sums[part][:, 0] / (count * dz)
    for part in PARTS:
        with np.errstate(invalid="ignore", divide="ignore"):
            table[f"{part}_velocity"] = np.where(sums[part][:, 0] > 0.0, sums[part][:, 1] / sums[part][:, 0], np.nan)
    return pd.DataFrame(table)


def settling_snapshots(run, times):
    """[(position (n, 3) [m], diameter (n,) [m], terminal settling velocity (n,) [m/s])] of ``run``'s droplet
    snapshots at ``times`` [s], the velocity :func:`settler.derived.settling_velocity`'s for each droplet's diameter
    and density in the run's case."""
    from settler.derived import settling_velocity

    out = []
    for t in times:
        _, d = run.droplets(t)
        diameter = d["diameter"].to_numpy(dtype=float)
        out.append((d[["x", "y", "z"]].to_numpy(dtype=float), diameter,
                    settling_velocity(run.case, diameter, d["density"].to_numpy(dtype=float))))
    return out


def measure_plume_zones(run, window: tuple[float, float] | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder or :class:`analysis.Run` over ``window`` (default: its steady window, else
    its last third): :func:`zone_table` of its droplet snapshots there; meta {"window", "snapshots"}. ValueError
    where the window holds no droplet snapshot, the run lacks its profiles, or its inlet is a slot (a row of
    plumes, not one axis)."""
    from settler.output import read_table

    run, window, times, folder = axis_window(run, window, ("channel_profile.csv", "zone_profile.csv"),
                                             "the core, skirt and return flow are measured")
    table = zone_table([run.droplets(t) for t in times], read_table(folder / "channel_profile.csv"),
                       read_table(folder / "zone_profile.csv"), run.case.geometry.height, tuple(run.case.inlet_center))
    return table, {"window": (float(window[0]), float(window[1])), "snapshots": list(times)}


def write_plume_zones(run_folder, dest, window: tuple[float, float] | None = None) -> Path:
    """Measure ``run_folder`` over ``window`` (:func:`measure_plume_zones`) and write :data:`PLUME_ZONES_FILE` into
    ``dest`` atomically, the window and the snapshots in its header."""
    table, meta = measure_plume_zones(run_folder, window)
    return write_window_table(Path(dest) / PLUME_ZONES_FILE, PLUME_ZONES_UNITS, table, meta)


def read_window_table(path) -> tuple[pd.DataFrame, dict]:
    """The (table, meta) a :func:`write_window_table` file holds (meta: window, snapshots)."""
    fields = read_window_header(path)
    return pd.read_csv(path, comment="#"), {"window": fields["window"], "snapshots": fields["snapshots"]}


def read_plume_zones(path) -> tuple[pd.DataFrame, dict]:
    """The (table, meta) a :func:`write_plume_zones` file holds (meta: window, snapshots)."""
    return read_window_table(path)


def shares(table: pd.DataFrame) -> pd.DataFrame:
    """Per band: each part's share of the band's droplet volume and its velocity over the axis velocity [-]."""
    total = sum(table[f"{p}_load"] for p in PARTS)
    out = {"z": table["z"]}
    for part in PARTS:
        out[f"{part}_share"] = table[f"{part}_load"] / total
        out[f"{part}_speed"] = table[f"{part}_velocity"] / table["axis_velocity"]
    return pd.DataFrame(out)


def plume_speed_ratio(table: pd.DataFrame, bands: slice = MIDDLE_BANDS) -> float:
    """t [-]: the plume's droplets' (core and skirt) volume-weighted downward velocity over the axis velocity, over
    ``bands`` (default :data:`MIDDLE_BANDS`): below 1 where the plume's droplets lag its axis, above 1 where grown
    droplets outrun the slag."""
    middle = table.iloc[bands]
    load = middle["core_load"] + middle["skirt_load"]
    moving = (middle["core_load"] * middle["core_velocity"] + middle["skirt_load"] * middle["skirt_velocity"]).sum()
    axis = float(middle["axis_velocity"].mean())
    return float(moving / load.sum()) / axis if axis != 0.0 and load.sum() > 0.0 else float("nan")


def _report(folder, table, meta) -> None:
    print(f"{folder}: {meta['window'][0]:g}-{meta['window'][1]:g} s, {len(meta['snapshots'])} snapshots")
    show = shares(table)
    show.insert(1, "u [mm/s]", table["axis_velocity"] * 1e3)
    show["z"] *= 1e3
    print(show.rename(columns={"z": "z [mm]"}).to_string(index=False, float_format=lambda x: f"{x:.3g}"))


def main(argv=None) -> int:
    from .steady import window_measure_main

    return window_measure_main(
        argv, "python -m analysis.plume_zones",
        "where a full run's droplets are at each height: the plume's core, its skirt and the return flow (shares of "
        "the band's droplet volume, velocities over the axis velocity)",
        "full run folders or stored references (a reference keeps few snapshots; a run folder's every snapshot in "
        "the window is used)", measure_plume_zones, _report)


if __name__ == "__main__":
    raise SystemExit(main())
