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
    "max_cell_reynolds": ("-", "largest cell Reynolds number of the slag flow (full engine; NaN in reduced)"),
    "max_cfl": ("-", "largest advective CFL number of the slag flow (full engine; NaN in reduced)"),
    "max_overlap_ratio": ("-", "largest contact overlap / smaller diameter (full engine; NaN in reduced)"),
    "wall_time": ("s", "wall-clock time the run has taken since t = 0, resumed runs included (full engine; NaN in "
                       "reduced): its slope over time is the wall time per simulated second"),
}


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


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
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
    """Write a time series as CSV atomically, with a header comment line giving every column's unit."""
    units = ", ".join(f"{c} [{TIME_SERIES[c][0]}]" for c in frame.columns)
    atomic_write_text(path, f"# units: {units}\n" + frame.to_csv(index=False))


def read_time_series(path: str | os.PathLike) -> pd.DataFrame:
    """Read a time series written by :func:`write_time_series`."""
    return pd.read_csv(path, comment="#")


def write_run_metadata(out_dir: str | os.PathLike, case, engine: str, **extra) -> None:
    """Write ``case.toml`` (the resolved case) and ``metadata.json`` (engine, units, extra facts) into out_dir."""
    from . import __version__

    out_dir = Path(out_dir)
    atomic_write_text(out_dir / "case.toml", case.to_toml())
    meta = {"engine": engine, "settler_version": __version__, "case_source": case.source,
            "time_series_units": {c: u for c, (u, _) in TIME_SERIES.items()},
            "time_series_columns": {c: d for c, (_, d) in TIME_SERIES.items()}, **extra}
    atomic_write_text(out_dir / "metadata.json", json.dumps(meta, indent=1, default=float))
