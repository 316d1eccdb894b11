"""Run outputs shared by both engines: the time-series schema, atomic writes and run metadata.

Both ``settler full`` and ``settler reduced`` write ``timeseries.csv`` with the columns of :data:`TIME_SERIES`
(units in the header comment and in ``metadata.json``), the resolved case as ``case.toml`` and ``metadata.json``
beside it. A column an engine cannot compute is written as NaN, never left out, so reduced and full runs line up
column for column in :mod:`analysis`.

Every file is written atomically (to a temporary file in the same folder, then renamed), so a killed run never
leaves a half-written output.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from .errors import OutputError

#: Time-series columns: name -> (unit, meaning). The one definition both engines use.
TIME_SERIES: dict[str, tuple[str, str]] = {
    "time": ("s", "simulated time"),
    "droplet_count": ("-", "number of droplets in the slag"),
    "mean_diameter": ("m", "number-mean droplet diameter in the slag"),
    "sauter_diameter": ("m", "Sauter mean diameter d32 of droplets in the slag"),
    "mean_settling_velocity": ("m/s", "number-mean downward velocity of droplets in the slag"),
    "centreline_settling_velocity": ("m/s", "mean downward velocity of droplets within one inlet radius of the "
                                            "inlet axis, at mid-height (NaN if none there)"),
    "mass_fed": ("kg", "matte mass fed since t = 0"),
    "mass_in_slag": ("kg", "matte mass in the slag now"),
    "mass_settled": ("kg", "matte mass that reached the bottom since t = 0"),
    "mass_lost": ("kg", "matte mass that left through the outlet since t = 0"),
    "mass_reacted": ("kg", "FeS mass removed from droplets by the reaction since t = 0"),
    "mass_balance_error": ("-", "(fed - in slag - settled - lost - reacted) / max(fed, tiny)"),
    "channel_radius": ("m", "radius around the inlet axis holding half the droplet volume at mid-height (within "
                            "MID_BAND of the height); the channel's width (NaN if no droplet there)"),
    "channel_velocity": ("m/s", "downward slag velocity on the inlet axis at mid-height (full engine: the grid flow "
                                "there; reduced: the channel zone's plume velocity plus the mean downflow)"),
    "coalesced_count": ("-", "droplets in the slag formed by coalescence (seed paper Fig. 15; full engine, NaN in reduced)"),
    "uncoalesced_count": ("-", "droplets in the slag that never coalesced (seed paper Fig. 15; full engine, NaN in "
                               "reduced)"),
    "merges": ("-", "coalescence events since the previous row (reduced: the droplets coalescence removed, not "
                    "an integer)"),
    "pairs_marked": ("-", "pairs marked for the delayed merge since the previous row (full engine; NaN in reduced)"),
    "merges_refused_by_size": ("-", "evaluated pairs refused since the previous row because the merged droplet would "
                                    "exceed coalescence.size_limit (full engine; NaN in reduced)"),
    "pairs_waiting": ("-", "marked pairs past their growth time plus one fluid step, not yet merged (full engine; NaN "
                           "in reduced)"),
    "longest_marked": ("s", "longest time any marked pair has been marked (full engine; NaN in reduced)"),
    "max_cell_reynolds": ("-", "largest cell Reynolds number of the slag flow (full engine; NaN in reduced)"),
    "max_cfl": ("-", "largest advective CFL number of the slag flow (full engine; NaN in reduced)"),
    "max_overlap_ratio": ("-", "largest contact overlap / smaller diameter (full engine; NaN in reduced)"),
    "wall_time": ("s", "wall-clock time the run has taken since t = 0, resumed runs included (full engine; NaN in "
                       "reduced): its slope over time is the wall time per simulated second"),
    "feed_backlog": ("kg", "matte mass due by the feed schedule but not yet placed because the inlet layer was full "
                           "(full engine; NaN in reduced): a growing backlog means the feed falls behind"),
}

#: Half-width of the mid-height band of the channel and centreline columns, as a fraction of the slag height.
MID_BAND = 0.1
#: Height bands of the channel profile (``channel_profile.csv``, written at every snapshot by both engines).
PROFILE_BANDS = 10
#: Columns of ``channel_profile.csv``: the channel measures of :data:`TIME_SERIES` against height.
CHANNEL_PROFILE: dict[str, tuple[str, str]] = {
    "time": ("s", "simulated time of the snapshot"),
    "z": ("m", "height of the band's centre above the bottom"),
    "channel_radius": ("m", "radius around the inlet axis holding half the droplet volume in the band (NaN: none)"),
    "channel_velocity": ("m/s", "downward slag velocity on the inlet axis at the band's centre"),
    "droplet_volume": ("m^3", "droplet volume in the band"),
}


def half_volume_radius(radius, volume) -> float:
    """The radius [m] around an axis that holds half the volume of droplets at distances ``radius`` [m] from it with
    volumes ``volume`` [m^3]: their volume-weighted median distance, interpolated between droplets (each counted
    at half its volume at its own distance). NaN for no droplets."""
    r = np.asarray(radius, dtype=float).ravel()
    v = np.asarray(volume, dtype=float).ravel()
    total = float(v.sum()) if v.size else 0.0
    if total <= 0.0:
        return float("nan")
    order = np.argsort(r, kind="stable")
    r, v = r[order], v[order]
    below = np.cumsum(v) - 0.5 * v
    return float(np.interp(0.5 * total, below, r))


def band_edges(height: float, bands: int = PROFILE_BANDS) -> np.ndarray:
    """Edges [m] of ``bands`` equal height bands from the bottom (0) to the top (``height``)."""
    return np.linspace(0.0, float(height), int(bands) + 1)


#: Ring width of the return radius (``return_radius`` of :data:`ZONE_PROFILE`), in grid cells.
RING_CELLS = 1.0
#: The roof layer (:data:`ZONES`) extends down from the top while the slice volume fraction is at least this share
#: of its peak in the upper half of the slag.
ROOF_SHARE = 0.5

#: Columns of ``zone_profile.csv`` (full engine, at every snapshot, the :data:`PROFILE_BANDS` bands of the channel
#: profile): what the reduced model's zones (plume core, downflow skirt, return annulus) can be fitted to, besides
#: the core's radius and axis velocity of :data:`CHANNEL_PROFILE`.
ZONE_PROFILE: dict[str, tuple[str, str]] = {
    "time": ("s", "simulated time of the snapshot"),
    "z": ("m", "height of the band's centre above the bottom"),
    "volume_fraction": ("-", "droplet volume with centres in the band over the band's volume (whole cross-section)"),
    "core_volume_fraction": ("-", "droplet volume with centres in the band within the channel radius of the inlet "
                                  "axis over that cylinder's volume (NaN: no channel radius in the band)"),
    "upward_slag_flux": ("m^3/s", "slag volume flux upward through the horizontal plane at the band's centre: the "
                                  "sum of eps w h^2 over the grid's z faces nearest to it with w > 0"),
    "downward_slag_flux": ("m^3/s", "the same over the faces with w < 0, as a positive number"),
    "return_radius": ("m", "distance from the inlet axis at which the ring-averaged slag velocity (rings RING_CELLS "
                           "cells wide) on that plane turns from downward to upward, interpolated between ring "
                           "centres (NaN: no downflow on the axis, or no turn inside the box)"),
    "rising_volume": ("m^3", "volume of the droplets in the band that move upward (velocity z > 0)"),
}
#: Columns of ``zones.csv`` (full engine, one row per snapshot): the roof layer under the inlet, measured in the
#: cylinder of the inlet radius around the inlet axis in slices one cell high.
ZONES: dict[str, tuple[str, str]] = {
    "time": ("s", "simulated time of the snapshot"),
    "roof_thickness": ("m", "depth below the slag top of the roof layer: the slices from the top down to the last "
                            "one, below the peak of the slice volume fraction in the upper half, whose fraction is at "
                            "least ROOF_SHARE of the peak (0: no droplets in the upper half)"),
    "roof_volume_fraction": ("-", "droplet volume in the roof layer over its volume (NaN for thickness 0)"),
    "roof_peak_fraction": ("-", "the peak slice volume fraction in the upper half under the inlet"),
    "rising_count": ("-", "droplets below the insertion layer moving upward (velocity z > 0)"),
    "rising_volume": ("m^3", "their volume"),
}
#: Columns of ``lift_by_size.csv`` (full engine, one row per snapshot and occupied size bin, the bins of the
#: merges-by-size table): the droplets carried back up by the return flow, by size.
LIFT_BY_SIZE: dict[str, tuple[str, str]] = {
    "time": ("s", "simulated time of the snapshot"),
    "diameter_low": ("m", "lower edge of the size bin"),
    "diameter_high": ("m", "upper edge of the size bin"),
    "count": ("-", "droplets of the bin below the insertion layer"),
    "rising_count": ("-", "those of them moving upward (velocity z > 0)"),
    "rising_velocity": ("m/s", "mean upward velocity of the rising ones (NaN: none)"),
}
#: Columns of ``merges_by_height.csv`` (full engine at every snapshot, popbal at every output; the
#: :data:`PROFILE_BANDS` bands of the channel profile): where the merges happen, counted at the larger droplet's
#: centre just before the merge, since the start of the run (differences between snapshots give the rate); "under
#: the inlet" is the inlet's disk (a slot: its rectangle) extended down through the slag, the plume's and the roof
#: layer's region (popbal: its roof layer and channel zone, :meth:`popbal.driver.Result.merges_by_height`).
MERGES_BY_HEIGHT: dict[str, tuple[str, str]] = {
    "time": ("s", "simulated time of the snapshot"),
    "z": ("m", "height of the band's centre above the bottom"),
    "merges_under_inlet": ("-", "merges in the band under the inlet since the start of the run"),
    "merges_elsewhere": ("-", "merges in the band outside it since the start of the run"),
}
#: Tables a full run writes at every snapshot: file name -> columns (the zone diagnostics and the channel profile).
SNAPSHOT_TABLES: dict[str, dict[str, tuple[str, str]]] = {
    "channel_profile.csv": CHANNEL_PROFILE, "zone_profile.csv": ZONE_PROFILE, "zones.csv": ZONES,
    "lift_by_size.csv": LIFT_BY_SIZE, "merges_by_height.csv": MERGES_BY_HEIGHT}


#: Columns of ``merges_by_size.csv`` (full engine, coalescence on): the merges of a run by the size bins of the smaller
#: and the larger droplet of each merged pair; name -> (unit, meaning).
MERGES_BY_SIZE: dict[str, tuple[str, str]] = {
    "small_low": ("m", "lower edge of the smaller droplet's size bin"),
    "small_high": ("m", "upper edge of the smaller droplet's size bin"),
    "large_low": ("m", "lower edge of the larger droplet's size bin"),
    "large_high": ("m", "upper edge of the larger droplet's size bin (inf: the last bin)"),
    "merges": ("-", "merges of such pairs since the start of the run"),
}


def units_line(columns: dict[str, tuple[str, str]]) -> str:
    """The ``# units: name [unit], ...`` line that opens every CSV written here (read with ``comment="#"``)."""
    return "# units: " + ", ".join(f"{k} [{u}]" for k, (u, _) in columns.items()) + "\n"


#: Decimals [s] that written times are rounded to: a time accumulated from steps (34.799999999996565) is written as
#: the output time it stands for (34.8), so that a reader can select it by that value (``ds.sel(time=34.8)``).
TIME_DECIMALS = 9


def round_times(frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with its ``time`` column (if any) rounded to :data:`TIME_DECIMALS` decimals of a second."""
    if "time" in frame:
        frame = frame.assign(time=frame["time"].round(TIME_DECIMALS))
    return frame


def write_table(rows: list[dict], columns: dict[str, tuple[str, str]], path) -> None:
    """Write ``rows`` (dicts with the keys of ``columns``, name -> (unit, meaning)) atomically as CSV, a units line
    first; times rounded by :func:`round_times`."""
    frame = round_times(pd.DataFrame(rows, columns=list(columns)).astype(float))
    atomic_write_text(path, units_line(columns) + frame.to_csv(index=False))


def read_table(path) -> pd.DataFrame:
    """The rows of a CSV written by :func:`write_table`."""
    return pd.read_csv(path, comment="#")


def write_channel_profile(rows: list[dict], path) -> None:
    """Write the channel profile rows (keys of :data:`CHANNEL_PROFILE`) atomically as CSV with a units line."""
    write_table(rows, CHANNEL_PROFILE, path)


def read_channel_profile(path) -> pd.DataFrame:
    """The rows of a ``channel_profile.csv``."""
    return read_table(path)


#: Files a run of either engine writes into its output folder (plus the numbered snapshots of SNAPSHOT_PATTERNS):
#: a folder holding any of them holds a run.
RUN_FILES = ("case.toml", "metadata.json", "timeseries.csv", "timeseries.png", "summary.json", "checkpoint.npz",
             "last_good.npz", "snapshots.pvd", "droplets.png", "distribution.npz", "merges_by_size.csv",
             "channel_profile.csv", "zone_profile.csv", "zones.csv", "lift_by_size.csv",
             "merges_by_height.csv")
SNAPSHOT_PATTERNS = ("droplets_*.vtu", "fluid_*.vti", "fluid_*.vtu")


def time_series_frame(rows: list[dict] | dict[str, np.ndarray]) -> pd.DataFrame:
    """A DataFrame with exactly the :data:`TIME_SERIES` columns in order; missing columns are NaN.

    Unknown columns raise ValueError, so a typo cannot silently create a new column.
    """
    frame = pd.DataFrame(rows)
    unknown = [c for c in frame.columns if c not in TIME_SERIES]
    if unknown:
        raise ValueError(f"time-series columns {unknown} are not in settler.output.TIME_SERIES; allowed: "
                         + ", ".join(TIME_SERIES))
    for column in TIME_SERIES:
        if column not in frame:
            frame[column] = np.nan
    return frame[list(TIME_SERIES)].astype(float)


def mass_balance_error(fed, in_slag, settled, lost, reacted):
    """Relative mass-accounting error (fed - in slag - settled - lost - reacted) / fed [-]."""
    fed = np.asarray(fed, dtype=float)
    return (fed - in_slag - settled - lost - reacted) / np.maximum(fed, 1e-300)


def _file_mode() -> int:
    """The mode a plain ``open`` would give a new file: 0666 less the process's umask."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename).

    The file gets the permissions of an ordinary new file under the umask (a temporary file alone would be 0600,
    readable by nobody else)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        os.fchmod(fd, _file_mode())
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode("utf-8"))


def write_time_series(frame: pd.DataFrame, path: str | os.PathLike) -> None:
    """Write a time series as CSV atomically, with a header comment line giving every column's unit (read it with
    ``pandas.read_csv(path, comment="#")``); times rounded by :func:`round_times`."""
    frame = round_times(frame)
    atomic_write_text(path, units_line({c: TIME_SERIES[c] for c in frame.columns}) + frame.to_csv(index=False))


def read_time_series(path: str | os.PathLike) -> pd.DataFrame:
    """Read a time series written by :func:`write_time_series`."""
    return pd.read_csv(path, comment="#")


def json_safe(value):
    """``value`` with every non-finite float (NaN, +-inf) replaced by None and NumPy scalars and arrays made plain,
    so that strict JSON readers accept what :func:`to_json` writes (bare NaN and Infinity are not JSON)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return json_safe(float(value))


def to_json(value, indent=1) -> str:
    """Strict JSON text of ``value`` (non-finite numbers become null, see :func:`json_safe`)."""
    return json.dumps(json_safe(value), indent=indent, allow_nan=False)


def prepare_output_folder(path, *, overwrite=False, resume=False, option="--out", create=True) -> Path:
    """Check and create a run's output folder; returns it as a Path. Raises :class:`OutputError`.

    Refused: an empty name, a path that is a file (or a device such as /dev/null) or lies under one, a folder that
    cannot be created or written, and -- unless ``resume`` (continue the run there) or ``overwrite`` (its run files,
    :data:`RUN_FILES` and the snapshots, are deleted first; other files are left) -- a folder that holds another run.
    ``create=False`` only checks (nothing is created or deleted), for a command that writes its outputs at the end.
    """
    if path is None or str(path).strip() == "":
        raise OutputError(f"{option} {str(path)!r}: give the name of a folder to write the run into")
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise OutputError(f"{option} {out}: is a file, not a folder; give a folder (it is created if missing)")
    above = next((p for p in out.parents if p.exists()), None)
    if above is not None and not above.is_dir():
        raise OutputError(f"{option} {out}: cannot create the folder: part of the path is a file ({above})")
    if not create:
        existing = run_files(out) if out.is_dir() else []
        if existing and not (overwrite or resume):
            raise OutputError(_occupied(option, out, existing))
        return out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise OutputError(f"{option} {out}: cannot create the folder: part of the path is a file") from None
    except OSError as exc:
        raise OutputError(f"{option} {out}: cannot create the folder ({exc.strerror})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {out}: the folder is not writable")
    if resume:
        return out
    existing = run_files(out)
    if existing and not overwrite:
        raise OutputError(_occupied(option, out, existing))
    for p in existing:
        p.unlink()
    return out


def _occupied(option, out, existing) -> str:
    shown = ", ".join(p.name for p in existing[:4]) + (f" and {len(existing) - 4} more" if len(existing) > 4 else "")
    return (f"{option} {out}: the folder holds another run ({shown}); choose another folder, continue that run with "
            "--resume (settler full), or give --overwrite to replace it")


def run_files(folder) -> list[Path]:
    """The run files (:data:`RUN_FILES` and numbered snapshots) present in ``folder``."""
    folder = Path(folder)
    found = [folder / name for name in RUN_FILES if (folder / name).is_file()]
    for pattern in SNAPSHOT_PATTERNS:
        found += sorted(folder.glob(pattern))
    return found


#: The packages whose git trees :func:`source_commit` records: two runs whose trees are equal ran the same engine,
#: even at different commits (commits that changed only analysis/, tests/ or the documentation).
ENGINE_PACKAGES = ("fulldem", "popbal", "settler")


def source_commit() -> dict:
    """The git commit of the toolkit's source, if it runs from a git checkout: {"commit": hash or None, "dirty":
    whether tracked files differ from it, or None, "engine_trees": {package: git tree hash at that commit} of
    :data:`ENGINE_PACKAGES` (absent outside a checkout)}."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                                timeout=10)
        if commit.returncode != 0:
            return {"commit": None, "dirty": None}
        status = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                                capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    trees = subprocess.run(["git", "-C", str(root), "rev-parse"] + [f"HEAD:{p}" for p in ENGINE_PACKAGES],
                           capture_output=True, text=True, timeout=10)
    found = trees.stdout.split() if trees.returncode == 0 else []
    return {"commit": commit.stdout.strip(), "dirty": bool(status.stdout.strip()) if status.returncode == 0 else None,
            **({"engine_trees": dict(zip(ENGINE_PACKAGES, found))} if len(found) == len(ENGINE_PACKAGES) else {})}


def write_run_metadata(out_dir: str | os.PathLike, case, engine: str, **extra) -> None:
    """Write ``case.toml`` (the resolved case) and ``metadata.json`` (engine, version, the source's git commit,
    units, extra facts) into out_dir."""
    from . import __version__

    out_dir = Path(out_dir)
    atomic_write_text(out_dir / "case.toml", case.to_toml())
    meta = {"engine": engine, "settler_version": __version__, **source_commit(), "case_source": case.source,
            "time_series_units": {c: u for c, (u, _) in TIME_SERIES.items()},
            "time_series_columns": {c: d for c, (_, d) in TIME_SERIES.items()}, **extra}
    atomic_write_text(out_dir / "metadata.json", to_json(meta))
