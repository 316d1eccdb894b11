"""The collision efficiency of a whole full run, height band by height band: its merges (``merges_by_height.csv``)
over the gravitational collisions its droplets make cell by cell (SI units). Re-exported by :mod:`analysis.evidence`.

The kernel run (:mod:`analysis.kernel_run`) measures the efficiency in a dilute closed box of two sizes, with the
concentrations of horizontal slices and the mean velocity of each size. Where the whole runs merge -- a dense layer
under the lid, a narrow plume -- the concentration varies on the scale of a cell, and what multiplies the kernel
there is the local n_i n_j. Here the collisions of every snapshot are summed cell by cell over all pairs of droplets
in a cell of edge ``cell`` (default: the run's own ``fulldem.cell_size``),

    C_cell = sum_{i<j in the cell} pi (a_i + a_j)^2 abs(U_i - U_j) / V_cell   [1/s],

with U the single-droplet terminal velocity of each droplet's diameter and density in the case's slag and drag law
(:func:`settler.derived.settling_velocity`): the differential-settling kernel popbal applies, with the
concentrations the full run holds in each cell, as if mixed within it. The sum is exact in O(n log n): the droplets
of a cell sorted by U, pair j takes U_j (S2 + 2 a_j S1 + a_j^2 S0) - (T2 + 2 a_j T1 + a_j^2 T0) with S_k = sum a_i^k
and T_k = sum U_i a_i^k over the droplets before it. Each cell counts in the band that holds its centre; the bands
are those of ``merges_by_height.csv`` (:data:`settler.output.PROFILE_BANDS` equal bands of the height).

The same merges over the collisions of droplets *well mixed* in each band's two regions -- under the inlet (its disk
or slot extended down, where ``merges_by_height.csv`` books a merge "under the inlet") and elsewhere -- give the
efficiency a model with those zones would need there (:func:`region_collision_rates`: the same pair sum over the
region, over the region's volume). Against the cell-by-cell efficiency it measures how much the droplets cluster
within the region.

Shear. A cell's droplets also meet by the slag's own shear: (4/3) G (a_i + a_j)^3 n_i n_j per unit volume
(Smoluchowski's simple-shear kernel, the form popbal's shear collisions take), G = sqrt(2 S:S) the shear rate of the
resolved slag at the cell (:func:`cell_shear_rates`, from a run folder's fluid snapshots; a stored reference keeps one
plane and has none). With both kernels summed cell by cell over each band's two regions, the merges are fitted as
E_g C_g + E_s C_s over the bands and regions (:func:`kernel_fit`): the gravitational and the shear efficiency of the
full engine at its grid's scale, the two numbers popbal's kernel takes. Regions under the inlet (plume and layer,
strong shear) and elsewhere (weak shear) give them leverage apart; their correlation is reported. The shear
collisions of each region's droplets well mixed, sheared at the mean shear rate at them
(:func:`region_shear_rates`), are what a zone of popbal with that shear would count: beside the well-mixed
gravitational ones they give a zone's own efficiency (the roof layer's, the channel's) as popbal applies it.

The efficiency of a band is its merges between the table's rows nearest the window over the time integral of its
collision rate, taken as the mean over the snapshots in the window times its length. Standard error: the Poisson
count of the merges and the standard error of the mean rate over the snapshots, in quadrature (one snapshot: the
rate's scatter is unknown and only the count's part is given).

A stored reference keeps few snapshots and one plane of the slag, so ``python -m analysis.reference_set`` measures
each run folder when it stores it and keeps the table as :data:`COLLISIONS_FILE` (:func:`write_collisions`), which
:func:`band_efficiency` reads back. The table also keeps, per band under the inlet and elsewhere, the matte volume
held and the slag's shear rate at the droplets: the zone quantities (roof inventory, roof and channel shear) that the
reduced model's zones are fitted to, which likewise need every snapshot and the whole slag grid.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from settler.derived import settling_velocity
from settler.output import PROFILE_BANDS

from .files import read_window_header, window_header


def pair_sums(group, diameter, velocity) -> tuple[np.ndarray, np.ndarray]:
    """(the distinct values of ``group`` (n,) [int], for each the sum over the pairs of its droplets of
    (a_i + a_j)^2 abs(U_i - U_j) [m^3/s]), a = diameter / 2 [m], U = ``velocity`` [m/s]; exact, by sorted prefix sums
    (module docstring)."""
    group = np.asarray(group, dtype=np.int64)
    a = 0.5 * np.asarray(diameter, dtype=float)
    u = np.asarray(velocity, dtype=float)
    if len(a) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    order = np.lexsort((u, group))  # by group, then by U within the group
    group, a, u = group[order], a[order], u[order]
    first = np.r_[True, group[1:] != group[:-1]]
    start = np.maximum.accumulate(np.where(first, np.arange(len(group)), 0))

    def before(values):  # the sum over the droplets of the same group before each one (its exclusive prefix sum)
        total = np.cumsum(values) - values
        return total - total[start]

    s0, s1, s2 = before(np.ones_like(a)), before(a), before(a * a)
    t0, t1, t2 = before(u), before(u * a), before(u * a * a)
    per_droplet = u * (s2 + 2.0 * a * s1 + a * a * s0) - (t2 + 2.0 * a * t1 + a * a * t0)
    index = np.cumsum(first) - 1
    return group[first], np.bincount(index, per_droplet, minlength=int(first.sum()))


def cell_collision_rates(position, diameter, velocity, cell: float, height: float,
                         bands: int = PROFILE_BANDS) -> np.ndarray:
    """Gravitational collisions per second [1/s] in each of ``bands`` equal height bands of a slag of ``height`` [m]:
    the sum over cubic cells of edge ``cell`` [m] (from the origin) of C_cell (module docstring), each cell in the band
    of its centre. position (n, 3) [m], diameter (n,) [m], velocity (n,) [m/s] (each droplet's settling velocity)."""
    position = np.asarray(position, dtype=float)
    if not (cell > 0.0 and height > 0.0 and bands >= 1):
        raise ValueError(f"cell = {cell!r} m, height = {height!r} m, bands = {bands!r}: all must be > 0")
    rates = np.zeros(bands)
    if len(position) < 2:
        return rates
    index = np.floor(position / cell).astype(np.int64)
    shifted = index - index.min(axis=0)
    span = shifted.max(axis=0) + 1
    key = (shifted[:, 2] * span[1] + shifted[:, 1]) * span[0] + shifted[:, 0]
    keys, sums = pair_sums(key, diameter, velocity)
    iz = keys // (span[0] * span[1]) + index[:, 2].min()
    band = np.clip(np.floor((iz + 0.5) * cell / height * bands).astype(np.int64), 0, bands - 1)
    np.add.at(rates, band, sums)
    return math.pi * rates / cell**3


def region_collision_rates(band, under_inlet, diameter, velocity, volumes) -> np.ndarray:
    """Gravitational collisions per second [1/s] of droplets well mixed in each height band's two regions, under the
    inlet and elsewhere (popbal's zones seen as well mixed): (bands, 2) = pi sum over the region's pairs of
    (a_i + a_j)^2 abs(U_i - U_j) / V_region. band (n,) [int], under_inlet (n,) [bool], diameter [m], velocity [m/s],
    volumes (bands, 2) [m^3] of the regions."""
    volumes = np.asarray(volumes, dtype=float)
    rates = np.zeros(volumes.shape)
    key = 2 * np.asarray(band, dtype=np.int64) + np.where(under_inlet, 0, 1)
    keys, sums = pair_sums(key, diameter, velocity)
    flat = rates.reshape(-1)
    flat[keys] = math.pi * sums / volumes.reshape(-1)[keys]
    return rates


def region_shear_rates(band, under_inlet, diameter, shear_rate, volumes) -> np.ndarray:
    """Shear collisions per second [1/s] of droplets well mixed in each height band's two regions, under the inlet
    and elsewhere, sheared at the region's own rate: (bands, 2) = (4/3) G_region sum over the region's pairs of
    (a_i + a_j)^3 / V_region (Smoluchowski's simple-shear kernel, as popbal's zones apply it). band (n,) [int],
    under_inlet (n,) [bool], diameter [m], shear_rate (bands, 2) [1/s] (NaN: none known, giving NaN where the region
    holds a pair), volumes (bands, 2) [m^3] of the regions."""
    volumes = np.asarray(volumes, dtype=float)
    rates = np.zeros(volumes.shape)
    key = 2 * np.asarray(band, dtype=np.int64) + np.where(under_inlet, 0, 1)
    keys, sums = shear_pair_sums(key, diameter)
    _, count = np.unique(key, return_counts=True)  # the same sorted keys
    keys, sums = keys[count > 1], sums[count > 1]  # a lone droplet meets nobody, whatever the shear
    flat = rates.reshape(-1)
    flat[keys] = (4.0 / 3.0) * np.asarray(shear_rate, dtype=float).reshape(-1)[keys] * sums / volumes.reshape(-1)[keys]
    return rates


def shear_pair_sums(group, diameter) -> tuple[np.ndarray, np.ndarray]:
    """(the distinct values of ``group`` (n,) [int], for each the sum over the pairs of its droplets of
    (a_i + a_j)^3 [m^3]), a = diameter / 2 [m]: n S3 + 3 S1 S2 - 4 S3 with S_k = sum a^k over the group."""
    keys, index = np.unique(np.asarray(group, dtype=np.int64), return_inverse=True)
    a = 0.5 * np.asarray(diameter, dtype=float)
    count = np.bincount(index, minlength=len(keys))
    s1, s2, s3 = (np.bincount(index, a**k, len(keys)) for k in (1, 2, 3))
    return keys, count * s3 + 3.0 * s1 * s2 - 4.0 * s3


def cell_shear_rates(centres, velocity) -> tuple[np.ndarray, float]:
    """The shear rate G = sqrt(2 S:S) [1/s] (S the strain-rate tensor; G is du/dy in a simple shear) at every cell of
    a slag snapshot given as cell ``centres`` (n, 3) [m] and ``velocity`` (n, 3) [m/s] on a uniform grid, by central
    differences (one-sided at the walls): (G on the grid (nx, ny, nz), the cell edge [m]). ValueError for a grid
    that is not three-dimensional (a stored reference keeps one plane of the slag)."""
    from .files import slag_grid

    axes, v = slag_grid(centres, velocity)
    edge = float(axes[0][1] - axes[0][0])
    grad = np.stack([np.stack(np.gradient(v[..., i], *[x[1] - x[0] for x in axes]), axis=-1) for i in range(3)],
                    axis=-2)  # [..., i, j] = d v_i / d x_j
    strain = 0.5 * (grad + np.swapaxes(grad, -1, -2))
    return np.sqrt(2.0 * (strain * strain).sum(axis=(-1, -2))), edge


def kernel_fit(merges, gravitational, shear) -> dict:
    """The two efficiencies of merges = E_g C_g + E_s C_s over the regions given (arrays of one shape: merges [-] and
    the gravitational and shear collisions [-] of each), weighted least squares with Poisson weights 1 / max(merges,
    1); the standard errors from the weighted normal matrix, scaled by the reduced chi-square where it exceeds 1
    (scatter beyond the count's). Returns {"gravitational", "shear" (the efficiencies) [-], "standard_errors" (2,),
    "correlation" [-], "chi2_reduced" [-], "regions" (used: those with collisions) [-]}, NaN where fewer than two
    regions have collisions or the two kernels are proportional over them (nothing tells them apart)."""
    y = np.asarray(merges, dtype=float).reshape(-1)
    x = np.column_stack([np.asarray(gravitational, dtype=float).reshape(-1),
                         np.asarray(shear, dtype=float).reshape(-1)])
    used = x.sum(axis=1) > 0
    y, x = y[used], x[used]
    w = 1.0 / np.maximum(y, 1.0)
    normal = x.T @ (x * w[:, None])
    if len(y) < 2 or np.linalg.cond(normal) > 1e12:  # too few regions, or the two kernels proportional
        nan = math.nan
        return {"gravitational": nan, "shear": nan, "standard_errors": np.array([nan, nan]), "correlation": nan,
                "chi2_reduced": nan, "regions": int(used.sum())}
    covariance = np.linalg.inv(normal)
    coef = covariance @ (x.T @ (w * y))
    dof = max(len(y) - 2, 1)
    chi2 = float((w * (y - x @ coef) ** 2).sum()) / dof
    covariance = covariance * max(chi2, 1.0)
    se = np.sqrt(np.diag(covariance))
    return {"gravitational": float(coef[0]), "shear": float(coef[1]), "standard_errors": se,
            "correlation": float(covariance[0, 1] / (se[0] * se[1])), "chi2_reduced": chi2, "regions": int(used.sum())}


def merges_between(table: pd.DataFrame, window: tuple[float, float], where="the run") -> tuple[float, float,
                                                                                        pd.DataFrame]:
    """(t0, t1 [s], the merges by band between them: a DataFrame of z [m], merges_under_inlet, merges_elsewhere [-]) of
    a cumulative ``merges_by_height`` table, between its rows nearest the ``window`` (start, end) [s]; ValueError
    naming ``where`` if the window holds no two rows."""
    times = np.unique(table["time"].to_numpy(dtype=float))
    t0 = float(times[np.argmin(np.abs(times - window[0]))])
    t1 = float(times[np.argmin(np.abs(times - window[1]))])
    if not t1 > t0:
        raise ValueError(f"{where}: window {window[0]:g}-{window[1]:g} s holds no two merges_by_height rows "
                         f"(snapshots at {times[0]:g}-{times[-1]:g} s)")
    columns = ["merges_under_inlet", "merges_elsewhere"]
    first = table[table["time"] == t0].set_index("z")
    last = table[table["time"] == t1].set_index("z")
    bands = (last[columns] - first[columns]).reset_index().sort_values("z").reset_index(drop=True)
    return t0, t1, bands


class _Folder:
    """A full run folder read with :mod:`analysis.files` alone (what :func:`measure_collisions` needs of an
    :class:`analysis.Run`: its case, time series, merge table, droplet and slag snapshots)."""

    def __init__(self, folder):
        from settler.cases import load_case
        from settler.output import OutputError, read_time_series

        from .files import snapshot_files

        self.folder = Path(folder)
        if not (self.folder / "timeseries.csv").is_file():
            raise OutputError(f"{self.folder}: not a run folder (no timeseries.csv)")
        self.case = load_case(self.folder / "case.toml")
        self.timeseries = read_time_series(self.folder / "timeseries.csv")
        self.is_reference = (self.folder / "reference.json").is_file()
        path = self.folder / "merges_by_height.csv"
        self.zones = {"merges_by_height": pd.read_csv(path, comment="#")} if path.is_file() else {}
        self._snapshots = {t: (d, f) for t, d, f in snapshot_files(self.folder)}

    def snapshot_times(self):
        return [t for t, (d, _) in self._snapshots.items() if d is not None]

    def droplets(self, time):
        from .files import droplets_file

        return time, droplets_file(self._snapshots[time][0])

    def slag(self, time):
        from .files import NoData, slag_file

        path = self._snapshots[time][1]
        if path is None:
            raise NoData(f"no slag snapshot at t = {time:g} s")
        return (time, *slag_file(path))


def _as_run(run):
    """An :class:`analysis.Run` (or anything with its case, timeseries, zones, snapshot_times, droplets, slag and
    folder) as it is; a folder as :class:`_Folder`."""
    return _Folder(run) if isinstance(run, (str, Path)) else run


#: The measured table of a run, stored beside a reference (which keeps too few snapshots and one slag plane to measure
#: it again): per height band, the droplets held, the merges and the collisions of every kind over the window
#: recorded in the header.
COLLISIONS_FILE = "collisions_by_height.csv"
COLLISIONS_UNITS = {
    "z": ("m", "height of the band's centre above the bottom"),
    "held": ("-", "mean droplets in the band over the window's snapshots"),
    "merges_under_inlet": ("-", "merges in the band under the inlet over the window"),
    "merges_elsewhere": ("-", "merges in the band elsewhere over the window"),
    "collisions": ("-", "gravitational collisions cell by cell over the window"),
    "mixed_under_inlet": ("-", "gravitational collisions of the band's droplets under the inlet well mixed"),
    "mixed_elsewhere": ("-", "gravitational collisions of the band's droplets elsewhere well mixed"),
    "gravitational_under_inlet": ("-", "gravitational collisions cell by cell on the slag grid, under the inlet"),
    "gravitational_elsewhere": ("-", "gravitational collisions cell by cell on the slag grid, elsewhere"),
    "shear_under_inlet": ("-", "shear collisions cell by cell with the slag's shear rate, under the inlet (NaN: no "
                          "whole slag grid)"),
    "shear_elsewhere": ("-", "shear collisions cell by cell with the slag's shear rate, elsewhere (NaN: no whole "
                        "slag grid)"),
    "mixed_shear_under_inlet": ("-", "shear collisions of the band's droplets under the inlet well mixed, sheared at "
                                "the slag's shear rate at them (NaN: no whole slag grid)"),
    "mixed_shear_elsewhere": ("-", "shear collisions of the band's droplets elsewhere well mixed, sheared at the "
                              "slag's shear rate at them (NaN: no whole slag grid)"),
    "volume_under_inlet": ("m^3", "mean matte volume of the band's droplets under the inlet over the window's "
                           "snapshots"),
    "volume_elsewhere": ("m^3", "mean matte volume of the band's droplets elsewhere over the window's snapshots"),
    "shear_rate_under_inlet": ("1/s", "the slag's shear rate G = sqrt(2 S:S) at the band's droplets under the inlet, "
                               "averaged over them and the window's snapshots (NaN: none there, or no whole slag "
                               "grid)"),
    "shear_rate_elsewhere": ("1/s", "the slag's shear rate at the band's droplets elsewhere, averaged over them and "
                             "the window's snapshots (NaN: none there, or no whole slag grid)"),
}


def measure_collisions(run, window: tuple[float, float] | None = None, cell: float | None = None,
                       shear: bool = True) -> tuple[pd.DataFrame, dict]:
    """(the :data:`COLLISIONS_UNITS` table of ``run`` (a full run folder, a stored reference or an
    :class:`analysis.Run`) over ``window`` (start, end) [s] (default: its steady window, else its last third), cells
    of edge ``cell`` [m] (default: the run's ``fulldem.cell_size``), the shear columns NaN without ``shear`` or
    without the whole slag grid at every snapshot; {"window" (the merge table's rows) [s], "snapshots" (times) [s],
    "cell" [m], "rate_scatter" (the relative standard error of the mean collision rate over the snapshots, NaN for
    one)}). Raises ValueError for a run without merges_by_height.csv or without a droplet snapshot in the window."""
    from fulldem.boundaries import Inlet

    from .steady import window_of

    run = _as_run(run)
    table = run.zones.get("merges_by_height")
    if table is None or table.empty:
        raise ValueError(f"{run.folder}: no merges_by_height.csv (full runs made before a04ea13 lack it)")
    t0, t1, merged = merges_between(table, window or window_of(run.timeseries)[0], run.folder)
    times = [float(t) for t in run.snapshot_times() if t0 <= t <= t1]
    if not times:
        raise ValueError(f"{run.folder}: no droplet snapshot within {t0:g}-{t1:g} s (the merge table's rows): "
                         "a stored reference keeps few snapshots; give the run folder or another window")
    case, g = run.case, run.case.geometry
    height = float(g.height)
    cell = float(case.fulldem.cell_size) if cell is None else float(cell)
    places = merged[["merges_under_inlet", "merges_elsewhere"]].to_numpy()
    bands = len(places)
    inlet = Inlet(tuple(case.inlet_center), 0.5 * g.inlet_diameter, height, g.inlet_length or 0.0)
    volumes = np.outer(np.full(bands, height / bands), [inlet.area, g.width * g.depth - inlet.area])
    rates, mixed, held, volume, kernels, mixed_shear = [], [], [], [], [], []
    for t in times:
        _, d = run.droplets(t)
        position = d[["x", "y", "z"]].to_numpy()
        diameter = d["diameter"].to_numpy()
        u = settling_velocity(case, diameter, d["density"].to_numpy())
        rates.append(cell_collision_rates(position, diameter, u, cell, height, bands))
        k = np.clip(np.floor(position[:, 2] / height * bands).astype(np.int64), 0, bands - 1)
        under = inlet.contains(position[:, 0], position[:, 1])
        mixed.append(region_collision_rates(k, under, diameter, u, volumes))
        held.append(np.bincount(k, minlength=bands))
        place = np.where(under, 0, 1)
        matte = np.zeros((bands, 2))
        np.add.at(matte, (k, place), math.pi / 6.0 * diameter**3)
        volume.append(matte)
        kernels.append(_region_kernels(run, t, position, diameter, u, inlet, bands, (k, place)) if shear else None)
        if kernels[-1] is not None:
            with np.errstate(divide="ignore", invalid="ignore"):
                rate_here = kernels[-1][2] / kernels[-1][3]  # the snapshot's shear rate at each region's droplets
            mixed_shear.append(region_shear_rates(k, under, diameter, rate_here, volumes))
    duration = t1 - t0
    rates = np.array(rates)
    totals = rates.sum(axis=1)
    scatter = float(totals.std(ddof=1) / math.sqrt(len(totals)) / totals.mean()) if len(totals) > 1 else math.nan
    mixed = np.mean(mixed, axis=0) * duration
    if all(x is not None for x in kernels):
        gravitational, shearing = (np.mean([x[i] for x in kernels], axis=0) * duration for i in (0, 1))
        at_droplets, counted = (np.sum([x[i] for x in kernels], axis=0) for i in (2, 3))
        with np.errstate(divide="ignore", invalid="ignore"):
            shear_rate = np.where(counted > 0, at_droplets / counted, np.nan)
        mixed_shear = np.mean(mixed_shear, axis=0) * duration
    else:
        gravitational = shearing = shear_rate = mixed_shear = np.full((bands, 2), np.nan)
    volume = np.mean(volume, axis=0)
    table = pd.DataFrame({"z": merged["z"].to_numpy(), "held": np.mean(held, axis=0),
                          "merges_under_inlet": places[:, 0], "merges_elsewhere": places[:, 1],
                          "collisions": rates.mean(axis=0) * duration,
                          "mixed_under_inlet": mixed[:, 0], "mixed_elsewhere": mixed[:, 1],
                          "gravitational_under_inlet": gravitational[:, 0],
                          "gravitational_elsewhere": gravitational[:, 1],
                          "shear_under_inlet": shearing[:, 0], "shear_elsewhere": shearing[:, 1],
                          "mixed_shear_under_inlet": mixed_shear[:, 0], "mixed_shear_elsewhere": mixed_shear[:, 1],
                          "volume_under_inlet": volume[:, 0], "volume_elsewhere": volume[:, 1],
                          "shear_rate_under_inlet": shear_rate[:, 0], "shear_rate_elsewhere": shear_rate[:, 1]})
    return table, {"window": (t0, t1), "snapshots": times, "cell": cell, "rate_scatter": scatter}


def efficiencies(table: pd.DataFrame, meta: dict) -> dict:
    """What a :func:`measure_collisions` table says: {"window", "snapshots", "cell" (from ``meta``), "bands" (the
    table with efficiency [-] cell by cell, efficiency_under_inlet and efficiency_elsewhere [-] well mixed, per
    band), "efficiency" (all bands, cell by cell) [-], "standard_error" [-] (the merges' Poisson count and the
    rate's scatter over the snapshots, in quadrature), "mixed" ({"under_inlet", "elsewhere"}: all bands' merges in
    the region over its well-mixed collisions) [-], "kernels" (:func:`kernel_fit` of the band regions' merges on
    their gravitational and shear collisions, plus "shear_over_gravitational", the ratio of the collision totals;
    None without the shear columns)}."""
    bands = table.copy()
    places = bands[["merges_under_inlet", "merges_elsewhere"]].to_numpy()
    merges = places.sum(axis=1)
    mixed = bands[["mixed_under_inlet", "mixed_elsewhere"]].to_numpy()
    with np.errstate(divide="ignore", invalid="ignore"):
        bands["efficiency"] = np.where(bands["collisions"] > 0, merges / bands["collisions"], np.nan)
        per_region = np.where(mixed > 0, places / mixed, np.nan)
    bands["efficiency_under_inlet"], bands["efficiency_elsewhere"] = per_region[:, 0], per_region[:, 1]
    total_merges, total_collisions = float(merges.sum()), float(bands["collisions"].sum())
    efficiency = total_merges / total_collisions if total_collisions > 0 else math.nan
    relative = 1.0 / total_merges if total_merges > 0 else math.inf
    if math.isfinite(meta.get("rate_scatter", math.nan)):
        relative += meta["rate_scatter"] ** 2
    region_totals = mixed.sum(axis=0)
    mixed_efficiency = {place: (float(places[:, i].sum() / region_totals[i]) if region_totals[i] > 0 else math.nan)
                        for i, place in enumerate(("under_inlet", "elsewhere"))}
    shearing = bands[["shear_under_inlet", "shear_elsewhere"]].to_numpy()
    fit = None
    if np.isfinite(shearing).all():
        gravitational = bands[["gravitational_under_inlet", "gravitational_elsewhere"]].to_numpy()
        fit = kernel_fit(places, gravitational, shearing)
        fit["shear_over_gravitational"] = float(shearing.sum() / gravitational.sum())
    return {"window": tuple(meta["window"]), "snapshots": list(meta["snapshots"]), "cell": meta["cell"],
            "bands": bands, "efficiency": efficiency, "standard_error": efficiency * math.sqrt(relative),
            "mixed": mixed_efficiency, "kernels": fit}


def band_efficiency(run, window: tuple[float, float] | None = None, cell: float | None = None,
                    shear: bool = True) -> dict:
    """The collision efficiency of ``run`` (a full run folder or stored reference, or an :class:`analysis.Run`)
    band by band: :func:`efficiencies` of :func:`measure_collisions` (same arguments), or, for a stored reference
    that keeps a :data:`COLLISIONS_FILE`, no ``cell`` is asked for and ``window`` is None or the file's own window
    (within 1 ms at either end), of that file (measured on the whole run folder when it was stored; the reference's
    own few snapshots would give a measure over one or two of them)."""
    run = _as_run(run)
    stored = Path(run.folder) / COLLISIONS_FILE
    if run.is_reference and stored.is_file() and cell is None:
        table, meta = read_collisions(stored)
        if window is None or all(abs(float(a) - b) <= 1e-3 for a, b in zip(window, meta["window"])):
            return efficiencies(table, meta)
    return efficiencies(*measure_collisions(run, window, cell, shear))


def write_collisions(run_folder, dest) -> Path:
    """Measure the run folder (or :class:`analysis.Run`) ``run_folder`` (:func:`measure_collisions` over its steady window or last third) and
    write :data:`COLLISIONS_FILE` into the folder ``dest`` (atomically), the window, snapshots, cell and the rate's
    scatter in its header."""
    from settler.output import atomic_write_text, units_line

    table, meta = measure_collisions(run_folder)
    header = units_line(COLLISIONS_UNITS) + window_header(meta["window"], meta["snapshots"], {
        "cell": f"{meta['cell']!r} m", "rate_scatter": repr(meta["rate_scatter"])})
    path = Path(dest) / COLLISIONS_FILE
    atomic_write_text(path, header + table.to_csv(index=False, float_format="%.9g"))
    return path


def read_collisions(path) -> tuple[pd.DataFrame, dict]:
    """The (table, meta) a :func:`write_collisions` file holds."""
    fields = read_window_header(path)
    meta = {"window": fields["window"], "cell": float(fields["cell"].split()[0]),
            "rate_scatter": float(fields["rate_scatter"]), "snapshots": fields["snapshots"]}
    return pd.read_csv(path, comment="#"), meta


def _region_kernels(run, time, position, diameter, velocity, inlet, bands, where):
    """(gravitational, shear) collisions per second [1/s], (bands, 2) under the inlet and elsewhere, summed cell by
    cell on the slag grid of the snapshot at ``time`` with its own shear rates, then the sum of the shear rate [1/s]
    at the droplets and their number [-], (bands, 2) each, the droplets placed by ``where`` = (band, 0 under the
    inlet / 1 elsewhere) per droplet; None where the snapshot's slag is not a whole grid (a stored reference)."""
    from .files import NoData

    try:
        _, centres, slag_velocity = run.slag(time)
        rate, edge = cell_shear_rates(centres, slag_velocity)
    except (NoData, ValueError):
        return None
    shape = np.array(rate.shape)
    index = np.clip(np.floor(position / edge).astype(np.int64), 0, shape - 1)
    key = (index[:, 0] * shape[1] + index[:, 1]) * shape[2] + index[:, 2]
    cells = np.arange(int(np.prod(shape)))
    centre = np.column_stack([cells // (shape[1] * shape[2]), (cells // shape[2]) % shape[1], cells % shape[2]])
    centre = (centre + 0.5) * edge
    height = float(shape[2] * edge)
    cell_band = np.clip(np.floor(centre[:, 2] / height * bands).astype(np.int64), 0, bands - 1)
    place = np.where(inlet.contains(centre[:, 0], centre[:, 1]), 0, 1)
    gravitational, shearing = np.zeros(len(cells)), np.zeros(len(cells))
    keys, sums = pair_sums(key, diameter, velocity)
    gravitational[keys] = math.pi * sums / edge**3
    keys, sums = shear_pair_sums(key, diameter)
    shearing[keys] = (4.0 / 3.0) * rate.reshape(-1)[keys] * sums / edge**3
    out = []
    for values in (gravitational, shearing):
        total = np.zeros((bands, 2))
        np.add.at(total, (cell_band, place), values)
        out.append(total)
    at_droplets, counted = np.zeros((bands, 2)), np.zeros((bands, 2))
    np.add.at(at_droplets, where, rate.reshape(-1)[key])
    np.add.at(counted, where, 1.0)
    return out + [at_droplets, counted]
