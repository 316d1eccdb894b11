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


def slag_file(path) -> tuple[np.ndarray, np.ndarray]:
    """(cell centres (n, 3) [m], cell velocity (n, 3) [m/s]) of one slag snapshot file (``fluid_NNNNN.vtu``); a
    cell's centre is the mean of its 8 corner points. Raises NoData if it holds no hexahedra with a velocity."""
    import meshio

    mesh = meshio.read(path)
    cells = mesh.cells_dict.get("hexahedron")
    velocity = mesh.cell_data_dict.get("velocity", {}).get("hexahedron")
    if cells is None or velocity is None or len(cells) == 0:
        raise NoData(f"{path.name}: no hexahedral cells with a velocity")
    centres = np.asarray(mesh.points, dtype=float)[np.asarray(cells)].mean(axis=1)
    return centres, np.asarray(velocity, dtype=float).reshape(-1, 3)


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
