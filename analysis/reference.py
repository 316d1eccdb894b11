"""Reference runs stored small in the repository: ``data/reference/<case>/``.

A full-engine run folder (``settler full CASE --out RUN``) holds hundreds of MB: numbered droplet and slag
snapshots (``droplets_NNNNN.vtu``, ``fluid_NNNNN.vti``) and a checkpoint. :func:`store_reference` keeps what
comparisons and the seed paper's figures need, in a folder of a few MB (SI units throughout):

==========================  ==========================================================================================
``timeseries.csv``          copied with every value at float32's precision (:func:`compact_table`; columns of
                            :data:`settler.output.TIME_SERIES`, units line first)
``case.toml``               the resolved case, copied with its first line's "loaded from" naming the case file from
                            ``data/`` (``data/cases/simple.toml``) instead of this machine's folder
``merges_by_size.csv``      copied the same way (a units line added where an older run lacks one), if the run has it
``channel_profile.csv``     copied the same way, if the run has it
``zone_profile.csv``,       the zone diagnostics (:data:`settler.output.SNAPSHOT_TABLES`), copied the same way, if the
``zones.csv``,              run has them (``merges_by_height.csv`` since 2026-12-05)
``lift_by_size.csv``,
``merges_by_height.csv``
``snapshots.npz``           a few droplet snapshots, chosen evenly over the run's snapshot times (always the last),
                            and the slag velocity on the central x-z plane of each (``np.savez_compressed``, float32;
                            keys below)
``reference.json``          where it came from (run folder, command, commit, metadata.json, summary.json), the
                            simulated end time [s] and wall time [s] reached, droplets at the end, file sizes [bytes]
==========================  ==========================================================================================

``snapshots.npz`` keys, ``k`` = 0 .. n-1 in time order: ``times`` (n,) [s] float64; per snapshot
``t{k}_position`` (m, 3) [m], ``t{k}_velocity`` (m, 3) [m/s], ``t{k}_diameter`` [m], ``t{k}_density`` [kg/m^3],
``t{k}_age`` [s], ``t{k}_merged`` [-] (1 if formed by coalescence, 0 if not, NaN where the run did not record it),
all float32 (about 7 significant digits: 0.1 um on a 1 m box); and, where the snapshot has a slag file,
``t{k}_slag_x``, ``t{k}_slag_z`` [m] (cell centres) and ``t{k}_slag_velocity`` (c, 3) [m/s] on the cell layer
nearest to y = the inlet centre's y (the mean of the two layers where it lies half-way between them), float32,
sorted by z, then x (so they reshape to (nz, nx)), and ``t{k}_slag_y`` [m] (float64, the plane's y).

The tables keep every whole number exactly and every other value to 7 significant digits, float32's precision
(the engine writes 17: the stored set's tables shrink from 11.4 to 6.5 MB); their header and units lines are
unchanged. The checkpoint and the full snapshots are never copied. A folder over :data:`SIZE_LIMIT` bytes keeps
fewer snapshots (down to one); if one is still too many, its droplet arrays keep :data:`KEEP_BITS` of float32's 23
mantissa bits, then fewer down to :data:`MIN_KEEP_BITS` while the folder is over the limit (bit rounding, as netCDF's
``quantize_mode="BitRound"``; Kloewer et al., Nat. Comput. Sci. 1 (2021) 713): a relative error of at most
2^-(bits+1), 8 um at 15 bits on cubic's 0.55 m height, and the random low bits no longer defeat the compression
(cubic's snapshot of 230 000 droplets: 5.8 MB at float32, 4.5 MB at 15 bits). ``reference.json``'s ``notes`` say
which was done.

:func:`load_reference` reads a stored folder back (:class:`Reference`: time series, case, info, droplets and slag
per snapshot) without any engine. Command line::

    python -m analysis.reference RUN CASE_NAME [--dest data/reference] [--snapshots 4]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from settler.output import read_channel_profile, read_time_series, to_json

from .files import portable_path, read_json, read_zone_tables


#: Largest size [bytes] of one stored reference folder; above it fewer snapshots are kept (three cases must stay
#: under 40 MB together, and no tracked file should exceed 5 MB: one snapshot of 146 000 droplets is 3.7 MB).
SIZE_LIMIT = 5_000_000
#: Files copied unchanged from the run folder (the first two are required).
REQUIRED_FILES = ("timeseries.csv", "case.toml")
OPTIONAL_FILES = ("merges_by_size.csv", "channel_profile.csv", "zone_profile.csv", "zones.csv", "lift_by_size.csv",
                  "merges_by_height.csv")
SNAPSHOT_FILE = "snapshots.npz"
#: Mantissa bits a snapshot's droplet arrays keep where one full snapshot is over :data:`SIZE_LIMIT` (float32: 23),
#: then one fewer at a time down to MIN_KEEP_BITS while the folder is still over it.
KEEP_BITS = 15
MIN_KEEP_BITS = 12
INFO_FILE = "reference.json"
#: Per-droplet arrays of ``snapshots.npz`` (name -> (unit, point_data field of the droplet .vtu)).
DROPLET_ARRAYS = {"position": ("m", None), "velocity": ("m/s", "velocity"), "diameter": ("m", "diameter"),
                  "density": ("kg/m^3", "density"), "age": ("s", "age"), "merged": ("-", "merged")}
FLOAT32_NOTE = ("snapshots.npz holds float32 (about 7 significant digits): droplet positions [m], velocities "
                "[m/s], diameters [m], densities [kg/m^3], ages [s], merged flags and the slag plane; times [s] are "
                "float64; the CSV files are copied unchanged")


class StoreError(ValueError):
    """A run folder or destination that cannot be stored as a reference; the message names the file and why."""


# ------------------------------------------------------------------------------------------------------ choosing
def choose_snapshots(times, count: int) -> list[int]:
    """Indices of ``count`` of the snapshot ``times`` [s] (ascending), spread evenly in time and ending with the last.

    Target times are t_ref + (t_last - t_ref) k / count for k = 1 .. count, with t_ref = min(0, first time): a run
    with snapshots every second up to 6 s gives 2, 4, 6 s for three. Each target takes the nearest snapshot (the
    later of two equally near); a snapshot is never taken twice (a neighbour is taken instead). All of them if
    ``count`` is at least their number; none if there are none.
    """
    times = np.asarray(times, dtype=float)
    n = len(times)
    count = int(count)
    if count < 1:
        raise ValueError(f"snapshots = {count}: give at least 1")
    if n == 0:
        return []
    if count >= n:
        return list(range(n))
    t_ref = min(0.0, float(times[0]))
    targets = t_ref + (float(times[-1]) - t_ref) * np.arange(1, count + 1) / count
    picked = []
    for j, target in enumerate(targets):
        distance = np.abs(times - target)
        best = int(np.flatnonzero(distance == distance.min())[-1])  # the later of equally near ones
        best = min(max(best, j), n - count + j)  # leave room for the others, before and after
        if picked and best <= picked[-1]:
            best = picked[-1] + 1
        picked.append(best)
    return picked


# ------------------------------------------------------------------------------------------------------- reading
def _snapshot_list(run: Path):
    """(time [s], droplets path or None, fluid path or None) of the run's snapshots.pvd, by time."""
    from .files import NoData, snapshot_files

    try:
        return snapshot_files(run)
    except NoData as exc:
        raise StoreError(f"{run / 'snapshots.pvd'}: {exc}") from None


def _read_droplets(path: Path) -> dict[str, np.ndarray]:
    """The droplet arrays of one ``droplets_NNNNN.vtu`` as float32 (keys of :data:`DROPLET_ARRAYS`)."""
    import meshio

    try:
        mesh = meshio.read(path)
    except Exception as exc:  # meshio raises many kinds for a damaged file
        raise StoreError(f"{path}: cannot be read as a droplet snapshot ({type(exc).__name__}: {exc})") from None
    points = np.asarray(mesh.points, dtype=float).reshape(-1, 3)
    n = len(points)
    out = {}
    for name, (_, field) in DROPLET_ARRAYS.items():
        width = 3 if name in ("position", "velocity") else None
        shape = (n, width) if width else (n,)
        if field is None:
            values = points
        elif field in mesh.point_data:
            values = np.asarray(mesh.point_data[field], dtype=float).reshape(shape)
        else:
            values = np.full(shape, np.nan)
        out[name] = np.ascontiguousarray(values, dtype=np.float32)
    return out


def _read_slag_plane(path: Path, y0: float) -> dict[str, np.ndarray]:
    """:func:`analysis.files.slag_plane` of one slag snapshot, an unreadable file a StoreError naming it."""
    from .files import slag_plane

    try:
        return slag_plane(path, y0)
    except ValueError as exc:
        raise StoreError(str(exc)) from None


# ------------------------------------------------------------------------------------------------------- storing
def _git_commit() -> str | None:
    """``git rev-parse HEAD`` of the repository holding this file, or None where that does not work."""
    try:
        done = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(__file__).resolve().parent,
                              capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError):
        return None
    text = done.stdout.strip()
    return text if done.returncode == 0 and text else None


def _folder_size(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.iterdir() if p.is_file())


def _check_name(case_name) -> str:
    name = str(case_name)
    if not name or name in (".", "..") or name.startswith(".") or "/" in name or os.sep in name:
        raise StoreError(f"case name {name!r}: give a plain folder name (no slashes, not starting with '.')")
    return name


def bit_round(values: np.ndarray, keep_bits: int) -> np.ndarray:
    """float32 ``values`` rounded to ``keep_bits`` mantissa bits (round to nearest, ties away from zero; NaN and
    infinities kept): relative error at most 2^-(keep_bits + 1), and the dropped bits zero, so they compress."""
    values = np.ascontiguousarray(values, dtype=np.float32)
    drop = 23 - int(keep_bits)
    if drop <= 0:
        return values.copy()
    bits = values.view(np.uint32)
    half = np.uint32(1 << (drop - 1))
    mask = np.uint32((0xFFFFFFFF >> drop) << drop)
    rounded = ((bits + half) & mask).view(np.float32)
    return np.where(np.isfinite(values), rounded, values)


def _write_snapshots(path: Path, times, chosen, droplets, slag, keep_bits=None) -> None:
    arrays = {"times": np.asarray([times[i] for i in chosen], dtype=np.float64)}
    for k, i in enumerate(chosen):
        for name, values in droplets[i].items():
            arrays[f"t{k}_{name}"] = values if keep_bits is None else bit_round(values, keep_bits)
        for name, values in slag.get(i, {}).items():
            arrays[f"t{k}_{name}"] = values
    np.savez_compressed(path, **arrays)


def store_reference(run, case_name, dest_root="data/reference", snapshots=4, command=None, commit=None) -> Path:
    """Store the run folder ``run`` small as the reference ``dest_root/case_name/`` and return that folder.

    Copies ``timeseries.csv`` and ``case.toml`` (required) and the optional tables (if present), the tables at
    float32's precision (:func:`compact_table`); writes ``snapshots.npz`` with ``snapshots`` droplet snapshots (0:
    none, no file) chosen by :func:`choose_snapshots` (float32; the slag velocity on the central x-z plane with each)
    and ``reference.json`` (see the module docstring). ``command`` defaults to metadata.json's "command", ``commit``
    to metadata.json's "commit", else ``git rev-parse HEAD`` of this repository (None if that fails). The folder is
    written as a temporary sibling and renamed over the previous one, whose content is replaced. Over
    :data:`SIZE_LIMIT` bytes, fewer snapshots are kept (down to 1), and then the one bit-rounded (:data:`KEEP_BITS`
    down to :data:`MIN_KEEP_BITS`), noted in ``reference.json``'s ``notes``.

    Raises :class:`StoreError` (a ValueError) naming the file: no run folder, no timeseries.csv or case.toml, an
    unreadable snapshot or JSON file, a bad case name or a destination that is the run folder itself.
    """
    name = _check_name(case_name)
    run = Path(run)
    if not run.is_dir():
        raise StoreError(f"{run}: no such run folder" if not run.exists() else f"{run}: is a file, not a run folder")
    for required in REQUIRED_FILES:
        if not (run / required).is_file():
            raise StoreError(f"{run / required}: missing; a reference needs the run's {' and '.join(REQUIRED_FILES)} "
                             "(give the --out folder of a 'settler full' run)")
    try:
        snapshots = int(snapshots)
    except (TypeError, ValueError):
        raise StoreError(f"snapshots = {snapshots!r}: give a whole number >= 0") from None
    if snapshots < 0:
        raise StoreError(f"snapshots = {snapshots}: give 0 (none kept) or more")
    dest_root = Path(dest_root)
    dest = dest_root / name
    run_resolved, dest_resolved = run.resolve(), dest.resolve()
    if run_resolved == dest_resolved or dest_resolved in run_resolved.parents:
        raise StoreError(f"{dest}: is the run folder {run} or holds it; store the reference somewhere else")

    try:
        series = read_time_series(run / "timeseries.csv")
    except (OSError, ValueError) as exc:
        raise StoreError(f"{run / 'timeseries.csv'}: cannot be read ({type(exc).__name__}: {exc})") from None
    if "time" not in series:
        raise StoreError(f"{run / 'timeseries.csv'}: has no time column")
    last = series.iloc[-1] if len(series) else None
    metadata = read_json(run / "metadata.json", StoreError)
    summary = read_json(run / "summary.json", StoreError)
    if command is None and isinstance(metadata, dict):
        command = metadata.get("command")
    if commit is None and isinstance(metadata, dict):
        commit = metadata.get("commit")  # the code that made the run (settler.output.write_run_metadata)
    if commit is None:
        commit = _git_commit()

    listed = _snapshot_list(run)
    usable = [(t, d, f) for t, d, f in listed if d is not None]
    notes = []
    if not listed:
        notes.append("the run has no snapshots (no snapshots.pvd, or it lists none): no snapshots.npz")
    elif len(usable) < len(listed):
        notes.append(f"{len(listed) - len(usable)} of the run's {len(listed)} snapshots have no droplet file on "
                     "disk and were not considered")
    times = [t for t, _, _ in usable]
    if usable and snapshots > len(usable):
        notes.append(f"{snapshots} snapshots asked for, the run has {len(usable)}: all stored")
    if usable and snapshots == 0:
        notes.append(f"0 snapshots asked for: none of the run's {len(usable)} stored (no snapshots.npz)")
    y0 = None
    if usable:
        from settler.cases import CaseError, load_case

        try:
            y0 = float(load_case(run / "case.toml").inlet_center[1])
        except (CaseError, OSError, ValueError) as exc:
            notes.append(f"case.toml cannot be read ({exc}); no slag planes stored")

    dest_root.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{name}.new-", dir=dest_root))
    try:
        mask = os.umask(0o022)
        os.umask(mask)
        os.chmod(tmp, 0o777 & ~mask)
        for file in REQUIRED_FILES + OPTIONAL_FILES:
            if file == "case.toml":
                _copy_case(run / file, tmp / file)
            elif (run / file).is_file():
                _copy_table(run / file, tmp / file)

        droplets: dict[int, dict] = {}
        slag: dict[int, dict] = {}

        def load(indices):
            for i in indices:
                if i in droplets:
                    continue
                _, d_path, f_path = usable[i]
                droplets[i] = _read_droplets(d_path)
                if f_path is not None and y0 is not None:
                    plane = _read_slag_plane(f_path, y0)
                    if plane:
                        slag[i] = plane

        requested = snapshots
        count = min(requested, len(usable))
        chosen = choose_snapshots(times, count) if usable and count > 0 else []
        keep_bits = None
        while True:
            info_notes = list(notes)
            if chosen:
                load(chosen)
                _write_snapshots(tmp / SNAPSHOT_FILE, times, chosen, droplets, slag, keep_bits)
                missing_slag = [times[i] for i in chosen if i not in slag]
                if missing_slag:
                    info_notes.append("no slag plane for the snapshots at t = "
                                      + ", ".join(f"{t:g}" for t in missing_slag) + " s (no fluid file or no velocity)")
            info = _info(run, name, command, commit, metadata, summary, last, usable, chosen, droplets, slag, tmp,
                         requested, info_notes)
            text = to_json(info)
            total = _folder_size(tmp) + len(text.encode("utf-8"))
            if total > SIZE_LIMIT and count == 1 and chosen and (keep_bits or 24) > MIN_KEEP_BITS:
                keep_bits = KEEP_BITS if keep_bits is None else keep_bits - 1
                notes[:] = [n for n in notes if "mantissa bits" not in n]
                notes.append(f"one snapshot made {total / 1e6:.3g} MB, over the {SIZE_LIMIT / 1e6:g} MB limit: its "
                             f"droplet arrays keep {keep_bits} of float32's 23 mantissa bits (relative error at most "
                             f"2^-{keep_bits + 1})")
                continue
            if total <= SIZE_LIMIT or count <= 1 or not chosen:
                break
            per_snapshot = (tmp / SNAPSHOT_FILE).stat().st_size / count
            room = SIZE_LIMIT - (total - per_snapshot * count)
            fewer = min(count - 1, max(1, int(room // max(per_snapshot, 1.0))))
            notes.append(f"{count} snapshots made {total / 1e6:.3g} MB, over the {SIZE_LIMIT / 1e6:g} MB limit: "
                         f"{fewer} kept instead")
            count = fewer
            chosen = choose_snapshots(times, count)
        if total > SIZE_LIMIT:
            info["notes"].append(f"the folder is {total / 1e6:.3g} MB, over the {SIZE_LIMIT / 1e6:g} MB limit even "
                                 f"with {count if chosen else 'no'} snapshot(s)")
            text = to_json(info)
        (tmp / INFO_FILE).write_text(text + "\n", encoding="utf-8")
        _replace(tmp, dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return dest


def _info(run, name, command, commit, metadata, summary, last, usable, chosen, droplets, slag, tmp, requested,
          notes) -> dict:
    """The content of reference.json."""
    end_count = None
    if last is not None and "droplet_count" in last and math.isfinite(float(last["droplet_count"])):
        end_count = int(round(float(last["droplet_count"])))
    elif chosen:
        end_count = int(len(droplets[chosen[-1]]["diameter"]))
    files = {p.name: p.stat().st_size for p in sorted(tmp.iterdir()) if p.is_file() and p.name != INFO_FILE}
    meta = metadata if isinstance(metadata, dict) else {}
    try:
        from settler.cases import load_case

        seed = int(load_case(run / "case.toml").feed.seed)
    except Exception:  # noqa: BLE001 -- an unreadable case is noted elsewhere; the seed is then unknown
        seed = None
    return {
        "case_name": name,
        "command": command,
        "commit": commit,
        "dirty": meta.get("dirty"),
        "engine_trees": meta.get("engine_trees"),
        "seed": seed,
        "end_time": None if last is None else float(last["time"]),
        "wall_time": None if last is None or "wall_time" not in last else float(last["wall_time"]),
        "droplets_at_end": end_count,
        "snapshots": {"requested": requested, "stored": len(chosen), "in_run": len(usable),
                      "times": [usable[i][0] for i in chosen],
                      "droplets": [int(len(droplets[i]["diameter"])) for i in chosen],
                      "slag_plane": [i in slag for i in chosen],
                      "units": {k: u for k, (u, _) in DROPLET_ARRAYS.items()}},
        "files": files,
        "total_bytes": int(sum(files.values())),
        "precision": FLOAT32_NOTE,
        "notes": list(notes),
        "metadata": _portable(metadata, command),
        "summary": summary,
    }


def _portable(metadata, command):
    """metadata.json as stored: its command replaced by ``command`` and a case source inside a checkout's data/
    folder named from there (``data/cases/simple.toml``), so that provenance names commands, not this machine's
    folders."""
    if not isinstance(metadata, dict):
        return metadata
    out = dict(metadata)
    if command is not None and "command" in out:
        out["command"] = command
    if isinstance(out.get("case_source"), str):
        out["case_source"] = portable_path(out["case_source"])
    return out


#: The first line of a resolved case.toml (settler.cases.Case.to_toml) that names where the case was loaded from.
LOADED_FROM = "# resolved case; loaded from "


def compact_table(text: str) -> str:
    """A run's CSV table (``#`` comment lines, a header line, rows) with its numbers at float32's precision: whole
    numbers as they are (counts stay exact at any size), every other finite number to 7 significant digits
    (``%.7g``), empty fields empty; the comment and header lines and every non-numeric field unchanged."""
    import io

    lines = text.splitlines(keepends=True)
    comments = "".join(line for line in lines if line.startswith("#"))
    body = "".join(line for line in lines if not line.startswith("#"))
    if not body.strip():
        return text
    frame = pd.read_csv(io.StringIO(body), dtype=str, keep_default_na=False)

    def short(field: str) -> str:
        try:
            value = float(field)
        except ValueError:
            return field
        if not math.isfinite(value) or value == int(value):
            return field  # whole numbers and nan/inf as the engine wrote them
        return f"{value:.7g}"

    for column in frame.columns:
        frame[column] = [short(v) for v in frame[column]]
    return comments + frame.to_csv(index=False, lineterminator="\n")


def _copy_table(source: Path, dest: Path) -> None:
    """Copy a CSV with :func:`compact_table`, adding the units line that runs made before the engine wrote one in
    ``merges_by_size.csv`` lack (:data:`settler.output.MERGES_BY_SIZE`)."""
    from settler.output import MERGES_BY_SIZE, units_line

    text = source.read_text(encoding="utf-8")
    if source.name == "merges_by_size.csv" and text.split("\n", 1)[0].strip() == ",".join(MERGES_BY_SIZE):
        text = units_line(MERGES_BY_SIZE) + text  # the engine's header without its units line
    dest.write_text(compact_table(text), encoding="utf-8")


def _copy_case(source: Path, dest: Path) -> None:
    """Copy a run's case.toml with its 'loaded from' comment naming the case file portably (:func:`_portable_path`):
    the case itself is unchanged."""
    lines = source.read_text(encoding="utf-8").splitlines(keepends=True)
    if lines and lines[0].startswith(LOADED_FROM):
        lines[0] = LOADED_FROM + portable_path(lines[0][len(LOADED_FROM):].strip()) + "\n"
    dest.write_text("".join(lines), encoding="utf-8")


def _replace(tmp: Path, dest: Path) -> None:
    """Put the finished folder ``tmp`` in place of ``dest`` (renames; the old content is deleted afterwards)."""
    if not dest.exists():
        os.rename(tmp, dest)
        return
    if not dest.is_dir():
        raise StoreError(f"{dest}: is a file, not a reference folder")
    old = Path(tempfile.mkdtemp(prefix=f".{dest.name}.old-", dir=dest.parent))
    os.rmdir(old)
    os.rename(dest, old)
    try:
        os.rename(tmp, dest)
    except BaseException:
        os.rename(old, dest)
        raise
    shutil.rmtree(old, ignore_errors=True)


# ------------------------------------------------------------------------------------------------------- loading
@dataclasses.dataclass
class Reference:
    """A stored reference run (:func:`load_reference`). SI units throughout.

    ``timeseries``: DataFrame of :data:`settler.output.TIME_SERIES`; ``case``: the resolved
    :class:`settler.cases.Case`; ``info``: reference.json; ``merges_by_size`` and ``channel_profile``: DataFrames or
    None; ``zones``: the zone diagnostics present (:func:`analysis.runs.read_zone_tables`); ``snapshot_times``: (n,)
    [s]; ``folder``: where it lies.
    """

    folder: Path
    timeseries: pd.DataFrame
    case: object
    info: dict
    merges_by_size: pd.DataFrame | None
    channel_profile: pd.DataFrame | None
    snapshot_times: np.ndarray
    zones: dict = dataclasses.field(default_factory=dict)
    _arrays: dict = dataclasses.field(default_factory=dict, repr=False)

    def index(self, k_or_time) -> int:
        """The snapshot index for ``k_or_time``: an int is an index (negative counts from the end), a float a time
        [s] (the nearest snapshot; the later of two equally near). Raises LookupError if there are no snapshots,
        IndexError for an index out of range, ValueError for a time that is not finite."""
        n = len(self.snapshot_times)
        if n == 0:
            raise LookupError(f"{self.folder}: the reference holds no snapshots")
        if isinstance(k_or_time, (bool, np.bool_)):
            raise TypeError("give a snapshot index (int) or a time [s] (float), not a bool")
        if isinstance(k_or_time, (int, np.integer)):
            k = int(k_or_time)
            if not -n <= k < n:
                raise IndexError(f"snapshot {k}: the reference holds {n} (0 .. {n - 1})")
            return k % n
        t = float(k_or_time)
        if not math.isfinite(t):
            raise ValueError(f"time = {k_or_time!r}: give a finite time [s]")
        distance = np.abs(self.snapshot_times - t)
        return int(np.flatnonzero(distance == distance.min())[-1])

    def droplets(self, k_or_time=-1) -> pd.DataFrame:
        """The droplets of a snapshot (see :meth:`index`; default the last): columns x, y, z [m], diameter [m],
        u, v, w [m/s], density [kg/m^3], age [s], merged [-], and settling_velocity [m/s] (= -w, downward positive,
        as :func:`analysis.figures.read_droplets` gives), float64 from the stored float32."""
        k = self.index(k_or_time)
        a = self._arrays
        position = np.asarray(a[f"t{k}_position"], dtype=float).reshape(-1, 3)
        velocity = np.asarray(a[f"t{k}_velocity"], dtype=float).reshape(-1, 3)
        frame = pd.DataFrame({"x": position[:, 0], "y": position[:, 1], "z": position[:, 2],
                              "diameter": np.asarray(a[f"t{k}_diameter"], dtype=float),
                              "u": velocity[:, 0], "v": velocity[:, 1], "w": velocity[:, 2],
                              "density": np.asarray(a[f"t{k}_density"], dtype=float),
                              "age": np.asarray(a[f"t{k}_age"], dtype=float),
                              "merged": np.asarray(a[f"t{k}_merged"], dtype=float)})
        frame["settling_velocity"] = -frame["w"]
        return frame

    def slag(self, k_or_time=-1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The slag on the central x-z plane of a snapshot (see :meth:`index`; default the last): (x [m], z [m] of
        the cell centres, velocity (n, 3) [m/s]), sorted by z then x. Raises LookupError if that snapshot has none."""
        k = self.index(k_or_time)
        if f"t{k}_slag_velocity" not in self._arrays:
            raise LookupError(f"{self.folder}: no slag plane stored for the snapshot at "
                              f"t = {self.snapshot_times[k]:g} s")
        a = self._arrays
        return (np.asarray(a[f"t{k}_slag_x"], dtype=float), np.asarray(a[f"t{k}_slag_z"], dtype=float),
                np.asarray(a[f"t{k}_slag_velocity"], dtype=float).reshape(-1, 3))

    def slag_plane_y(self, k_or_time=-1) -> float:
        """y [m] of the slag plane of a snapshot (the inlet centre's y, or the mean of the two layers' y)."""
        k = self.index(k_or_time)
        key = f"t{k}_slag_y"
        return float(self._arrays[key]) if key in self._arrays else float(self.case.inlet_center[1])


def load_reference(case_name, root="data/reference") -> Reference:
    """The reference stored as ``root/case_name/`` by :func:`store_reference`. Raises FileNotFoundError naming the
    missing folder or file (the available ones listed)."""
    from settler.cases import load_case

    folder = Path(root) / str(case_name)
    if not folder.is_dir():
        present = available_references(root)
        raise FileNotFoundError(f"{folder}: no such reference; present under {root}: "
                                + (", ".join(present) if present else "none"))
    for name in REQUIRED_FILES + (INFO_FILE,):
        if not (folder / name).is_file():
            raise FileNotFoundError(f"{folder / name}: missing; not a stored reference (store one with "
                                    "'python -m analysis.reference RUN CASE_NAME')")
    info = json.loads((folder / INFO_FILE).read_text(encoding="utf-8"))
    arrays: dict = {}
    times = np.zeros(0)
    if (folder / SNAPSHOT_FILE).is_file():
        with np.load(folder / SNAPSHOT_FILE) as data:
            arrays = {k: data[k] for k in data.files}
        times = np.asarray(arrays.get("times", np.zeros(0)), dtype=float)
    optional = {name: read_channel_profile(folder / name) if (folder / name).is_file() else None
                for name in OPTIONAL_FILES}  # the same plain CSV reading for both
    return Reference(folder=folder, timeseries=read_time_series(folder / "timeseries.csv"),
                     case=load_case(folder / "case.toml"), info=info,
                     merges_by_size=optional["merges_by_size.csv"],
                     channel_profile=optional["channel_profile.csv"], snapshot_times=times,
                     zones=read_zone_tables(folder), _arrays=arrays)


def available_references(root="data/reference") -> list[str]:
    """Names of the references stored under ``root`` (folders holding reference.json), sorted."""
    root = Path(root)
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir()
                  if p.is_dir() and not p.name.startswith(".") and (p / INFO_FILE).is_file())


# -------------------------------------------------------------------------------------------------- command line
def main(argv=None) -> int:
    """``python -m analysis.reference RUN CASE_NAME [--dest DIR] [--snapshots N]``: store RUN as a reference.
    Exit status 0 done, 2 a refused run folder or argument."""
    parser = argparse.ArgumentParser(
        prog="python -m analysis.reference",
        description="Store a 'settler full' run folder small as a reference (time series, case, a few float32 "
                    "droplet snapshots and slag planes; never the checkpoint).")
    parser.add_argument("run", help="the run folder (the --out of 'settler full')")
    parser.add_argument("case_name", help="name of the reference folder under --dest")
    parser.add_argument("--dest", default="data/reference", help="where references lie (default: data/reference)")
    parser.add_argument("--snapshots", type=int, default=4,
                        help="droplet snapshots to keep, spread evenly in time, the last always (default: 4)")
    parser.add_argument("--command", default=None,
                        help="the command that made the run, as a user would type it (default: the one in its "
                             "metadata.json, which names this machine's folders)")
    parser.add_argument("--commit", default=None,
                        help="git commit of the code that made the run (default: the one in its metadata.json, "
                             "else this checkout's)")
    args = parser.parse_args(argv)
    try:
        folder = store_reference(args.run, args.case_name, dest_root=args.dest, snapshots=args.snapshots,
                                 command=args.command, commit=args.commit)
    except ValueError as exc:  # StoreError, and unreadable CSV files (pandas raises ValueError subclasses)
        print(f"{parser.prog}: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    info = json.loads((folder / INFO_FILE).read_text(encoding="utf-8"))
    total = sum(p.stat().st_size for p in folder.iterdir() if p.is_file())
    times = info["snapshots"]["times"]
    print(f"wrote {folder}: {len(info['files']) + 1} files, {total / 1e6:.3g} MB; "
          + (f"{len(times)} snapshots at t = " + ", ".join(f"{t:g}" for t in times) + " s" if times
             else "no snapshots"))
    for note in info["notes"]:
        print(f"note: {note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
