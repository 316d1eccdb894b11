"""A full (fulldem) run against a reduced (popbal) run, column by column: ``settler compare FULL REDUCED --out DIR``.

What is compared (:data:`COLUMNS`, SI units): droplet_count [-], mean_diameter [m], sauter_diameter [m],
settled_fraction [-] (= mass_settled / mass_fed, NaN while nothing is fed), channel_radius [m], channel_velocity
[m/s] and mean_settling_velocity [m/s]. A column that is NaN throughout either run is skipped, with the reason.

The side-by-side table (:func:`side_by_side`) is on the full run's times within the span both runs cover; the
reduced run's columns are interpolated linearly onto them (NaN where a neighbouring reduced value is NaN; no
extrapolation), settled_fraction from its interpolated masses.

**Error definition.** For a column and a time window [start, end] (ends included): the window means of the full and
the reduced values over the table's rows in the window where both are finite (plain means of the rows: the full
run writes at a fixed output interval, so this is the time mean), and

    relative_error = abs(mean_reduced - mean_full) / abs(mean_full)

(NaN where no row is in the window or mean_full = 0). :func:`relative_error` and :func:`window_errors` are this
definition, pure and small, for reuse (calibration).

**Default windows** (:func:`default_windows`): the four quarters ``q1`` .. ``q4`` of the common time span and
``steady``, its last third (:data:`STEADY_FRACTION`), where the runs are compared once the start-up has passed.

Outputs of the command (all written atomically): ``comparison.csv`` (the side-by-side table, a units line first),
``errors.csv`` (per column per window), ``comparison.png`` (one panel per column, both runs, windows shaded) and
``comparison.json`` (inputs, windows, error definition, skipped columns, units); a short table is printed. When
both runs carry ``channel_profile.csv`` and ``merges_by_height.csv``, also ``profiles.csv`` and ``profiles.png``: where
the droplets are and merge against height over the ``steady`` window (:mod:`analysis.profiles`).
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from settler.output import OutputError, atomic_write_bytes, atomic_write_text, prepare_output_folder, to_json

from .runs import Run, load_run

#: Compared columns -> (unit, meaning). settled_fraction is derived; the others are time-series columns.
COLUMNS: dict[str, tuple[str, str]] = {
    "droplet_count": ("-", "number of droplets in the slag"),
    "mean_diameter": ("m", "number-mean droplet diameter in the slag"),
    "sauter_diameter": ("m", "Sauter mean diameter d32 in the slag"),
    "settled_fraction": ("-", "mass_settled / mass_fed: fraction of the fed matte that reached the bottom"),
    "channel_radius": ("m", "radius around the inlet axis holding half the droplet volume at mid-height"),
    "channel_velocity": ("m/s", "downward slag velocity on the inlet axis at mid-height"),
    "mean_settling_velocity": ("m/s", "number-mean downward velocity of the droplets in the slag"),
}
#: Relative tolerance on the ends of the common time span (a full run's 60 s may be written as 60.00000000003 s).
TIME_TOLERANCE = 1e-9
#: Fraction of the common time span, at its end, that makes the ``steady`` window.
STEADY_FRACTION = 1.0 / 3.0
ERROR_DEFINITION = ("relative error of the window mean: |mean_reduced - mean_full| / |mean_full|, means over the "
                    "rows of the side-by-side table (the full run's times) in the window where both are finite")
#: Output files of the command.
OUTPUT_FILES = ("comparison.csv", "errors.csv", "comparison.png", "comparison.json")
ERROR_COLUMNS = ["column", "window", "start", "end", "points", "mean_full", "mean_reduced", "relative_error", "note"]


@dataclasses.dataclass(frozen=True)
class Window:
    """A time window [start, end] [s] (ends included) named for the tables."""

    name: str
    start: float
    end: float


# --------------------------------------------------------------------------------------------- the definition
def relative_error(mean_full: float, mean_reduced: float) -> float:
    """abs(mean_reduced - mean_full) / abs(mean_full) [-]; NaN if either is not finite or mean_full is 0."""
    if not (math.isfinite(mean_full) and math.isfinite(mean_reduced)) or mean_full == 0.0:
        return math.nan
    return abs(mean_reduced - mean_full) / abs(mean_full)


def window_errors(time, full, reduced, windows) -> pd.DataFrame:
    """Relative error of the window mean (:func:`relative_error`) of one column in each window.

    ``time`` [s], ``full``, ``reduced``: equal-length arrays (the reduced values already on the full run's
    times); ``windows``: :class:`Window` items (or (name, start, end) tuples). Rows with a non-finite value in
    either run are left out. Returns one row per window: window, start, end [s], points (rows used), mean_full,
    mean_reduced (the column's unit) and relative_error [-] (NaN for a window without rows). Pure: no I/O.
    """
    time = np.asarray(time, dtype=float)
    full = np.asarray(full, dtype=float)
    reduced = np.asarray(reduced, dtype=float)
    if not time.shape == full.shape == reduced.shape:
        raise ValueError(f"window_errors: time, full and reduced differ in shape ({time.shape}, {full.shape}, "
                         f"{reduced.shape})")
    usable = np.isfinite(full) & np.isfinite(reduced)
    rows = []
    for window in windows:
        window = Window(*window) if not isinstance(window, Window) else window
        inside = usable & (time >= window.start) & (time <= window.end)
        points = int(inside.sum())
        mean_full = float(full[inside].mean()) if points else math.nan
        mean_reduced = float(reduced[inside].mean()) if points else math.nan
        rows.append({"window": window.name, "start": window.start, "end": window.end, "points": points,
                     "mean_full": mean_full, "mean_reduced": mean_reduced,
                     "relative_error": relative_error(mean_full, mean_reduced)})
    return pd.DataFrame(rows, columns=ERROR_COLUMNS[1:-1])


def default_windows(start: float, end: float) -> list[Window]:
    """The quarters ``q1`` .. ``q4`` of [start, end] [s] and ``steady``, its last :data:`STEADY_FRACTION`."""
    edges = np.linspace(start, end, 5)
    quarters = [Window(f"q{k + 1}", float(edges[k]), float(edges[k + 1])) for k in range(4)]
    return quarters + [Window("steady", float(end - STEADY_FRACTION * (end - start)), float(end))]


_WINDOW = re.compile(r"^(?:(?P<name>[A-Za-z_][\w-]*)=)?(?P<start>[^:=]+):(?P<end>[^:=]+)$")


def parse_windows(text: str, start: float, end: float) -> list[Window]:
    """Windows from the command line: comma-separated ``START:END`` or ``NAME=START:END`` [s], and the words
    ``quarters`` (q1 .. q4 of the common span [start, end]), ``steady`` (its last third) or ``default`` (both).
    An unnamed window is called ``START-END``. Raises OutputError naming the item and what is allowed."""
    defaults = default_windows(start, end)
    words = {"default": defaults, "quarters": defaults[:4], "steady": defaults[4:]}
    windows: list[Window] = []
    for item in (part.strip() for part in str(text).split(",")):
        if item in words:
            windows += words[item]
            continue
        match = _WINDOW.match(item)
        try:
            low, high = float(match["start"]), float(match["end"])
        except (TypeError, ValueError):
            raise OutputError(f"--windows {item!r}: allowed: START:END or NAME=START:END in seconds, or "
                              "quarters, steady, default; comma-separated") from None
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise OutputError(f"--windows {item!r}: allowed: finite times [s] with START < END")
        windows.append(Window(match["name"] or f"{low:g}-{high:g}", low, high))
    names = [w.name for w in windows]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise OutputError(f"--windows {text!r}: window names {repeated} repeated; give each window its own name")
    return windows


# ------------------------------------------------------------------------------------------------ the tables
def compared_series(frame: pd.DataFrame) -> pd.DataFrame:
    """``time`` and the :data:`COLUMNS` of a time series (settled_fraction derived; a column the series lacks is
    NaN)."""
    out = pd.DataFrame({"time": frame["time"].to_numpy(dtype=float)})
    for column in COLUMNS:
        if column == "settled_fraction":
            fed = frame.get("mass_fed", pd.Series(np.nan, index=frame.index)).to_numpy(dtype=float)
            settled = frame.get("mass_settled", pd.Series(np.nan, index=frame.index)).to_numpy(dtype=float)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[column] = np.where(fed > 0.0, settled / np.where(fed > 0.0, fed, 1.0), np.nan)
        else:
            out[column] = frame[column].to_numpy(dtype=float) if column in frame else np.nan
    return out


def interpolate(time, source_time, values) -> np.ndarray:
    """``values`` given at ``source_time`` [s] (ascending), linearly interpolated to ``time`` [s]: NaN outside
    the source's span and wherever a bracketing value is NaN."""
    time = np.asarray(time, dtype=float)
    source_time = np.asarray(source_time, dtype=float)
    values = np.asarray(values, dtype=float)
    if source_time.size == 0:
        return np.full(time.shape, np.nan)
    out = np.interp(time, source_time, values, left=np.nan, right=np.nan)
    exact = np.searchsorted(source_time, time)  # np.interp takes a NaN neighbour into an exact hit: restore it
    hit = (exact < source_time.size) & (source_time[np.minimum(exact, source_time.size - 1)] == time)
    out[hit] = values[exact[hit]]
    return out


def common_span(full: pd.DataFrame, reduced: pd.DataFrame) -> tuple[float, float]:
    """[start, end] [s] covered by both time series; OutputError if they do not overlap."""
    start = max(float(full["time"].min()), float(reduced["time"].min()))
    end = min(float(full["time"].max()), float(reduced["time"].max()))
    if not end > start:
        raise OutputError(f"the runs share no time span (full {full['time'].min():g}-{full['time'].max():g} s, "
                          f"reduced {reduced['time'].min():g}-{reduced['time'].max():g} s)")
    return start, end


def side_by_side(full: pd.DataFrame, reduced: pd.DataFrame) -> pd.DataFrame:
    """The compared columns of both time series on the full run's times within :func:`common_span` (ends widened by
    :data:`TIME_TOLERANCE`, the reduced run taken at the end there): ``time`` [s],
    then ``<column>_full`` and ``<column>_reduced`` per column of :data:`COLUMNS`. The reduced run's time-series
    columns are interpolated (:func:`interpolate`) before settled_fraction is derived from its masses."""
    start, end = common_span(full, reduced)
    tolerance = TIME_TOLERANCE * max(end - start, abs(end))  # both engines' end times carry round-off
    f = compared_series(full)
    f = f[(f["time"] >= start - tolerance) & (f["time"] <= end + tolerance)].reset_index(drop=True)
    at = np.clip(f["time"].to_numpy(), start, end)
    # the reduced run's own columns (masses, not their ratio) interpolated, then the compared ones derived
    r = reduced.sort_values("time", kind="stable")
    r = compared_series(pd.DataFrame({"time": at, **{c: interpolate(at, r["time"], r[c]) for c in r.columns
                                                     if c != "time"}}))
    table = pd.DataFrame({"time": f["time"]})
    for column in COLUMNS:
        table[f"{column}_full"] = f[column]
        table[f"{column}_reduced"] = r[column].to_numpy()
    return table


def skip_reasons(full: pd.DataFrame, reduced: pd.DataFrame, labels=("full", "reduced")) -> dict[str, str]:
    """Column of :data:`COLUMNS` -> why it is not compared: NaN throughout (or missing from) either time series."""
    reasons = {}
    for column in COLUMNS:
        empty = [label for label, frame in zip(labels, (compared_series(full), compared_series(reduced)))
                 if not np.isfinite(frame[column].to_numpy(dtype=float)).any()]
        if empty:
            reasons[column] = f"NaN throughout the {' and the '.join(empty)} run (not computed there)"
    return reasons


def error_table(table: pd.DataFrame, windows, skipped: dict[str, str] | None = None) -> pd.DataFrame:
    """:func:`window_errors` of every column of :data:`COLUMNS` in a side-by-side ``table``, stacked (columns of
    :data:`ERROR_COLUMNS`); a skipped column gets one row per window with NaN errors and its reason as the note."""
    skipped = skipped or {}
    parts = []
    for column in COLUMNS:
        if column in skipped:
            errors = pd.DataFrame([{"window": w.name, "start": w.start, "end": w.end, "points": 0} for w in windows],
                                  columns=ERROR_COLUMNS[1:-1])
            errors["note"] = f"skipped: {skipped[column]}"
        else:
            errors = window_errors(table["time"], table[f"{column}_full"], table[f"{column}_reduced"], windows)
            errors["note"] = [_why_undefined(row) for row in errors.to_dict("records")]
        errors.insert(0, "column", column)
        parts.append(errors)
    return pd.concat(parts, ignore_index=True)[ERROR_COLUMNS]


def _why_undefined(row: dict) -> str:
    """Why a row of :func:`window_errors` has no relative error ("" if it has one)."""
    if row["points"] == 0:
        return "no row in the window where both runs have values"
    if row["mean_full"] == 0.0:
        return "the full run's window mean is 0: relative error undefined"
    return ""


@dataclasses.dataclass
class Comparison:
    """What :func:`compare` returns: the side-by-side ``table``, the ``errors`` per column per window, the
    ``windows``, the ``skipped`` columns with reasons, and both runs."""

    full: Run
    reduced: Run
    table: pd.DataFrame
    errors: pd.DataFrame
    windows: list[Window]
    skipped: dict[str, str]
    band: "Band | None" = None

    @property
    def compared(self) -> list[str]:
        """The columns compared (not skipped)."""
        return [c for c in COLUMNS if c not in self.skipped]

    def steady_errors(self, window: str = "steady") -> pd.Series:
        """column -> relative error [-] in the named window (default ``steady``)."""
        rows = self.errors[self.errors["window"] == window]
        return pd.Series(rows["relative_error"].to_numpy(), index=rows["column"].to_numpy(), name=window)


def compare(full, reduced, windows=None) -> Comparison:
    """Compare a full run with a reduced run (each a :class:`analysis.runs.Run` or a run folder).

    ``windows``: :class:`Window` items or (name, start, end) tuples [s], a command-line string
    (:func:`parse_windows`), or None for :func:`default_windows` of the common span. Raises OutputError for a folder
    that is not a run or runs that share no time span.
    """
    full, reduced = load_run(full), load_run(reduced)
    table = side_by_side(full.timeseries, reduced.timeseries)
    start, end = common_span(full.timeseries, reduced.timeseries)
    if windows is None:
        windows = default_windows(start, end)
    elif isinstance(windows, str):
        windows = parse_windows(windows, start, end)
    else:
        windows = [w if isinstance(w, Window) else Window(*w) for w in windows]
    skipped = skip_reasons(full.timeseries, reduced.timeseries)
    return Comparison(full=full, reduced=reduced, table=table, errors=error_table(table, windows, skipped),
                      windows=windows, skipped=skipped)


# -------------------------------------------------------------------------------------------------- the band
#: Columns a band adds to the error table: the 5 %, 50 % and 95 % quantiles of the reduced window mean over the
#: band's runs, and whether the full run's window mean lies inside the 90 % band.
BAND_COLUMNS = ["band_low", "band_median", "band_high", "inside_band"]
#: Columns that are shares of the matte fed, so at most 1 in a band.
FRACTIONS = ("settled_fraction",)


@dataclasses.dataclass(frozen=True)
class Band:
    """The reduced model's 90 % prediction band (:mod:`analysis.calibration.bands`): ``samples`` popbal runs of the
    reduced run's case with the calibration ``layer`` applied and its parameters drawn from the layer's estimates
    and covariance, each run's columns times exp(delta z) for the layer's model discrepancy delta.
    ``quantiles``: {column: (3, rows)} 5/50/95 % on the side-by-side table's times; ``windows``: the window means'
    quantiles per column and window (columns ``column``, ``window`` and :data:`BAND_COLUMNS`)."""

    layer: str
    samples: int
    delta: float
    quantiles: dict
    windows: pd.DataFrame


def prediction_band(comparison: Comparison, layer: str, samples: int = 20, seed: int = 0, progress=None) -> Band:
    """The :class:`Band` of ``comparison``'s reduced run under calibration ``layer`` (a layer of ``settler calibrate
    --set`` in data/calibration/), from ``samples`` popbal runs to the reduced run's end time at its output
    interval. ``progress``: a callable (done, total) or None."""
    from .calibration.bands import QUANTILES, discrepancy_factors, sample_runs

    reduced = comparison.reduced.timeseries
    times = np.sort(reduced["time"].to_numpy(dtype=float))
    interval = float(np.median(np.diff(times))) if times.size > 1 else float(times.max())
    series, delta = sample_runs(comparison.reduced.folder / "case.toml", layer, samples, float(times.max()),
                                interval, seed=seed, progress=progress)
    factors = discrepancy_factors(samples, comparison.compared, delta, seed)
    full_time = comparison.table["time"].to_numpy()
    quantiles, rows = {}, []
    tables = [_on_times(comparison, s) for s in series]  # one side-by-side table per band run, not per column
    for column in comparison.compared:
        stack = np.stack([t[f"{column}_reduced"].to_numpy(dtype=float) for t in tables]) * factors[column][:, None]
        if column in FRACTIONS:  # a share of the feed: the discrepancy cannot take it past 1
            stack = np.minimum(stack, 1.0)
        with warnings.catch_warnings():  # rows where every run is NaN (before the first droplet) stay NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            quantiles[column] = np.nanquantile(stack, QUANTILES, axis=0)
        full = comparison.table[f"{column}_full"].to_numpy()
        both = np.isfinite(full) & np.isfinite(comparison.table[f"{column}_reduced"].to_numpy())
        for window in comparison.windows:  # the rows of the error definition: both runs finite (window_errors)
            inside = (full_time >= window.start) & (full_time <= window.end) & both
            means = np.array([np.nanmean(row[inside]) if np.isfinite(row[inside]).any() else np.nan
                              for row in stack])
            low, median, high = (np.nanquantile(means, QUANTILES) if np.isfinite(means).any()
                                 else (np.nan, np.nan, np.nan))
            mean_full = float(np.mean(full[inside])) if inside.any() else math.nan
            rows.append({"column": column, "window": window.name, "band_low": low, "band_median": median,
                         "band_high": high, "inside_band": bool(low <= mean_full <= high)
                         if math.isfinite(mean_full) and math.isfinite(low) else None})
    return Band(layer=layer, samples=samples, delta=delta, quantiles=quantiles,
                windows=pd.DataFrame(rows, columns=["column", "window", *BAND_COLUMNS]))


def _on_times(comparison: Comparison, series: pd.DataFrame) -> pd.DataFrame:
    """A band run's side-by-side table on the comparison table's times (NaN rows where the run has none)."""
    table = side_by_side(comparison.full.timeseries, series).set_index("time")
    return table.reindex(comparison.table["time"].to_numpy())


def with_band(comparison: Comparison, band: Band) -> Comparison:
    """``comparison`` with ``band`` attached and its error table widened by :data:`BAND_COLUMNS`."""
    errors = comparison.errors.merge(band.windows, on=["column", "window"], how="left")
    return dataclasses.replace(comparison, band=band, errors=errors)


def band_summary(band: Band, window: str | None = None) -> str:
    """One line: how many of the full run's window means in ``window`` (default ``steady``, else the last window)
    lie inside their 90 % band."""
    names = list(dict.fromkeys(band.windows["window"]))
    window = window or ("steady" if "steady" in names else names[-1] if names else "steady")
    rows = band.windows[(band.windows["window"] == window) & band.windows["inside_band"].notna()]
    inside = int(rows["inside_band"].astype(bool).sum())
    outside = ", ".join(rows.loc[~rows["inside_band"].astype(bool), "column"])
    return (f"90 % band ({band.samples} popbal runs of calibration layer {band.layer!r}, discrepancy "
            f"{band.delta:.3g}): {inside} of {len(rows)} {window}-window means of the full run inside"
            + (f"; outside: {outside}" if outside else ""))


# ------------------------------------------------------------------------------------------------- the figure
#: Scale and unit shown on the figure's axes, per unit of :data:`COLUMNS`.
DISPLAY = {"m": (1e3, "mm"), "m/s": (1e3, "mm/s"), "-": (1.0, "-")}


def comparison_figure(comparison: Comparison):
    """One panel per compared column against time [s]: the full run, the reduced run (its own output times) and the
    windows shaded (labelled with their relative error). Returns a matplotlib Figure (made without pyplot)."""
    from matplotlib.figure import Figure

    columns = comparison.compared or list(COLUMNS)[:1]
    ncols = 2 if len(columns) > 1 else 1
    nrows = math.ceil(len(columns) / ncols)
    fig = Figure(figsize=(6.0 * ncols, 2.8 * nrows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, squeeze=False)).ravel()
    reduced = compared_series(comparison.reduced.timeseries)
    start, end = float(comparison.table["time"].min()), float(comparison.table["time"].max())
    reduced = reduced[(reduced["time"] >= start) & (reduced["time"] <= end)]
    for ax, column in zip(axes, columns):
        scale, unit = DISPLAY[COLUMNS[column][0]]
        ax.plot(comparison.table["time"], scale * comparison.table[f"{column}_full"], label="full (fulldem)")
        ax.plot(reduced["time"], scale * reduced[column], label="reduced (popbal)", linestyle="--")
        if comparison.band is not None and column in comparison.band.quantiles:
            q = comparison.band.quantiles[column]
            ax.fill_between(comparison.table["time"], scale * q[0], scale * q[-1], color="C1", alpha=0.2,
                            linewidth=0, label=f"90 % band ({comparison.band.layer})")
        low, high = ax.get_ylim()  # headroom above the curves for the windows' notes
        ax.set_ylim(low, high + (0.12 + 0.09 * max(window_levels(comparison.windows), default=0)) * (high - low))
        _shade_windows(ax, comparison, column)
        words = column.replace("_", " ")
        ax.set_ylabel(f"{words} [{unit}]" if unit != "-" else words)
        ax.grid(alpha=0.3)
    for ax in axes[len(columns):]:
        ax.set_visible(False)
    for ax in axes[max(len(columns) - ncols, 0):len(columns)]:
        ax.set_xlabel("time [s]")
        ax.tick_params(labelbottom=True)
    axes[0].legend(fontsize="small")
    fig.suptitle(f"{comparison.full.name} (full) vs {comparison.reduced.name} (reduced); shaded: windows "
                 "(relative error of the window mean)", fontsize="medium")
    return fig


def window_levels(windows) -> list[int]:
    """A level per window (0, 1, ...) such that windows on one level do not overlap: the first level free of
    overlaps, in the order given (the quarters on level 0, the steady window above them)."""
    placed: list[list] = []
    levels = []
    for window in windows:
        level = next((k for k, row in enumerate(placed)
                      if all(window.end <= w.start or window.start >= w.end for w in row)), len(placed))
        if level == len(placed):
            placed.append([])
        placed[level].append(window)
        levels.append(level)
    return levels


def _shade_windows(ax, comparison: Comparison, column: str):
    """Shade the windows (level 0 filled, higher levels hatched) and label each with its relative error."""
    errors = comparison.errors[comparison.errors["column"] == column].set_index("window")["relative_error"]
    for k, (window, level) in enumerate(zip(comparison.windows, window_levels(comparison.windows))):
        colour = f"C{2 + k % 6}"
        if level == 0:
            ax.axvspan(window.start, window.end, color=colour, alpha=0.12, linewidth=0)
        else:
            ax.axvspan(window.start, window.end, facecolor="none", edgecolor=colour, hatch="//", alpha=0.35,
                       linewidth=0)
        error = errors.get(window.name, math.nan)
        text = f"{window.name}: {100 * error:.3g} %" if math.isfinite(error) else f"{window.name}: –"
        ax.text(0.5 * (window.start + window.end), 0.98 - 0.09 * level, text, transform=ax.get_xaxis_transform(),
                ha="center", va="top", fontsize="x-small")


# ----------------------------------------------------------------------------------------------- the command
def add_arguments(parser) -> None:
    """Arguments of ``settler compare``."""
    parser.add_argument("full", help="the full run: the --out folder of 'settler full', or a stored "
                                     "data/reference/<case> folder")
    parser.add_argument("reduced", help="the reduced run: the --out folder of 'settler reduced'")
    parser.add_argument("--out", metavar="DIR", required=True,
                        help="folder to write comparison.csv, errors.csv, comparison.png and comparison.json into "
                             "(and profiles.csv, profiles.png when both runs have height tables) "
                             "(created if missing; a run folder is refused; an earlier comparison there is "
                             "replaced)")
    parser.add_argument("--windows", metavar="LIST", default=None,
                        help="time windows [s] for the errors, comma-separated: START:END, NAME=START:END, or the "
                             "words quarters (q1..q4 of the common span), steady (its last third), default (both; "
                             "the default)")
    parser.add_argument("--band", metavar="LAYER", default=None,
                        help="draw the reduced model's 90 %% prediction band: popbal rerun on the reduced run's case "
                             "with this calibration layer of 'settler calibrate --set' (a name in data/calibration/, "
                             "e.g. designed), its parameters drawn from the layer's estimates and covariance and its "
                             "model discrepancy added; errors.csv then says whether each full window mean lies inside")
    parser.add_argument("--band-samples", metavar="N", type=int, default=None,
                        help="popbal runs for the band (default 20; at least 5; only with --band)")


def write_outputs(comparison: Comparison, out: Path, command_line: str | None = None) -> dict[str, Path]:
    """Write :data:`OUTPUT_FILES` into ``out`` (atomically); returns name -> path."""
    units = {"time": "s", **{f"{c}_{side}": COLUMNS[c][0] for c in COLUMNS for side in ("full", "reduced")}}
    paths = {name: out / name for name in OUTPUT_FILES}
    table = comparison.table.copy()
    if comparison.band is not None:
        for column, q in comparison.band.quantiles.items():
            for name, row in zip(("band_low", "band_high"), (q[0], q[-1])):
                table[f"{column}_{name}"] = row
                units[f"{column}_{name}"] = COLUMNS[column][0]
    atomic_write_text(paths["comparison.csv"], "# units: " + ", ".join(f"{c} [{u}]" for c, u in units.items())
                      + "\n" + table.to_csv(index=False))
    band_units = (", band_low, band_median and band_high [unit of the column], inside_band [true/false]"
                  if comparison.band is not None else "")
    atomic_write_text(paths["errors.csv"], "# units: start [s], end [s], points [-], mean_full and mean_reduced "
                      "[unit of the column, comparison.json], relative_error [-]" + band_units + "\n"
                      + comparison.errors.to_csv(index=False))
    _write_png(comparison_figure(comparison), paths["comparison.png"])
    info = {"command": command_line, "error_definition": ERROR_DEFINITION,
            "full": _describe(comparison.full), "reduced": _describe(comparison.reduced),
            "windows": [dataclasses.asdict(w) for w in comparison.windows], "window_unit": "s",
            "columns": {c: {"unit": u, "meaning": m} for c, (u, m) in COLUMNS.items()},
            "skipped": comparison.skipped}
    if comparison.band is not None:
        b = comparison.band
        info["band"] = {"layer": b.layer, "samples": b.samples, "discrepancy": b.delta, "quantiles": [0.05, 0.5, 0.95],
                        "definition": "popbal on the reduced run's case with the layer applied, its parameters drawn "
                                      "from the layer's estimates and covariance, each run times exp(delta z); "
                                      "comparison.csv <column>_band_low/_high per row, errors.csv band_* per window",
                        "summary": band_summary(b)}
    info["profiles"] = _write_profiles(comparison, out, paths)
    atomic_write_text(paths["comparison.json"], to_json(info) + "\n")
    return paths


def _write_profiles(comparison: Comparison, out: Path, paths: dict[str, Path]) -> dict:
    """``profiles.csv`` and ``profiles.png`` (:mod:`analysis.profiles`) for the ``steady`` window (the last window
    if none is named so) when both runs carry the height tables; what comparison.json records of them."""
    from .profiles import PROFILE, has_profiles, profile_comparison, profile_figure, profile_units

    def skipped(reason):
        for name in ("profiles.csv", "profiles.png"):  # an earlier comparison's, which these runs do not replace
            (out / name).unlink(missing_ok=True)
        return {"skipped": reason}

    missing = [r.folder for r in (comparison.full, comparison.reduced) if not has_profiles(r)]
    if missing:
        return skipped(f"no channel_profile.csv and merges_by_height.csv in {', '.join(map(str, missing))}")
    window = next((w for w in comparison.windows if w.name == "steady"), comparison.windows[-1])
    try:
        table = profile_comparison(comparison.full, comparison.reduced, (window.start, window.end))
    except ValueError as exc:
        return skipped(str(exc))
    units = profile_units()
    paths["profiles.csv"] = out / "profiles.csv"
    atomic_write_text(paths["profiles.csv"], "# units: " + ", ".join(f"{c} [{u}]" for c, u in units.items())
                      + "\n" + table.to_csv(index=False))
    paths["profiles.png"] = out / "profiles.png"
    _write_png(profile_figure(table, (f"{comparison.full.folder.name} (full)",
                                      f"{comparison.reduced.folder.name} (reduced)"), (window.start, window.end)),
               paths["profiles.png"])
    return {"window": dataclasses.asdict(window), "files": ["profiles.csv", "profiles.png"],
            "merge_spans": {side: list(span) for side, span in table.attrs["merge_spans"].items()},
            "columns": {c: {"unit": u, "meaning": m} for c, (u, m) in PROFILE.items()},
            "definition": "analysis.profiles: per height band, droplet volume averaged over the window's profile "
                          "rows, merges between the first and last merges_by_height rows inside the window over "
                          "their time"}


def _write_png(fig, path: Path) -> None:
    """Write a matplotlib figure as a PNG atomically and release it."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    fig.clear()
    atomic_write_bytes(path, buffer.getvalue())


def _describe(run: Run) -> dict:
    meta = run.metadata or {}
    return {"folder": str(run.folder.resolve()), "engine": run.engine, "case": run.name,
            "commit": meta.get("commit") or (run.reference or {}).get("commit"),
            "end_time": float(run.timeseries["time"].max())}


def error_summary(comparison: Comparison) -> str:
    """A short text table: relative error [%] per compared column (rows) and window (columns), then the skipped
    columns with their reasons."""
    names = [w.name for w in comparison.windows]
    width = max(len(c) for c in COLUMNS)
    lines = [f"{'relative error [%]':<{width}s}  " + "  ".join(f"{n:>8s}" for n in names)]
    for column in comparison.compared:
        errors = comparison.errors[comparison.errors["column"] == column].set_index("window")["relative_error"]
        cells = ["{:>8s}".format(f"{100 * errors[n]:.3g}" if math.isfinite(errors[n]) else "-") for n in names]
        lines.append(f"{column:<{width}s}  " + "  ".join(cells))
    lines += [f"skipped {column}: {reason}" for column, reason in comparison.skipped.items()]
    return "\n".join(lines)


def main(args) -> int:
    """``settler compare FULL REDUCED --out DIR [--windows LIST]``: 0 done; OutputError (exit 2 through settler.cli)
    for a folder that is not a run, bad windows or an unusable output folder."""
    prepare_output_folder(args.out, option="--out", create=False)  # refuse a bad --out before the work
    if args.band_samples is not None and args.band is None:
        raise OutputError(f"--band-samples {args.band_samples}: only with --band LAYER (the band it sizes)")
    comparison = compare(args.full, args.reduced, windows=args.windows)
    if args.band is not None:
        comparison = _add_band(comparison, args.band, args.band_samples or 20)
    for run, wanted in ((comparison.full, "fulldem"), (comparison.reduced, "popbal")):
        if run.engine != wanted:
            print(f"settler compare: warning: {run.folder} was made by {run.engine or 'an unknown engine'}, "
                  f"not {wanted}", file=sys.stderr)
    out = prepare_output_folder(args.out, option="--out")  # refuses a file, an unwritable folder, a run folder
    paths = write_outputs(comparison, out, getattr(args, "command_line", None))
    profiles = json.loads(paths["comparison.json"].read_text()).get("profiles", {})
    print(f"{comparison.full.name} ({comparison.full.engine}, {comparison.full.folder}) vs "
          f"{comparison.reduced.name} ({comparison.reduced.engine}, {comparison.reduced.folder}), "
          f"t = {comparison.table['time'].min():g}-{comparison.table['time'].max():g} s, "
          f"{len(comparison.table)} rows")
    print(error_summary(comparison))
    if comparison.band is not None:
        print(band_summary(comparison.band))
    if "profiles.csv" in paths:
        from .profiles import profile_summary
        spans = ", ".join(f"{side} {t0:g}-{t1:g} s" for side, (t0, t1) in profiles["merge_spans"].items())
        print(profile_summary(pd.read_csv(paths["profiles.csv"], comment="#")) + f"\n(merges over {spans})")
    elif "skipped" in profiles:
        print(f"no height profiles: {profiles['skipped']}")
    print(f"wrote {', '.join(str(p) for p in paths.values())}")
    return 0


def _add_band(comparison: Comparison, layer: str, samples: int) -> Comparison:
    """The command's band: clear errors for a bad --band or --band-samples, a progress bar on stderr."""
    from tqdm import tqdm

    from settler.cases import CaseError

    if samples < 5:
        raise OutputError(f"--band-samples {samples}: allowed: an integer of at least 5 (a 90 % band from fewer "
                          "runs is its extremes)")
    bar = tqdm(total=samples, desc="band", unit="run", file=sys.stderr, disable=None)
    try:
        band = prediction_band(comparison, layer, samples, progress=lambda done, total: bar.update(1))
    except ValueError as exc:
        raise OutputError(f"--band {layer}: {exc}; allowed: a layer written by 'settler calibrate --set' "
                          "(e.g. designed)") from None
    except CaseError as exc:
        raise OutputError(f"--band {layer}: {exc}") from None
    finally:
        bar.close()
    return with_band(comparison, band)
