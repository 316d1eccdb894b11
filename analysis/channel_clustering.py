"""How much more often a full run's droplets under the inlet meet than popbal's channel, mixing them, counts (SI units).

popbal's channel collides the droplets it holds as if they were mixed over its section pi R_c^2 in each cell of
height. A full run's droplets within R_c of the inlet axis are not mixed there: most of them crowd into a narrow
core. The disk of radius R about the axis is taken as the grid columns whose centres lie within R (cubic cells of
edge h from the origin, the run's own grid by default; area N_col h^2, equivalent radius R_eq = h sqrt(N_col / pi)),
each cell and its droplets in the height band that holds the cell's centre. For a band's droplets in the disk this
module sums the gravitational collisions two ways, as :mod:`analysis.band_efficiency` does for whole bands:

- **cell by cell**, C_cell = sum over the cells of sum over the pairs in the cell of
  pi (a_i + a_j)^2 abs(U_i - U_j) / h^3 (the full engine's merges follow these: the kernel run's merges over its
  cell-by-cell collisions give the collision efficiency E = 0.80 that zones_core takes);
- **well mixed** over the disk's slab, C_mixed = the same kernel summed over all the band's pairs in the disk over
  the slab's volume (its cells'): what popbal's channel of that section counts holding those droplets;

with U the single-droplet terminal velocity of each droplet (:func:`settler.derived.settling_velocity`). Their ratio
S = C_cell / C_mixed [-] is the **clustering factor** a channel of that section lacks: holding a run's droplets, it
would merge them as the run does with efficiency E S. The **collision radius** b = R_eq / sqrt(S) [m] is the radius
of the disk over which the droplets, mixed, would meet as often as they do. Droplets uniform over the disk give
S = 1 in expectation in every band, droplets uniform over whole cells of area A inside it S = N_col h^2 / A
(tests/test_channel_clustering.py checks both, the first with bands that are not whole numbers of cells). A disk
of fewer than :data:`MIN_COLUMNS` columns is refused: the clustering within it is not resolved.

``python -m analysis.channel_clustering RUN... [--radius MM]... [--cell MM]`` prints S and b per band and over the
interior bands (between the top one, the roof layer's, and the bottom one, the floor's); the default radii are
popbal's channel radius under the run's case with the current calibration layer (``--layer`` another) and the inlet
radius; ``--cell`` measures runs of different grids on one cell. The registered hold-outs are refused (the measure
is for designing closures). A stored reference keeps one or few snapshots: S is measured on those, a run folder's
every snapshot in the window is used.

What it measures (2026-12-07, the stored training runs' last snapshot, docs/guide/reduced-model.md): at popbal's
channel radius under zones_core, S = 1.77-3.12 in the demo families (R_c = 9.5 mm at 2.5 mm cells) and 6.94 and
6.75 in simple and cubic (R_c = 37.9 mm at 5 mm cells); b = 5.3-7.0 and 14.4-14.6 mm.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from settler.output import PROFILE_BANDS

from .band_efficiency import cell_collision_rates, pair_sums

#: Columns of :func:`disk_clustering`'s table: name -> (unit, meaning).
CLUSTERING_UNITS = {
    "z": ("m", "height of the band's centre above the bottom"),
    "droplets": ("-", "droplets in the band within the radius, summed over the snapshots"),
    "cell_collisions": ("1/s", "their gravitational collisions cell by cell, summed over the snapshots"),
    "mixed_collisions": ("1/s", "their gravitational collisions mixed over the disk's slab, summed over the snapshots"),
    "clustering": ("-", "S = cell_collisions / mixed_collisions (NaN: no pair)"),
    "collision_radius": ("m", "b = radius / sqrt(S) (NaN: no pair or no collision)"),
}


def disk_clustering(position, diameter, velocity, centre, radius: float, cell: float, height: float,
                    extent: tuple[float, float], bands: int = PROFILE_BANDS) -> pd.DataFrame:
    """The :data:`CLUSTERING_UNITS` table of one snapshot's droplets in the grid columns whose centres lie within
    ``radius`` [m] of the vertical axis through ``centre`` (x, y) [m]: position (n, 3) [m], diameter (n,) [m],
    velocity (n,) [m/s] (each droplet's settling velocity), cubic cells of edge ``cell`` [m] from the origin over a
    box ``extent`` (width, depth) [m] wide, ``bands`` equal height bands of ``height`` [m], each cell (and so each
    of its droplets) in the band that holds the cell's centre, as :func:`analysis.band_efficiency.
    cell_collision_rates` counts it. The disk is those whole columns (area N_col h^2, its equivalent radius
    sqrt(N_col / pi) h in ``meta``), so that droplets spread uniformly over it give S = 1 in expectation and a cell
    is never cut. ValueError for a radius, cell, height or extent that is not positive, or a disk of fewer than
    :data:`MIN_COLUMNS` columns (the measure needs the disk resolved)."""
    if not (radius > 0.0 and cell > 0.0 and height > 0.0 and bands >= 1 and min(extent) > 0.0):
        raise ValueError(f"radius = {radius!r} m, cell = {cell!r} m, height = {height!r} m, extent = {extent!r} m, "
                         f"bands = {bands!r}: all must be > 0")
    columns = disk_columns(centre, radius, cell, extent)
    if len(columns) < MIN_COLUMNS:
        raise ValueError(f"a radius of {radius * 1e3:g} mm holds {len(columns)} grid column(s) of {cell * 1e3:g} mm "
                         f"(at least {MIN_COLUMNS} needed): the droplets' clustering within it is not resolved; "
                         "give a larger radius")
    position = np.asarray(position, dtype=float).reshape(-1, 3)
    diameter = np.asarray(diameter, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    index = np.floor(position / cell).astype(np.int64)
    inside = np.isin(index[:, 0] * COLUMN_KEY + index[:, 1], columns[:, 0] * COLUMN_KEY + columns[:, 1])
    position, diameter, velocity, index = position[inside], diameter[inside], velocity[inside], index[inside]
    band = np.clip(np.floor((index[:, 2] + 0.5) * cell / height * bands).astype(np.int64), 0, bands - 1)
    cells = cell_collision_rates(position, diameter, velocity, cell, height, bands)
    keys, sums = pair_sums(band, diameter, velocity)
    area = len(columns) * cell**2
    layers = np.arange(int(math.ceil(height / cell - 1e-9)))  # the cell layers, each in the band of its centre
    slab = np.bincount(np.clip(np.floor((layers + 0.5) * cell / height * bands).astype(np.int64), 0, bands - 1),
                       minlength=bands) * cell * area  # each band's volume of the disk's cells [m^3]
    mixed = np.zeros(bands)
    mixed[keys] = math.pi * sums / slab[keys]
    return _table(height, bands, np.bincount(band, minlength=bands), cells, mixed, math.sqrt(area / math.pi))


#: The fewest grid columns a disk must hold for :func:`disk_clustering` to measure within it [chosen: a disk of 12
#: columns is about two cells across, the least over which a core narrower than the disk can show; the demo at 5 mm
#: cells sits on it at R = 9.4 mm, so its collision radius there is at the limit of what the grid resolves].
MIN_COLUMNS = 12
#: Key of a column (i, j): i COLUMN_KEY + j (grids up to a million cells on a side).
COLUMN_KEY = 1_000_003


def disk_columns(centre, radius: float, cell: float, extent: tuple[float, float]) -> np.ndarray:
    """(N_col, 2) [int] the (i, j) of the grid columns (cells of edge ``cell`` [m] from the origin, over a box
    ``extent`` (width, depth) [m]) whose centres lie within ``radius`` [m] of ``centre`` (x, y) [m]."""
    i = np.arange(int(math.ceil(extent[0] / cell - 1e-9)))
    j = np.arange(int(math.ceil(extent[1] / cell - 1e-9)))
    ii, jj = np.meshgrid(i, j, indexing="ij")
    near = np.hypot((ii + 0.5) * cell - centre[0], (jj + 0.5) * cell - centre[1]) < radius
    return np.column_stack([ii[near], jj[near]])


def _table(height, bands, droplets, cells, mixed, radius) -> pd.DataFrame:
    with np.errstate(divide="ignore", invalid="ignore"):
        clustering = np.where(mixed > 0.0, cells / mixed, np.nan)
        collision_radius = np.where(clustering > 0.0, radius / np.sqrt(clustering), np.nan)
    table = pd.DataFrame({"z": (np.arange(bands) + 0.5) * height / bands, "droplets": droplets,
                          "cell_collisions": cells, "mixed_collisions": mixed, "clustering": clustering,
                          "collision_radius": collision_radius})
    table.attrs["radius"] = float(radius)  # the disk's equivalent radius sqrt(N_col / pi) h [m]
    return table


def interior(table: pd.DataFrame) -> dict:
    """{"clustering" S [-], "collision_radius" b [m]} over the interior bands of a :func:`disk_clustering` table (all
    but the top and the bottom one, where the roof and floor layers are): the ratio of their collisions' sums, and
    the disk's equivalent radius (``table.attrs["radius"]``) over its square root. NaN where they hold no pair."""
    rows = table.sort_values("z").iloc[1:-1]
    mixed = float(rows["mixed_collisions"].sum())
    s = float(rows["cell_collisions"].sum()) / mixed if mixed > 0.0 else math.nan
    return {"clustering": s, "collision_radius": table.attrs["radius"] / math.sqrt(s) if s > 0.0 else math.nan}


def channel_radius(case_file, layer: str | None = None) -> float:
    """popbal's channel radius R_c [m] in the case of ``case_file`` with the calibration layer ``layer`` applied
    (``case.calibration = layer``; None: :data:`analysis.calibration.bands.CURRENT_LAYER`): :func:`popbal.setup`'s.
    settler.cases.CaseError for a name that is not a layer, or a case popbal refuses."""
    import popbal
    from settler.cases import load_case

    from .calibration.bands import CURRENT_LAYER

    return float(popbal.setup(load_case(case_file, {"case.calibration": layer or CURRENT_LAYER})).channel_radius)


def measure_clustering(run, radius: float, window: tuple[float, float] | None = None,
                       cell: float | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder, stored reference or :class:`analysis.Run`: :func:`disk_clustering` about
    its inlet axis at ``radius`` [m] on cells of edge ``cell`` [m] (default the run's ``fulldem.cell_size``; give
    one size to compare runs of different grids), summed over its droplet snapshots in ``window`` (default: its
    steady window, else its last third); meta {"window", "snapshots", "radius" (asked), "equivalent_radius" (the
    disk's columns'), "cell"}. ValueError naming the run where the window holds no droplet snapshot, the inlet is
    a slot (a row of plumes) or the disk is not resolved."""
    from .plume_zones import axis_window, settling_snapshots

    run, window, times, _ = axis_window(run, window, (), "the channel's clustering is measured")
    case, g = run.case, run.case.geometry
    cell = float(case.fulldem.cell_size) if cell is None else float(cell)
    height, extent = float(g.height), (float(g.width), float(g.depth))
    for name, length in (("width", extent[0]), ("depth", extent[1]), ("height", height)):
        if abs(length / cell - round(length / cell)) > 1e-6:
            raise ValueError(f"{run.folder}: a measuring cell of {cell * 1e3:g} mm does not divide the box's {name} "
                             f"({length * 1e3:g} mm) into whole cells; allowed: a cell that does")
    sums = None
    for position, diameter, u in settling_snapshots(run, times):
        try:
            one = disk_clustering(position, diameter, u, tuple(case.inlet_center), radius, cell, height, extent)
        except ValueError as exc:
            raise ValueError(f"{run.folder}: {exc}") from None
        part = one[["droplets", "cell_collisions", "mixed_collisions"]].to_numpy(dtype=float)
        sums = part if sums is None else sums + part
    equivalent = one.attrs["radius"]
    table = _table(height, len(sums), sums[:, 0], sums[:, 1], sums[:, 2], equivalent)
    return table, {"window": window, "snapshots": list(times), "radius": radius, "equivalent_radius": equivalent,
                   "cell": cell}


def main(argv=None) -> int:
    """``python -m analysis.channel_clustering RUN... [--radius MM]... [--cell MM] [--layer NAME] [--window
    START:END] [--registry FILE]``: exit 0, or 2 with one line naming the run or the value that failed."""
    import argparse
    import sys
    from pathlib import Path

    from settler.cases import CaseError

    from .calibration.registry import RegistryError, load_registry, refuse_holdout_folders
    from .files import NoData, OutputError
    from .steady import parse_window

    prog = "python -m analysis.channel_clustering"
    parser = argparse.ArgumentParser(prog=prog, description=(
        "how much more often a full run's droplets within a radius of the inlet axis meet, cell by cell, than "
        "mixed over the disk (popbal's channel mixes them): the clustering factor S and the collision radius b per "
        "height band and over the interior bands"))
    parser.add_argument("runs", nargs="+", help="full run folders or stored references (a reference keeps few "
                        "snapshots; a run folder's every snapshot in the window is used)")
    parser.add_argument("--radius", type=float, action="append", metavar="MM",
                        help="radius [mm] about the inlet axis (repeatable); default popbal's channel radius under "
                             "the run's case with the calibration layer --layer, and the inlet radius")
    parser.add_argument("--cell", type=float, metavar="MM", help="the measuring cell's edge [mm]; default each "
                        "run's own grid cell (give one size to compare runs of different grids)")
    parser.add_argument("--layer", help="the calibration layer popbal's default radius is taken under (default "
                        "the current one, analysis.calibration.bands.CURRENT_LAYER)")
    parser.add_argument("--window", help="START:END [s]; default each run's steady window, else its last third")
    parser.add_argument("--registry", default="data/calibration/holdouts.toml",
                        help="the calibration's registry: its pre-registered hold-outs are refused (the measure is "
                             "for designing closures, which the hold-outs must not inform)")
    args = parser.parse_args(argv)
    try:
        window = parse_window(args.window) if args.window else None
        for name, value in [("--radius", r) for r in args.radius or []] + [("--cell", args.cell)]:
            if value is not None and not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f"{name} {value!r}: a length in mm must be a positive number")
        refuse_holdout_folders(args.runs, load_registry(args.registry), "the clustering measure")
    except (ValueError, OSError, RegistryError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    cell = args.cell * 1e-3 if args.cell else None
    from .runs import load_run

    for folder in args.runs:
        try:
            run = load_run(folder)
            radii = [r * 1e-3 for r in args.radius] if args.radius else \
                [channel_radius(Path(run.folder) / "case.toml", args.layer),
                 0.5 * float(run.case.geometry.inlet_diameter)]
            measured = [measure_clustering(run, radius, window, cell) for radius in radii]
        except (OutputError, ValueError, OSError, NoData, CaseError) as exc:
            text = str(exc)
            print(f"{prog}: {text if text.startswith(str(Path(folder))) else f'{folder}: {text}'}", file=sys.stderr)
            return 2
        for table, meta in measured:
            _report(folder, table, meta)
    return 0


def _report(folder, table, meta) -> None:
    inner = interior(table)
    print(f"{folder}: within R = {meta['radius'] * 1e3:.1f} mm of the inlet axis (grid columns of "
          f"{meta['cell'] * 1e3:g} mm, equivalent radius {meta['equivalent_radius'] * 1e3:.1f} mm), "
          f"{len(meta['snapshots'])} snapshot(s) in {meta['window'][0]:g}-{meta['window'][1]:g} s: interior S = "
          f"{inner['clustering']:.2f}, b = {inner['collision_radius'] * 1e3:.1f} mm")
    for row in table.sort_values("z", ascending=False).itertuples():
        print(f"  z {row.z:6.3f} m  droplets {row.droplets:8.0f}  S {row.clustering:6.2f}  "
              f"b {row.collision_radius * 1e3:6.1f} mm")


if __name__ == "__main__":
    raise SystemExit(main())
