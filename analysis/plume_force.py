"""The plume's axis velocity against the confined Stokes flow its droplets drive (SI units).

Each droplet settling at its terminal velocity passes its weight less buoyancy, V drho g, to the slag. Summed over a
height band of thickness dz, the droplets at distance r from the inlet axis are a ring force per unit height; in a
closed column of radius R (the box's cross-section as a circle, popbal.model.column_radius) with no slip at R, zero
net flux through every horizontal section and unidirectional Stokes flow, a ring of force F per unit height at r
drives the slag on the axis down at

    w0 = F K(r / R) / (4 pi mu),    K = 2 ln(R / r) - 2 + 2 (r / R)^2

(:func:`ring_kernel`; the pressure gradient that keeps the flux zero pushes back, so K < 0 beyond r / R = 0.451:
droplets in the outer slag hold the axis back). A uniform core of radius a averages K to A0 = 2 ln(R / a) - 1 +
(a / R)^2 (popbal.closures.confined_axis_coefficient), the confined plume law popbal's channel takes. The full
engine does not put a droplet's force on a line: it spreads it over a Gaussian of width sigma = max(sigma_cells h,
sigma_diameter d) around the droplet (``fulldem.sigma_cells``, ``fulldem.sigma_diameter``, h the cell), whose
average of K is

    K_sigma(r) = 2 ln(R / r) - E1(r^2 / (2 sigma^2)) - 2 + 2 (r^2 + 2 sigma^2) / R^2

(:func:`smoothed_ring_kernel`; E1 the exponential integral; finite on the axis, 2 ln(R / sigma) - ln 2 + gamma - 2 +
4 sigma^2 / R^2; the Gaussian's tail beyond the wall neglected). So a band's droplets, wherever they are, predict the
axis velocity

    u_K = drho g / (4 pi mu dz) sum_i V_i K_sigma_i(r_i)   (:func:`stokes_axis_velocity`).

:func:`measure_plume_force` takes it over a run's steady window (each droplet snapshot, each of
:data:`settler.output.PROFILE_BANDS` bands) beside the measured axis velocity (``channel_profile.csv``) and the load
per height; :func:`write_plume_force` stores the table beside a reference run (:data:`PLUME_FORCE_FILE`, written by
``python -m analysis.reference_set``). It neglects the slag's inertia (the plume's Reynolds number reaches 10-20 in
the demo's and the paper's cases), the column's finite height (the top and bottom bands, where the flow turns), the
droplets' own acceleration and the box's corners (droplets beyond R count as at R).

What it measures (2026-12-06, the remade training runs' folders, every snapshot in the steady window;
docs/guide/reduced-model.md): over the middle four bands u / u_K = 0.93 / 0.91 / 0.81 / 0.87 / 0.72 in the demo's
2.5 mm viscosity-double, feed-half, cell_25, feed-double and viscosity-half runs (plume Reynolds number 1.3-13), 0.91
without coalescence, 0.85 / 0.89 / 0.81 for the demo at 5 / 3.3 / 2.5 mm cells, 0.79 / 0.78 in simple / cubic (Re
about 20), 1.10-1.15 in deep's 50 and 150 mm columns (Re below 1): near one where the slag's inertia is small,
falling as it grows, for compact and spread plumes alike.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from settler.physics.constants import STANDARD_GRAVITY as GRAVITY

from .plume_zones import (MIDDLE_BANDS, axis_window, band_value, read_window_table, snapshot_rows,
                          write_window_table)

#: The stored table's name beside a reference run.
PLUME_FORCE_FILE = "plume_force.csv"
#: Euler's constant gamma, in the smoothed kernel's value on the axis.
EULER_GAMMA = 0.5772156649015329
#: Its columns: name -> (unit, meaning).
PLUME_FORCE_UNITS = {
    "z": ("m", "height of the band's centre above the bottom"),
    "axis_velocity": ("m/s", "downward slag velocity on the inlet axis (channel_profile.csv), mean over the snapshots"),
    "stokes_axis_velocity": ("m/s", "u_K: the confined Stokes flow's axis velocity driven by the band's droplets"),
    "load": ("m^3/m", "droplet volume per height in the band"),
}


def ring_kernel(radius, column_radius: float):
    """K(r / R) = 2 ln(R / r) - 2 + 2 (r / R)^2 [-] of a ring force at ``radius`` r [m] in a closed column of
    ``column_radius`` R [m]: the axis velocity over F / (4 pi mu) (module docstring). r is taken as at most R (K(R) =
    0) and must be positive: a ring on the axis is a line force, whose axis velocity is infinite."""
    _check_positive("column_radius", column_radius, "m")
    r = np.minimum(np.asarray(radius, dtype=float), column_radius)
    if not np.all(r > 0.0):
        bad = float(r[~(r > 0.0)].flat[0])
        raise ValueError(f"ring_kernel: radius = {bad!r} m; allowed a distance > 0 from the axis (a ring on the axis "
                         "is a line force, whose axis velocity is infinite: smoothed_ring_kernel spreads it)")
    x = r / column_radius
    return 2.0 * np.log(1.0 / x) - 2.0 + 2.0 * x * x


def smoothed_ring_kernel(radius, column_radius: float, width):
    """K_sigma(r) [-]: :func:`ring_kernel` averaged over a Gaussian of ``width`` sigma [m] (scalar or per ring) around
    a point force at ``radius`` r [m] (module docstring), as the full engine spreads each droplet's force; r taken as
    at most R, r = 0 allowed."""
    from scipy.special import exp1

    _check_positive("column_radius", column_radius, "m")
    r = np.minimum(np.asarray(radius, dtype=float), column_radius)
    sigma = np.broadcast_to(np.asarray(width, dtype=float), r.shape)
    if not (np.all(r >= 0.0) and np.all(sigma > 0.0)):
        raise ValueError("smoothed_ring_kernel: allowed radius >= 0 and width > 0 [m]; got radius min "
                         f"{float(np.min(r))!r}, width min {float(np.min(sigma))!r}")
    x = r * r / (2.0 * sigma * sigma)
    # -2 ln r - E1(x) = -ln(2 sigma^2) + gamma - Ein(x), Ein(x) = E1(x) + gamma + ln x, x - x^2/4 near 0
    with np.errstate(divide="ignore"):
        ein = np.where(x > 1e-6, exp1(np.maximum(x, 1e-300)) + EULER_GAMMA + np.log(np.maximum(x, 1e-300)),
                       x - 0.25 * x * x)
    log_part = 2.0 * math.log(column_radius) - np.log(2.0 * sigma * sigma) + EULER_GAMMA - ein
    return log_part - 2.0 + 2.0 * (r * r + 2.0 * sigma * sigma) / column_radius**2


def stokes_axis_velocity(radius, volume, band_height: float, column_radius: float, viscosity: float,
                         density_difference: float, width) -> float:
    """u_K [m/s, downward] of droplets of ``volume`` [m^3] at ``radius`` [m] from the axis in a band of
    ``band_height`` dz [m] (module docstring), the slag's ``viscosity`` mu [Pa s] and ``density_difference`` drho
    [kg/m^3], each droplet's force spread over a Gaussian of ``width`` [m] (scalar or per droplet;
    :func:`smoothed_ring_kernel`)."""
    for name, value, unit in (("band_height", band_height, "m"), ("viscosity", viscosity, "Pa s")):
        _check_positive(name, value, unit)
    force = density_difference * GRAVITY * np.asarray(volume, dtype=float) / band_height
    return float(np.sum(force * smoothed_ring_kernel(radius, column_radius, width)) / (4.0 * math.pi * viscosity))


def _check_positive(name: str, value, unit: str) -> None:
    if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} = {value!r}; allowed a finite number > 0 [{unit}]")


def force_table(snapshots, channel: pd.DataFrame, height: float, axis: tuple[float, float], column_radius: float,
                viscosity: float, density_difference: float, smoothing: tuple[float, float],
                bands: int | None = None) -> pd.DataFrame:
    """The table of :data:`PLUME_FORCE_UNITS` from ``snapshots`` [(time [s], droplets DataFrame with x, y, z [m],
    diameter [m])] and the run's ``channel`` profile, the inlet ``axis`` (x, y) [m] and the engine's ``smoothing``
    (sigma_min [m], sigma per diameter [-]: each droplet's force spread over a Gaussian of width max(sigma_min,
    sigma per diameter x d)), in the profile's bands over ``height`` [m]. ValueError naming the file where a
    snapshot's time, or a band at it, has no profile row."""
    from settler.output import PROFILE_BANDS, band_edges

    edges = band_edges(height, bands or PROFILE_BANDS)
    count = len(edges) - 1
    dz = edges[1] - edges[0]
    sums = {name: np.zeros(count) for name in ("axis_velocity", "stokes_axis_velocity", "load")}
    for time, frame in snapshots:
        rows = snapshot_rows(channel, "channel_profile.csv", time)
        z = frame["z"].to_numpy(dtype=float)
        r = np.hypot(frame["x"].to_numpy(dtype=float) - axis[0], frame["y"].to_numpy(dtype=float) - axis[1])
        diameter = frame["diameter"].to_numpy(dtype=float)
        volume = np.pi / 6.0 * diameter**3
        width = np.maximum(smoothing[0], smoothing[1] * diameter)
        for b, (low, high) in enumerate(zip(edges[:-1], edges[1:])):
            centre = 0.5 * (low + high)
            sums["axis_velocity"][b] += band_value(rows, "channel_profile.csv", "channel_velocity", time, centre, count)
            inside = (z >= low) & (z < high)
            sums["load"][b] += float(volume[inside].sum()) / dz
            sums["stokes_axis_velocity"][b] += stokes_axis_velocity(r[inside], volume[inside], dz, column_radius,
                                                                    viscosity, density_difference, width[inside])
    n = len(snapshots)
    return pd.DataFrame({"z": 0.5 * (edges[:-1] + edges[1:]), **{k: v / n for k, v in sums.items()}})


def middle_ratio(table: pd.DataFrame) -> float:
    """The measured axis velocity over u_K, their means over :data:`MIDDLE_BANDS` [-] (NaN where u_K is 0 there)."""
    middle = table.iloc[MIDDLE_BANDS]
    stokes = float(middle["stokes_axis_velocity"].mean())
    return float(middle["axis_velocity"].mean()) / stokes if stokes != 0.0 else math.nan


def equivalent_core(table: pd.DataFrame, feed_volume_rate: float, column_radius: float, viscosity: float,
                    density_difference: float, speed_ratio: float = 1.0) -> dict[str, float]:
    """The uniform core popbal's line-force channel would need to drive the measured axis (middle bands): with the
    feed Q [m^3/s] carried at t times the axis speed u (``speed_ratio`` t: a load Q / (t u) per height in a uniform
    core of radius R* in the column of radius R) and the force factor f = u / u_K, the channel drives u when

        A0(R / R*) = W t u / Q,    W = u_K 4 pi mu / (drho g)   (the band's load weighted by K_sigma)

    (then at a multiplier f / t on the line-force law). Returns ``a0`` (W t u / Q [-]), ``core_radius`` R* [m] (NaN
    where A0 cannot reach W t u / Q: R* would be at least R), ``force_factor`` f [-] and ``axis_velocity`` u [m/s],
    means over :data:`MIDDLE_BANDS`."""
    from scipy.optimize import brentq

    from popbal.closures import confined_axis_coefficient

    for name, value, unit in (("feed_volume_rate", feed_volume_rate, "m^3/s"), ("column_radius", column_radius, "m"),
                              ("viscosity", viscosity, "Pa s"), ("density_difference", density_difference, "kg/m^3"),
                              ("speed_ratio", speed_ratio, "-")):
        _check_positive(name, value, unit)
    middle = table.iloc[MIDDLE_BANDS]
    u, u_k = float(middle["axis_velocity"].mean()), float(middle["stokes_axis_velocity"].mean())
    load = u_k * 4.0 * math.pi * viscosity / (density_difference * GRAVITY)
    a0 = load * speed_ratio * u / feed_volume_rate
    radius = math.nan
    if a0 > 0.0 and math.isfinite(a0):  # A0(R / a) falls from +inf at a -> 0 to 0 at a = R
        x = brentq(lambda s: confined_axis_coefficient(1.0 / s) - a0, 1e-12, 1.0 - 1e-12)
        radius = x * column_radius
    return {"a0": a0, "core_radius": radius, "force_factor": u / u_k if u_k != 0.0 else math.nan,
            "axis_velocity": u}


def measure_plume_force(run, window: tuple[float, float] | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder or :class:`analysis.Run` over ``window`` (default: its steady window, else
    its last third): :func:`force_table` of its droplet snapshots there, at the case's fulldem smoothing; meta
    {"window", "snapshots", "feed" (the matte feed [m^3/s]), "middle_ratio" (:func:`middle_ratio`)}. ValueError
    where the window holds no droplet snapshot, the run lacks its channel profile, or its inlet is a slot."""
    from popbal.model import column_radius
    from settler.output import read_table

    run, window, times, folder = axis_window(run, window, ("channel_profile.csv",), "the axis velocity is measured")
    case = run.case
    fd = case.fulldem
    table = force_table([run.droplets(t) for t in times], read_table(folder / "channel_profile.csv"),
                        case.geometry.height, tuple(case.inlet_center), column_radius(case), case.slag_viscosity,
                        case.matte.density - case.slag.density, (fd.sigma_cells * fd.cell_size, fd.sigma_diameter))
    meta = {"window": (float(window[0]), float(window[1])), "snapshots": list(times),
            "feed": case.feed.mass_rate / case.matte.density, "middle_ratio": middle_ratio(table)}
    return table, meta


def write_plume_force(run_folder, dest, window: tuple[float, float] | None = None) -> Path:
    """Measure ``run_folder`` over ``window`` (:func:`measure_plume_force`) and write :data:`PLUME_FORCE_FILE` into
    ``dest`` atomically, the window and the snapshots in its header."""
    table, meta = measure_plume_force(run_folder, window)
    return write_window_table(Path(dest) / PLUME_FORCE_FILE, PLUME_FORCE_UNITS, table, meta)


def read_plume_force(path) -> tuple[pd.DataFrame, dict]:
    """The (table, meta) a :func:`write_plume_force` file holds (meta: window, snapshots, middle_ratio)."""
    table, meta = read_window_table(path)
    return table, {**meta, "middle_ratio": middle_ratio(table)}


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
