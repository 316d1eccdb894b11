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
strong shear) and elsewhere (weak shear) give them leverage apart; their correlation is reported.

The efficiency of a band is its merges between the table's rows nearest the window over the time integral of its
collision rate, taken as the mean over the snapshots in the window times its length. Standard error: the Poisson
count of the merges and the standard error of the mean rate over the snapshots, in quadrature (one snapshot: the
rate's scatter is unknown and only the count's part is given).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from settler.derived import settling_velocity
from settler.output import PROFILE_BANDS


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
    centres = np.asarray(centres, dtype=float)
    axes = [np.unique(np.round(centres[:, k], 12)) for k in range(3)]
    shape = tuple(len(x) for x in axes)
    if min(shape) < 2 or np.prod(shape) != len(centres):
        raise ValueError(f"slag grid of {len(centres)} cells with {shape} distinct coordinates: the shear rate needs "
                         "the whole three-dimensional grid (a run folder's fluid snapshot, not a stored plane)")
    edge = float(axes[0][1] - axes[0][0])
    order = np.lexsort((centres[:, 2], centres[:, 1], centres[:, 0]))
    v = np.asarray(velocity, dtype=float)[order].reshape(*shape, 3)
    grad = np.stack([np.stack(np.gradient(v[..., i], *[x[1] - x[0] for x in axes]), axis=-1) for i in range(3)],
                    axis=-2)  # [..., i, j] = d v_i / d x_j
    strain = 0.5 * (grad + np.swapaxes(grad, -1, -2))
    return np.sqrt(2.0 * (strain * strain).sum(axis=(-1, -2))), edge


def kernel_fit(merges, gravitational, shear) -> dict:
    """The two efficiencies of merges = E_g C_g + E_s C_s over the regions given (arrays of one shape: merges [-] and
    the gravitational and shear collisions [-] of each), weighted least squares with Poisson weights 1 / max(merges,
    1); the standard errors from the weighted normal matrix, scaled by the reduced chi-square where it exceeds 1
    (scatter beyond the count's). Returns {"gravitational", "shear" (the efficiencies) [-], "standard_errors" (2,),
    "correlation" [-], "chi2_reduced" [-], "regions" (used: those with collisions) [-]}."""
    y = np.asarray(merges, dtype=float).reshape(-1)
    x = np.column_stack([np.asarray(gravitational, dtype=float).reshape(-1),
                         np.asarray(shear, dtype=float).reshape(-1)])
    used = x.sum(axis=1) > 0
    y, x = y[used], x[used]
    w = 1.0 / np.maximum(y, 1.0)
    normal = x.T @ (x * w[:, None])
    covariance = np.linalg.inv(normal)
    coef = covariance @ (x.T @ (w * y))
    dof = max(len(y) - 2, 1)
    chi2 = float((w * (y - x @ coef) ** 2).sum()) / dof
    covariance = covariance * max(chi2, 1.0)
    se = np.sqrt(np.diag(covariance))
    return {"gravitational": float(coef[0]), "shear": float(coef[1]), "standard_errors": se,
            "correlation": float(covariance[0, 1] / (se[0] * se[1])), "chi2_reduced": chi2, "regions": int(used.sum())}


def band_efficiency(run, window: tuple[float, float] | None = None, cell: float | None = None,
                    shear: bool = True) -> dict:
    """The collision efficiency of ``run`` (a full run folder or stored reference, or an :class:`analysis.Run`)
    band by band over ``window`` (start, end) [s] (default: its steady window, else its last third), cells of edge
    ``cell`` [m] (default: the run's ``fulldem.cell_size``). Returns {"window" (the merge table's rows) [s],
    "snapshots" (their times) [s], "cell" [m], "bands" (a DataFrame: z [m], held (mean droplets) [-], merges [-],
    collisions [-], efficiency [-], and the same with each band's two regions well mixed (module docstring):
    collisions_under_inlet, collisions_elsewhere, efficiency_under_inlet, efficiency_elsewhere [-]), "efficiency"
    (all bands, cell by cell) [-], "standard_error" [-], "mixed" ({"under_inlet", "elsewhere"}: all bands' merges in
    the region over its well-mixed collisions) [-], "kernels" (with ``shear`` and the run's whole slag grid at every
    snapshot: :func:`kernel_fit` of the bands' merges by region on their cell-by-cell gravitational and shear
    collisions, plus "shear_over_gravitational", the ratio of the two collision totals; else None)}; the table then
    also holds shear_under_inlet and shear_elsewhere, the shear collisions [-]. Raises ValueError for a run without
    merges_by_height.csv or without a droplet snapshot inside the window."""
    from .evidence import merge_shares
    from .runs import load_run

    run = load_run(run)
    shares = merge_shares(run, window)
    t0, t1 = shares["window"]
    times = [float(t) for t in run.snapshot_times() if t0 <= t <= t1]
    if not times:
        raise ValueError(f"{run.folder}: no droplet snapshot within {t0:g}-{t1:g} s (the merge table's rows): "
                         "a stored reference keeps few snapshots; give the run folder or another window")
    case = run.case
    height = float(case.geometry.height)
    cell = float(case.fulldem.cell_size) if cell is None else float(cell)
    from fulldem.boundaries import Inlet

    places = shares["bands"][["merges_under_inlet", "merges_elsewhere"]].to_numpy()
    merges = places.sum(axis=1)
    bands = len(merges)
    g = case.geometry
    inlet = Inlet(tuple(case.inlet_center), 0.5 * g.inlet_diameter, height, g.inlet_length or 0.0)
    volumes = np.outer(np.full(bands, height / bands), [inlet.area, g.width * g.depth - inlet.area])
    rates, regional, held, kernels = [], [], [], []
    for t in times:
        _, d = run.droplets(t)
        position = d[["x", "y", "z"]].to_numpy()
        diameter = d["diameter"].to_numpy()
        u = settling_velocity(case, diameter, d["density"].to_numpy())
        rates.append(cell_collision_rates(position, diameter, u, cell, height, bands))
        k = np.clip(np.floor(position[:, 2] / height * bands).astype(np.int64), 0, bands - 1)
        regional.append(region_collision_rates(k, inlet.contains(position[:, 0], position[:, 1]), diameter, u,
                                               volumes))
        held.append(np.bincount(k, minlength=bands))
        if shear:
            kernels.append(_region_kernels(run, t, position, diameter, u, k, inlet, bands))
    shear = shear and all(x is not None for x in kernels)
    rates, held = np.array(rates), np.array(held)
    duration = t1 - t0
    collisions = rates.mean(axis=0) * duration
    region_collisions = np.mean(regional, axis=0) * duration
    total_merges, total_collisions = float(merges.sum()), float(collisions.sum())
    efficiency = total_merges / total_collisions if total_collisions > 0 else math.nan
    relative = 1.0 / total_merges if total_merges > 0 else math.inf
    if len(times) > 1:
        totals = rates.sum(axis=1)
        relative += (totals.std(ddof=1) / math.sqrt(len(totals)) / totals.mean()) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        per_band = np.where(collisions > 0, merges / collisions, np.nan)
        per_region = np.where(region_collisions > 0, places / region_collisions, np.nan)
    table = pd.DataFrame({"z": shares["bands"]["z"].to_numpy(), "held": held.mean(axis=0), "merges": merges,
                          "collisions": collisions, "efficiency": per_band,
                          "collisions_under_inlet": region_collisions[:, 0],
                          "collisions_elsewhere": region_collisions[:, 1],
                          "efficiency_under_inlet": per_region[:, 0], "efficiency_elsewhere": per_region[:, 1]})
    totals = region_collisions.sum(axis=0)
    mixed = {place: (float(places[:, i].sum() / totals[i]) if totals[i] > 0 else math.nan)
             for i, place in enumerate(("under_inlet", "elsewhere"))}
    fit = None
    if shear:
        gravitational, shearing = (np.mean([x[i] for x in kernels], axis=0) * duration for i in (0, 1))
        table["shear_under_inlet"], table["shear_elsewhere"] = shearing[:, 0], shearing[:, 1]
        fit = kernel_fit(places, gravitational, shearing)
        fit["shear_over_gravitational"] = float(shearing.sum() / gravitational.sum())
    return {"window": (t0, t1), "snapshots": times, "cell": cell, "bands": table, "efficiency": efficiency,
            "standard_error": efficiency * math.sqrt(relative), "mixed": mixed, "kernels": fit}


def _region_kernels(run, time, position, diameter, velocity, band, inlet, bands):
    """(gravitational, shear) collisions per second [1/s], (bands, 2) under the inlet and elsewhere, summed cell by
    cell on the slag grid of the snapshot at ``time`` with its own shear rates; None where the snapshot's slag is
    not a whole grid (a stored reference)."""
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
    return out
