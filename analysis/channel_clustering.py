"""How much more often a full run's droplets under the inlet meet than popbal's channel, mixing them, counts (SI units).

popbal's channel collides the droplets it holds as if they were mixed over its section pi R_c^2 in each cell of
height. A full run's droplets within R_c of the inlet axis are not mixed there: most of them crowd into a narrow
core. For the droplets of one height band within a radius R of the axis this module sums the gravitational
collisions two ways, as :mod:`analysis.band_efficiency` does for whole bands:

- **cell by cell**, C_cell = sum over the grid's cubic cells of edge h of sum over the pairs in the cell of
  pi (a_i + a_j)^2 abs(U_i - U_j) / h^3 (what the full engine's merges follow: their ratio, the cell efficiency, is
  0.6-0.98 in every band of the training runs, ``collisions_by_height.csv``);
- **well mixed** over the disk's slab, C_mixed = sum over all the band's pairs within R of the same kernel over
  pi R^2 h_b (h_b the band's height): what popbal's channel of radius R counts holding those droplets;

with U the single-droplet terminal velocity of each droplet (:func:`settler.derived.settling_velocity`). Their ratio
S = C_cell / C_mixed [-] is the **clustering factor** a channel of radius R lacks: a channel holding a run's droplets
would merge them as the run does with efficiency E_cell S. The **collision radius** b = R / sqrt(S) [m] is the
radius of the disk over which the droplets, mixed, would meet as often as they do (b = R for droplets spread
uniformly over the disk; for droplets uniform over an area A inside it, S = pi R^2 / A exactly in expectation, which
tests/test_channel_clustering.py checks).

``python -m analysis.channel_clustering RUN... [--radius MM]...`` prints S and b per band and over the interior
bands (between the top one, the roof layer's, and the bottom one, the floor's); the default radii are popbal's
channel radius under the run's case with the current calibration layer (``--layer`` another) and the inlet radius. A stored
reference keeps one or few snapshots: S is measured on those, a run folder's every snapshot in the window is used.

What it measures (2026-12-07, the stored training runs' last snapshot, docs/guide/reduced-model.md): at popbal's
channel radius under zones_core, S = 1.75-3.0 in the demo families (R_c = 9.5 mm at 2.5 mm cells) and 6.8-6.9 in
simple and cubic (R_c = 37.9 mm at 5 mm cells); b = 5.4-7.2 and 14.4-14.5 mm.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from settler.derived import settling_velocity
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
                    bands: int = PROFILE_BANDS) -> pd.DataFrame:
    """The :data:`CLUSTERING_UNITS` table of one snapshot's droplets within ``radius`` [m] of the vertical axis
    through ``centre`` (x, y) [m]: position (n, 3) [m], diameter (n,) [m], velocity (n,) [m/s] (each droplet's
    settling velocity), grid cells of edge ``cell`` [m] from the origin, ``bands`` equal height bands of ``height``
    [m]. ValueError for a radius, cell or height that is not positive."""
    if not (radius > 0.0 and cell > 0.0 and height > 0.0 and bands >= 1):
        raise ValueError(f"radius = {radius!r} m, cell = {cell!r} m, height = {height!r} m, bands = {bands!r}: "
                         "all must be > 0")
    position = np.asarray(position, dtype=float).reshape(-1, 3)
    diameter = np.asarray(diameter, dtype=float)
    velocity = np.asarray(velocity, dtype=float)
    inside = np.hypot(position[:, 0] - centre[0], position[:, 1] - centre[1]) < radius
    position, diameter, velocity = position[inside], diameter[inside], velocity[inside]
    band = np.clip(np.floor(position[:, 2] / height * bands).astype(np.int64), 0, bands - 1)
    cells = cell_collision_rates(position, diameter, velocity, cell, height, bands)
    keys, sums = pair_sums(band, diameter, velocity)
    mixed = np.zeros(bands)
    mixed[keys] = math.pi * sums / (math.pi * radius**2 * height / bands)
    return _table(height, bands, np.bincount(band, minlength=bands), cells, mixed, radius)


def _table(height, bands, droplets, cells, mixed, radius) -> pd.DataFrame:
    with np.errstate(divide="ignore", invalid="ignore"):
        clustering = np.where(mixed > 0.0, cells / mixed, np.nan)
        collision_radius = np.where(clustering > 0.0, radius / np.sqrt(clustering), np.nan)
    return pd.DataFrame({"z": (np.arange(bands) + 0.5) * height / bands, "droplets": droplets,
                         "cell_collisions": cells, "mixed_collisions": mixed, "clustering": clustering,
                         "collision_radius": collision_radius})


def interior(table: pd.DataFrame, radius: float) -> dict:
    """{"clustering" S [-], "collision_radius" b [m]} over the interior bands of a :func:`disk_clustering` table (all
    but the top and the bottom one, where the roof and floor layers are): the sums of their collisions' ratio. NaN
    where they hold no pair."""
    rows = table.sort_values("z").iloc[1:-1]
    mixed = float(rows["mixed_collisions"].sum())
    s = float(rows["cell_collisions"].sum()) / mixed if mixed > 0.0 else math.nan
    return {"clustering": s, "collision_radius": radius / math.sqrt(s) if s > 0.0 else math.nan}


def channel_radius(case_file, layer: str | None = None) -> float:
    """popbal's channel radius R_c [m] in the case of ``case_file`` with the calibration layer ``layer`` applied
    (``case.calibration = layer``; None: :data:`analysis.calibration.bands.CURRENT_LAYER`): :func:`popbal.setup`'s.
    settler.cases.CaseError for a name that is not a layer."""
    import popbal
    from settler.cases import load_case

    from .calibration.bands import CURRENT_LAYER

    return float(popbal.setup(load_case(case_file, {"case.calibration": layer or CURRENT_LAYER})).channel_radius)


def measure_clustering(run, radius: float, window: tuple[float, float] | None = None) -> tuple[pd.DataFrame, dict]:
    """(table, meta) of a full run folder, stored reference or :class:`analysis.Run`: :func:`disk_clustering` about
    its inlet axis at ``radius`` [m], its cells (``fulldem.cell_size``) and height, summed over its droplet snapshots
    in ``window`` (default: its steady window, else its last third); meta {"window", "snapshots", "radius",
    "cell"}. ValueError where the window holds no droplet snapshot or the inlet is a slot (a row of plumes)."""
    from .steady import window_snapshots

    run = _load(run)
    case, g = run.case, run.case.geometry
    if g.inlet_length:
        raise ValueError(f"{run.folder}: a slot inlet ({g.inlet_length:g} m long) feeds a row of plumes, not one "
                         "axis; the channel's clustering is measured about one axis")
    window, times = window_snapshots(run, window)
    if not times:
        raise ValueError(f"{run.folder}: no droplet snapshot within {window[0]:g}-{window[1]:g} s (a stored "
                         "reference keeps few; give the run folder or another window)")
    cell, height = float(case.fulldem.cell_size), float(g.height)
    total = None
    for t in times:
        _, d = run.droplets(t)
        diameter = d["diameter"].to_numpy(dtype=float)
        u = settling_velocity(case, diameter, d["density"].to_numpy(dtype=float))
        one = disk_clustering(d[["x", "y", "z"]].to_numpy(dtype=float), diameter, u, tuple(case.inlet_center),
                              radius, cell, height)
        total = one if total is None else total.assign(
            **{c: total[c] + one[c] for c in ("droplets", "cell_collisions", "mixed_collisions")})
    table = _table(height, len(total), total["droplets"].to_numpy(), total["cell_collisions"].to_numpy(),
                   total["mixed_collisions"].to_numpy(), radius)
    return table, {"window": window, "snapshots": list(times), "radius": radius, "cell": cell}


def _load(run):
    """``run`` as an :class:`analysis.Run` (a folder is loaded with :func:`analysis.load_run`)."""
    from pathlib import Path

    from .runs import load_run

    return load_run(run) if isinstance(run, (str, Path)) else run


def main(argv=None) -> int:
    """``python -m analysis.channel_clustering RUN... [--radius MM]... [--window START:END]``: exit 0, or 2 with one
    line naming the run or the value that failed."""
    import argparse
    import sys

    from pathlib import Path

    from settler.cases import CaseError

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
    parser.add_argument("--layer", help="the calibration layer popbal's default radius is taken under (default "
                        "the current one, analysis.calibration.bands.CURRENT_LAYER)")
    parser.add_argument("--window", help="START:END [s]; default each run's steady window, else its last third")
    args = parser.parse_args(argv)
    try:
        window = parse_window(args.window) if args.window else None
        for value in args.radius or []:
            if not (value > 0.0 and math.isfinite(value)):
                raise ValueError(f"--radius {value!r}: a radius in mm must be a positive number")
    except ValueError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    for folder in args.runs:
        try:
            run = _load(folder)
            radii = [r * 1e-3 for r in args.radius] if args.radius else \
                [channel_radius(Path(run.folder) / "case.toml", args.layer),
                 0.5 * float(run.case.geometry.inlet_diameter)]
            for radius in radii:
                table, meta = measure_clustering(run, radius, window)
                _report(folder, table, meta)
        except (OutputError, ValueError, OSError, NoData, CaseError) as exc:
            print(f"{prog}: {exc}", file=sys.stderr)
            return 2
    return 0


def _report(folder, table, meta) -> None:
    inner = interior(table, meta["radius"])
    print(f"{folder}: within R = {meta['radius'] * 1e3:.1f} mm of the inlet axis, cells {meta['cell'] * 1e3:g} mm, "
          f"{len(meta['snapshots'])} snapshot(s) in {meta['window'][0]:g}-{meta['window'][1]:g} s: interior S = "
          f"{inner['clustering']:.2f}, b = {inner['collision_radius'] * 1e3:.1f} mm")
    for row in table.sort_values("z", ascending=False).itertuples():
        print(f"  z {row.z:6.3f} m  droplets {row.droplets:8.0f}  S {row.clustering:6.2f}  "
              f"b {row.collision_radius * 1e3:6.1f} mm")


if __name__ == "__main__":
    raise SystemExit(main())
