"""What the figures read from a run folder (a ``settler full`` output folder or a stored reference): snapshots,
time series, the channel and zone tables and the resolved case, each raising :class:`NoData` with a one-line reason
when missing; and :func:`axes`, the one rule by which every figure function draws into axes of its own or the
caller's."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from settler.output import read_time_series

from ..files import NoData, check_run, droplets_file, pick_snapshot, slag_file


def axes(ax, count: int, figsize, **subplots):
    """(Figure, list of ``count`` Axes) to draw into: new ones on a new Figure of ``figsize`` [in] (made without
    pyplot, so no backend is touched; ``subplots``: arguments of Figure.subplots) when ``ax`` is None, else the
    caller's ``ax`` (one matplotlib Axes, or a sequence of ``count`` of them, for figures of several panels) and
    its Figure."""
    if ax is None:
        fig = Figure(figsize=figsize, layout="constrained")
        made = fig.subplots(**subplots) if subplots else fig.add_subplot()
        return fig, list(np.ravel(made))
    given = [ax] if hasattr(ax, "figure") else list(np.ravel(ax))
    if len(given) != count:
        raise ValueError(f"ax: {len(given)} Axes given; allowed: {'one' if count == 1 else count} "
                         f"(this figure has {count} panel{'s' if count > 1 else ''})")
    return given[0].figure, given


def _reference(run):
    """The stored reference (analysis.reference) if ``run`` is a ``data/reference/<case>`` folder, else None."""
    folder = check_run(run)
    if not ((folder / "snapshots.npz").is_file() and (folder / "reference.json").is_file()):
        return None
    from ..reference import load_reference

    return load_reference(folder.name, folder.parent)


def _reference_snapshot(reference, time):
    """(index, time [s]) of a stored reference's snapshot nearest ``time`` (None: the last)."""
    times = np.asarray(reference.snapshot_times, dtype=float)
    if times.size == 0:
        raise NoData("no snapshots stored in this reference")
    if time is None:
        k = times.size - 1
    else:
        time = float(time)
        if not math.isfinite(time):
            raise ValueError(f"time = {time!r}: give a finite snapshot time [s]")
        k = int(min(range(times.size), key=lambda q: (abs(times[q] - time), -times[q])))
    return k, float(times[k])


def read_droplets(run, time=None) -> tuple[float, pd.DataFrame]:
    """The droplets of the snapshot nearest ``time`` [s] (None: the last): (its time [s], DataFrame).

    Columns (SI units, one row per droplet): x, y, z [m] (centre), diameter [m], u, v, w [m/s] (velocity),
    settling_velocity [m/s] (= -w, downward positive), density [kg/m^3], age [s], and where the file holds them
    ident [-] and merged (1.0 if the droplet was formed by coalescence, else 0.0; newer runs only). A snapshot
    without droplets gives an empty frame with these columns. Raises NoData if there is no such snapshot file.
    """
    reference = _reference(run)
    if reference is not None:  # a stored reference: its float32 snapshots
        k, t = _reference_snapshot(reference, time)
        return t, reference.droplets(k)
    t, path = pick_snapshot(run, time, 0)
    return t, droplets_file(path)


def read_slag(run, time=None) -> tuple[float, np.ndarray, np.ndarray]:
    """The slag grid of the snapshot nearest ``time`` [s] (None: the last): (its time [s], cell centres (n, 3) [m],
    cell velocity (n, 3) [m/s]). A cell's centre is the mean of its 8 corner points. Raises NoData if there is no
    such snapshot file or it holds no hexahedra with a velocity."""
    reference = _reference(run)
    if reference is not None:  # a stored reference keeps the central x-z plane only
        k, t = _reference_snapshot(reference, time)
        x, z, velocity = reference.slag(k)
        if len(x) == 0:
            raise NoData(f"the stored snapshot at t = {t:g} s has no slag plane")
        centres = np.column_stack([x, np.full(len(x), reference.slag_plane_y(k)), z]).astype(float)
        return t, centres, np.asarray(velocity, dtype=float).reshape(-1, 3)
    t, path = pick_snapshot(run, time, 1)
    centres, velocity = slag_file(path)
    return t, centres, velocity


def _time_series(run) -> pd.DataFrame:
    path = check_run(run) / "timeseries.csv"
    if not path.is_file():
        raise NoData("no timeseries.csv")
    frame = read_time_series(path)
    if "time" not in frame or frame.empty:
        raise NoData("timeseries.csv has no rows" if "time" in frame else "timeseries.csv has no time column")
    return frame


def _channel_profile(run) -> pd.DataFrame:
    path = check_run(run) / "channel_profile.csv"
    if not path.is_file():
        raise NoData("no channel_profile.csv")
    try:
        from settler.output import read_channel_profile
    except ImportError:  # an older settler: the same CSV reading
        def read_channel_profile(p):
            return pd.read_csv(p, comment="#")
    return read_channel_profile(path)


def _case(run):
    """The run's resolved case from ``case.toml``, or None if it is missing or cannot be read."""
    from settler.cases import CaseError, load_case

    path = check_run(run) / "case.toml"
    if not path.is_file():
        return None
    try:
        return load_case(path)
    except (CaseError, OSError, ValueError):
        return None


def _case_name(run) -> str:
    case = _case(run)
    return case.case.name if case is not None and getattr(case.case, "name", None) else Path(run).resolve().name


def _need_case(run, what):
    case = _case(run)
    if case is None:
        raise NoData(f"no readable case.toml (needed for {what})")
    return case


def _finite(frame, column) -> bool:
    return column in frame and bool(np.isfinite(frame[column].to_numpy(dtype=float)).any())


def _need_columns(frame, columns, figure):
    present = [c for c in columns if _finite(frame, c)]
    if not present:
        raise NoData(f"timeseries.csv has no values of {', '.join(columns)} (needed for {figure})")
    return present


def _table(run, name) -> pd.DataFrame | None:
    path = check_run(run) / name
    if not path.is_file():
        return None
    frame = pd.read_csv(path, comment="#")
    return frame if len(frame) else None

