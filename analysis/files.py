"""Readers of a run folder's files, shared by every analysis module; importing no other analysis module.

A run folder is what ``settler full CASE --out RUN`` (or ``settler reduced``) writes, SI units throughout: see
:mod:`analysis.figures` for the files. These readers raise :class:`NoData` (a figure's or a loader's inputs are
missing, with a one-line reason) or FileNotFoundError (not a run folder); the stored reference runs of
``data/reference`` are read by :mod:`analysis.reference`, the one loader of both kinds is :mod:`analysis.runs`.
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

from settler.output import SNAPSHOT_TABLES, OutputError, read_table


class MeasureError(ValueError):
    """A closure that cannot be measured from the runs given (none of them carries it): a cross-validation fold
    that leaves those runs out, or a registry whose levels lack them. ``settler calibrate`` reports it by name."""


class NoData(LookupError):
    """A figure's inputs are not in the run folder (a missing file, a column that is all NaN, a snapshot without
    droplets); the message is the one-line reason."""


def check_run(run) -> Path:
    """``run`` as a Path after checking that it is a run folder: a folder holding ``timeseries.csv`` or
    ``snapshots.pvd``. Raises FileNotFoundError naming the folder and what is missing."""
    folder = Path(run)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: no such run folder" if not folder.exists()
                                else f"{folder}: is a file, not a run folder")
    if not (folder / "timeseries.csv").is_file() and not (folder / "snapshots.pvd").is_file():
        raise FileNotFoundError(f"{folder}: not a run folder (no timeseries.csv and no snapshots.pvd); give the "
                                "--out folder of a 'settler full' run")
    return folder


def snapshot_files(run) -> list[tuple[float, Path | None, Path | None]]:
    """The snapshots listed in ``RUN/snapshots.pvd``: (time [s], droplets .vtu, fluid .vtu) sorted by time.

    A file is None where the collection lists none for that time or the file is not on disk. No ``snapshots.pvd``:
    an empty list. Part 0 of the collection is the droplets, part 1 the slag grid (a file without a part attribute
    is told by its name, ``droplets_*`` or ``fluid_*``).
    """
    folder = check_run(run)
    pvd = folder / "snapshots.pvd"
    if not pvd.is_file():
        return []
    try:
        root = ET.parse(pvd).getroot()
    except ET.ParseError as exc:
        raise NoData(f"snapshots.pvd cannot be read ({exc})") from None
    found: dict[float, list] = {}
    for entry in root.iter("DataSet"):
        try:
            time = float(entry.get("timestep", "nan"))
        except ValueError:
            continue
        name = entry.get("file")
        if not name or not math.isfinite(time):
            continue
        part = entry.get("part")
        is_droplets = part == "0" if part is not None else Path(name).name.startswith("droplets")
        path = folder / name
        slot = found.setdefault(time, [None, None])
        slot[0 if is_droplets else 1] = path if path.is_file() else None
    return [(t, d, f) for t, (d, f) in sorted(found.items())]


def pick_snapshot(run, time, part):
    """(time [s], file) of the snapshot nearest ``time`` [s] (None: the last; of two equally near, the later):
    its droplets file (``part`` 0) or fluid file (1). Raises NoData naming what is missing."""
    what = ("droplets", "slag")[part]
    snapshots = snapshot_files(run)
    if not snapshots:
        raise NoData("no snapshots (no snapshots.pvd, or it lists none)")
    if time is not None:
        time = float(time)
        if not math.isfinite(time):
            raise ValueError(f"time = {time!r}: give a finite snapshot time [s]")
        t, droplets, fluid = min(snapshots, key=lambda s: (abs(s[0] - time), -s[0]))
    else:
        t, droplets, fluid = snapshots[-1]
    path = (droplets, fluid)[part]
    if path is None:
        raise NoData(f"the snapshot at t = {t:g} s has no {what} file (none listed in snapshots.pvd, or "
                     "not on disk)")
    return t, path


def droplets_file(path) -> pd.DataFrame:
    """The droplets of one snapshot file (``droplets_NNNNN.vtu``) as the frame :func:`analysis.figures.read_droplets`
    describes."""
    import meshio

    mesh = meshio.read(path)
    points = np.asarray(mesh.points, dtype=float).reshape(-1, 3)
    n = len(points)
    data = mesh.point_data

    def field(name, width=None):
        if name not in data:
            return np.full((n, width) if width else n, np.nan)
        return np.asarray(data[name], dtype=float).reshape((n, width) if width else n)

    velocity = field("velocity", 3)
    frame = pd.DataFrame({"x": points[:, 0], "y": points[:, 1], "z": points[:, 2], "diameter": field("diameter"),
                          "u": velocity[:, 0], "v": velocity[:, 1], "w": velocity[:, 2],
                          "settling_velocity": -velocity[:, 2], "density": field("density"), "age": field("age")})
    for optional in ("ident", "merged"):
        if optional in data:
            frame[optional] = field(optional)
    return frame


def slag_grid(centres, velocity) -> tuple[list[np.ndarray], np.ndarray]:
    """(the x, y, z cell-centre axes [m], the velocity on the grid (nx, ny, nz, 3) [m/s]) of a slag snapshot given as
    cell ``centres`` (n, 3) [m] and ``velocity`` (n, 3) [m/s] (:func:`slag_file`) on a uniform grid. ValueError for
    cells that do not fill a three-dimensional grid (a stored reference keeps one plane of the slag)."""
    centres = np.asarray(centres, dtype=float)
    axes = [np.unique(np.round(centres[:, k], 12)) for k in range(3)]
    shape = tuple(len(x) for x in axes)
    if min(shape) < 2 or np.prod(shape) != len(centres):
        raise ValueError(f"slag grid of {len(centres)} cells with {shape} distinct coordinates: this needs the whole "
                         "three-dimensional grid (a run folder's fluid snapshot, not a stored plane)")
    order = np.lexsort((centres[:, 2], centres[:, 1], centres[:, 0]))  # x slowest, z fastest
    return axes, np.asarray(velocity, dtype=float)[order].reshape(*shape, 3)


def slag_file(path) -> tuple[np.ndarray, np.ndarray]:
    """(cell centres (n, 3) [m], cell velocity (n, 3) [m/s]) of one slag snapshot file: ``fluid_NNNNN.vti`` (image
    data, :mod:`settler.vti`) or, from runs made before it, ``fluid_NNNNN.vtu`` (hexahedra; a cell's centre is the
    mean of its 8 corner points). Raises NoData if it holds no cells with a velocity."""
    if Path(path).suffix == ".vti":
        from settler.vti import read_image

        try:
            shape, origin, spacing, fields = read_image(path)
        except ValueError as exc:
            raise NoData(str(exc)) from None
        if "velocity" not in fields or 0 in shape:
            raise NoData(f"{Path(path).name}: no cells with a velocity")
        axes = [origin[a] + (np.arange(shape[a]) + 0.5) * spacing for a in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        return centres, fields["velocity"].reshape(-1, 3)
    import meshio

    mesh = meshio.read(path)
    cells = mesh.cells_dict.get("hexahedron")
    velocity = mesh.cell_data_dict.get("velocity", {}).get("hexahedron")
    if cells is None or velocity is None or len(cells) == 0:
        raise NoData(f"{path.name}: no hexahedral cells with a velocity")
    centres = np.asarray(mesh.points, dtype=float)[np.asarray(cells)].mean(axis=1)
    return centres, np.asarray(velocity, dtype=float).reshape(-1, 3)


def slag_plane(path: Path, y0: float) -> dict[str, np.ndarray]:
    """The slag velocity on the cell layer of a slag snapshot (``fluid_NNNNN.vti``, or an older run's
    ``fluid_NNNNN.vtu``) nearest to y = ``y0`` [m] (the mean of the two layers equally near): slag_x, slag_z [m] of
    the cell centres, slag_velocity (n, 3) [m/s] as float32, sorted by z then x, and the plane's slag_y [m]. Empty
    dict if the file has no cells with a velocity; ValueError naming an unreadable file."""
    import meshio

    path = Path(path)
    if path.suffix == ".vti":  # image data: the cell centres from the grid, the same layer rule
        try:
            centres, velocity = slag_file(path)
        except NoData:
            return {}
        return _plane_of(centres, velocity, y0)
    try:
        mesh = meshio.read(path)
    except Exception as exc:
        raise ValueError(f"{path}: cannot be read as a slag snapshot ({type(exc).__name__}: {exc})") from None
    cells = mesh.cells_dict.get("hexahedron")
    velocity = mesh.cell_data_dict.get("velocity", {}).get("hexahedron")
    if cells is None or velocity is None or len(cells) == 0:
        return {}
    points = np.asarray(mesh.points, dtype=float)
    cells = np.asarray(cells)
    velocity = np.asarray(velocity, dtype=float).reshape(-1, 3)
    y = sum(points[cells[:, c], 1] for c in range(8)) / 8.0  # centres' y only, corner by corner (a large grid)
    layer = _layer(y, y0)
    corners = points[cells[layer]]  # (layer cells, 8, 3)
    return _plane(corners[..., 0].mean(axis=1), corners[..., 2].mean(axis=1), velocity[layer], y[layer])


def _layer(y: np.ndarray, y0: float) -> np.ndarray:
    """Indices of the cells on the layer of centres ``y`` [m] nearest to ``y0`` (both layers where two are equally
    near)."""
    levels = np.unique(y)
    gaps = np.diff(levels)
    spacing_y = float(gaps[gaps > 0].min()) if np.any(gaps > 0) else 1.0
    distance = np.abs(y - y0)
    return np.flatnonzero(distance <= distance.min() + 1e-6 * spacing_y)


def _plane_of(centres: np.ndarray, velocity: np.ndarray, y0: float) -> dict[str, np.ndarray]:
    """The plane of :func:`_read_slag_plane` from cell centres (n, 3) [m] and velocities (n, 3) [m/s]."""
    layer = _layer(centres[:, 1], y0)
    return _plane(centres[layer, 0], centres[layer, 2], velocity[layer], centres[layer, 1])


def _plane(x, z, velocity, y) -> dict[str, np.ndarray]:
    """Average the layer cells sharing x and z (the two layers equally near), sorted by z then x."""
    extent = max(float(np.ptp(x)) if x.size else 0.0, float(np.ptp(z)) if z.size else 0.0, 1e-300)
    tolerance = 1e-6 * extent
    keys = np.stack([np.rint(z / tolerance), np.rint(x / tolerance)], axis=1)  # the two layers share x and z
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    counts = np.bincount(inverse, minlength=len(unique)).astype(float)

    def mean(values):
        return np.bincount(inverse, weights=values, minlength=len(unique)) / counts

    plane_v = np.stack([mean(velocity[:, a]) for a in range(3)], axis=1)
    return {"slag_x": mean(x).astype(np.float32), "slag_z": mean(z).astype(np.float32),
            "slag_velocity": plane_v.astype(np.float32), "slag_y": np.float64(y.mean())}


def read_json(path: Path, error=OutputError):
    """The JSON document in ``path``, None if there is no such file; an unreadable one raises ``error`` (an
    exception class) naming the file."""
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise error(f"{path}: cannot be read as JSON ({exc})") from None


def read_zone_tables(folder) -> dict[str, pd.DataFrame]:
    """The zone diagnostics present in ``folder`` (zone_profile.csv, zones.csv, lift_by_size.csv of
    :data:`settler.output.SNAPSHOT_TABLES`), keyed by the name without ``.csv``."""
    folder = Path(folder)
    return {name[:-4]: read_table(folder / name) for name in SNAPSHOT_TABLES
            if name != "channel_profile.csv" and (folder / name).is_file()}


def portable_path(source: str) -> str:
    """An absolute path named from its last ``data/`` folder (``data/cases/simple.toml``), else by its file name;
    a relative path as it is."""
    if not Path(source).is_absolute():
        return source
    parts = Path(source).parts
    if "data" in parts:
        return "/".join(parts[len(parts) - 1 - parts[::-1].index("data"):])
    return Path(source).name


def window_header(window, snapshots, fields: dict[str, str]) -> str:
    """The header line of a measure stored beside a run (collisions by height, the floor's lift, the floor layer):
    ``# window: T0 T1 s; NAME: TEXT; ...; snapshots: T T ...`` with ``fields`` (name -> its text, units included)
    in their order; read back by :func:`read_window_header`."""
    middle = "".join(f"{name}: {text}; " for name, text in fields.items())
    return (f"# window: {float(window[0])!r} {float(window[1])!r} s; {middle}snapshots: "
            + " ".join(repr(float(t)) for t in snapshots) + "\n")


def read_window_header(path) -> dict:
    """The fields of a :func:`window_header` line in the first three lines of ``path``: "window" as (T0, T1) [s],
    "snapshots" as a list of times [s], every other field as its text."""
    lines = Path(path).read_text().splitlines()
    head = next(line for line in lines[:3] if line.startswith("# window:"))
    fields = dict(part.strip().split(": ", 1) for part in head[2:].split(";"))
    fields["window"] = tuple(float(x) for x in fields["window"].split()[:2])
    fields["snapshots"] = [float(x) for x in fields["snapshots"].split()]
    return fields
