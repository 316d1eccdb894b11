"""The plume's axis velocity against the confined Stokes flow its droplets drive (SI units).

Each droplet settling at its terminal velocity passes its weight less buoyancy, V drho g, to the slag. Summed over a
height band of thickness dz, the droplets at distance r from the inlet axis are a ring force per unit height; in a
closed column of radius R (the box's cross-section as a circle, popbal.model.column_radius) with no slip at R, zero
net flux through every horizontal section and unidirectional Stokes flow, a ring of force F per unit height at r
drives the slag on the axis down at

    w0 = F K(r / R) / (4 pi mu),    K = 2 ln(R / r) - 2 + 2 (r / R)^2

(:func:`ring_kernel`; the slag between the axis and the ring moves as a plug, the pressure gradient that keeps the
flux zero pushes back; K < 0 beyond r / R = 0.45: droplets in the outer slag hold the axis back). A uniform core of
radius a averages K to A0 = 2 ln(R / a) - 1 + (a / R)^2 (popbal.closures.confined_axis_coefficient), the
confined plume law popbal's channel takes. So a band's droplets, wherever they are, predict the axis velocity

    u_K = drho g / (4 pi mu dz) sum_i V_i K(max(r_i, h / 2) / R)   (:func:`stokes_axis_velocity`),

r regularised at half the engine's cell h, over which the full engine spreads each droplet's force (a droplet at the
axis drives a cell, not a line; droplets beyond R, in the box's corners, count as at R, K = 0).
:func:`measure_plume_force` takes it over a run's steady window (each droplet snapshot, each of
:data:`settler.output.PROFILE_BANDS` bands) beside the measured axis velocity (``channel_profile.csv``) and the load
per height; :func:`write_plume_force` stores the table beside a reference run (:data:`PLUME_FORCE_FILE`, written by
``python -m analysis.reference_set``). It neglects the slag's inertia (the plume's Reynolds number reaches 10-20 in the demo's and the paper's
cases), the column's finite height (the top and bottom bands, where the flow turns) and the droplets' own
acceleration.

What it measures (2026-12-06, the remade training runs' run folders, their last 12 snapshots in the steady window;
docs/guide/reduced-model.md): over the middle four bands u / u_K = 0.65-0.86 in the demo's feed, viscosity and grid
families, 0.85 in the coalescence-off demo, 0.77 / 0.75 in simple / cubic, 0.65 / 0.77 in deep's 50 / 150 mm
columns: one factor of about 0.77 whether the plume is compact or spread, where the half load within the half-volume
radius (the line-force law) gave 0.77-1.68.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

#: The stored table's name beside a reference run.
PLUME_FORCE_FILE = "plume_force.csv"
#: The standard gravity [m/s^2] of the engine (settler.physics).
GRAVITY = 9.80665
#: Its columns: name -> (unit, meaning).
PLUME_FORCE_UNITS = {
    "z": ("m", "height of the band's centre above the bottom"),
    "axis_velocity": ("m/s", "downward slag velocity on the inlet axis (channel_profile.csv), mean over the snapshots"),
    "stokes_axis_velocity": ("m/s", "u_K: the confined Stokes flow's axis velocity driven by the band's droplets"),
    "load": ("m^3/m", "droplet volume per height in the band"),
}
#: The bands a summary takes: the middle four of ten (the ends are where the slag turns).
MIDDLE_BANDS = slice(3, 7)


def ring_kernel(radius, column_radius: float):
    """K(r / R) = 2 ln(R / r) - 2 + 2 (r / R)^2 [-] of a ring force at ``radius`` r [m] in a closed column of
    ``column_radius`` R [m]: the axis velocity over F / (4 pi mu) (module docstring). r is taken as at most R (K(R) =
    0) and must be positive."""
    r = np.minimum(np.asarray(radius, dtype=float), column_radius)
    if np.any(r <= 0.0):
        raise ValueError("ring_kernel: a ring at r <= 0 is a line force on the axis, whose velocity is infinite; "
                         "regularise r (stokes_axis_velocity takes min_radius)")
    x = r / column_radius
    return 2.0 * np.log(1.0 / x) - 2.0 + 2.0 * x * x


def stokes_axis_velocity(radius, volume, band_height: float, column_radius: float, viscosity: float,
                         density_difference: float, min_radius: float) -> float:
    """u_K [m/s, downward] of droplets of ``volume`` [m^3] at ``radius`` [m] from the axis in a band of
    ``band_height`` dz [m] (module docstring), the slag's ``viscosity`` mu [Pa s], ``density_difference`` drho
    [kg/m^3] and each r taken as at least ``min_radius`` [m] (> 0)."""
    if not min_radius > 0.0:
        raise ValueError(f"stokes_axis_velocity: min_radius = {min_radius!r}; allowed a length > 0 [m]")
    r = np.maximum(np.asarray(radius, dtype=float), min_radius)
    force = density_difference * GRAVITY * np.asarray(volume, dtype=float) / band_height
    return float(np.sum(force * ring_kernel(r, column_radius)) / (4.0 * math.pi * viscosity))


def force_table(snapshots, channel: pd.DataFrame, height: float, axis: tuple[float, float], column_radius: float,
                viscosity: float, density_difference: float, cell: float, bands: int | None = None) -> pd.DataFrame:
    """The table of :data:`PLUME_FORCE_UNITS` from ``snapshots`` [(time [s], droplets DataFrame with x, y, z [m],
    diameter [m])] and the run's ``channel`` profile, the inlet ``axis`` (x, y) [m] and the engine's ``cell`` [m]
    (r regularised at cell / 2), in the profile's bands over ``height`` [m]. ValueError naming the file where a
    snapshot's time, or a band at it, has no profile row."""
    from settler.output import PROFILE_BANDS, band_edges

    edges = band_edges(height, bands or PROFILE_BANDS)
    count = len(edges) - 1
    dz = edges[1] - edges[0]
    sums = {name: np.zeros(count) for name in ("axis_velocity", "stokes_axis_velocity", "load")}
    for time, frame in snapshots:
        rows = channel[np.isclose(channel["time"], time, rtol=0.0, atol=1e-6)]
        if rows.empty:
            raise ValueError(f"channel_profile.csv: no row at the snapshot time {time:g} s (written at every snapshot "
                             "by the full engine)")
        z = frame["z"].to_numpy(dtype=float)
        r = np.hypot(frame["x"].to_numpy(dtype=float) - axis[0], frame["y"].to_numpy(dtype=float) - axis[1])
        volume = np.pi / 6.0 * frame["diameter"].to_numpy(dtype=float) ** 3
        for b, (low, high) in enumerate(zip(edges[:-1], edges[1:])):
            centre = 0.5 * (low + high)
            u = rows.loc[np.isclose(rows["z"], centre, rtol=1e-9, atol=1e-12), "channel_velocity"]
            if u.empty:
                raise ValueError(f"channel_profile.csv: no row at {time:g} s for the band centred at z = {centre:g} m "
                                 f"(the profile's bands differ from {count} equal bands of the height)")
            inside = (z >= low) & (z < high)
            sums["axis_velocity"][b] += float(u.iloc[0])
            sums["load"][b] += float(volume[inside].sum()) / dz
            sums["stokes_axis_velocity"][b] += stokes_axis_velocity(r[inside], volume[inside], dz, column_radius,
                                                                    viscosity, density_difference, 0.5 * cell)
    n = len(snapshots)
    return pd.DataFrame({"z": 0.5 * (edges[:-1] + edges[1:]), **{k: v / n for k, v in sums.items()}})


def measure_plume_force(run, window: tuple[float, float] | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder or :class:`analysis.Run` over ``window`` (default: its steady window, else
    its last third): :func:`force_table` of its droplet snapshots there; meta {"window", "snapshots", "feed"
    (the matte feed [m^3/s]), "middle_ratio" (mean axis velocity over mean u_K in :data:`MIDDLE_BANDS`)}. ValueError
    where the window holds no droplet snapshot, the run lacks its channel profile, or its inlet is a slot."""
    from popbal.model import column_radius
    from settler.output import read_table

    from .runs import load_run
    from .steady import window_snapshots

    run = run if hasattr(run, "timeseries") else load_run(run)
    case = run.case
    if case.inlet_is_slot:
        raise ValueError(f"{run.folder}: a slot inlet feeds a row of plumes; the axis velocity is measured on one "
                         "inlet axis (a disk inlet)")
    window, times = window_snapshots(run, window)
    if not times:
        raise ValueError(f"no droplet snapshot within {window[0]:g}-{window[1]:g} s (a stored reference keeps few; "
                         "give the run folder or another window)")
    folder = Path(run.folder)
    if not (folder / "channel_profile.csv").is_file():
        raise ValueError(f"{folder}: no channel_profile.csv (the full engine's channel measures)")
    table = force_table([run.droplets(t) for t in times], read_table(folder / "channel_profile.csv"),
                        case.geometry.height, tuple(case.inlet_center), column_radius(case), case.slag_viscosity,
                        case.matte.density - case.slag.density, case.fulldem.cell_size)
    middle = table.iloc[MIDDLE_BANDS]
    meta = {"window": (float(window[0]), float(window[1])), "snapshots": list(times),
            "feed": case.feed.mass_rate / case.matte.density,
            "middle_ratio": float(middle["axis_velocity"].mean() / middle["stokes_axis_velocity"].mean())}
    return table, meta


def write_plume_force(run_folder, dest, window: tuple[float, float] | None = None) -> Path:
    """Measure ``run_folder`` over ``window`` (:func:`measure_plume_force`) and write :data:`PLUME_FORCE_FILE` into
    ``dest`` atomically, the window and the snapshots in its header."""
    from settler.output import atomic_write_text, units_line

    from .files import window_header

    table, meta = measure_plume_force(run_folder, window)
    header = units_line(PLUME_FORCE_UNITS) + window_header(meta["window"], meta["snapshots"], {})
    path = Path(dest) / PLUME_FORCE_FILE
    atomic_write_text(path, header + table.to_csv(index=False, float_format="%.7g"))
    return path


def read_plume_force(path) -> tuple[pd.DataFrame, dict]:
    """The (table, meta) a :func:`write_plume_force` file holds (meta: window, snapshots, middle_ratio)."""
    from .files import read_window_header

    fields = read_window_header(path)
    table = pd.read_csv(path, comment="#")
    middle = table.iloc[MIDDLE_BANDS]
    return table, {"window": fields["window"], "snapshots": fields["snapshots"],
                   "middle_ratio": float(middle["axis_velocity"].mean() / middle["stokes_axis_velocity"].mean())}


def _report(folder, table, meta) -> None:
    print(f"{folder}: {meta['window'][0]:g}-{meta['window'][1]:g} s, {len(meta['snapshots'])} snapshots; "
          f"u / u_K over the middle four bands {meta['middle_ratio']:.2f}")
    show = pd.DataFrame({"z [mm]": 1e3 * table["z"], "u [mm/s]": 1e3 * table["axis_velocity"],
                         "u_K [mm/s]": 1e3 * table["stokes_axis_velocity"],
                         "u / u_K": table["axis_velocity"] / table["stokes_axis_velocity"],
                         "load u / Q": table["load"] * table["axis_velocity"] / meta["feed"]})
    print(show.to_string(index=False, float_format=lambda x: f"{x:.3g}"))


def main(argv=None) -> int:
    from .steady import window_measure_main

    return window_measure_main(
        argv, "python -m analysis.plume_force",
        "the plume's axis velocity against the confined Stokes flow its droplets' weight drives, by height band",
        "full run folders or stored references (a reference keeps few snapshots; a run folder's every snapshot in "
        "the window is used)", measure_plume_force, _report)


if __name__ == "__main__":
    raise SystemExit(main())
