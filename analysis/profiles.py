"""Where the droplets are and where they merge, against height: a full run beside a reduced run (SI units).

A reduced model can match a run's droplet count while holding its droplets, or merging them, in the wrong place:
the count is a sum over heights. Both engines write, in the :data:`settler.output.PROFILE_BANDS` height bands of
``settler.output.band_edges``, the droplet volume (``channel_profile.csv``) and the merges since the start
(``merges_by_height.csv``, "under the inlet" and "elsewhere"), so the two can be compared band by band over a window:

- ``droplet_volume`` [m^3]: the band's droplet volume, the mean over the profile rows in the window (ends
  included);
- ``merge_rate_under_inlet`` and ``merge_rate_elsewhere`` [1/s]: the merges in the band between the first and the
  last ``merges_by_height`` rows inside the window (ends included), over the time between them
  (:func:`analysis.band_efficiency.merges_between`); the two engines write at different intervals (a full run at its
  snapshots, popbal at its outputs), so each run's span is reported with its profile.

``settler compare FULL REDUCED --out DIR`` writes them as ``profiles.csv`` and ``profiles.png`` for its ``steady``
window when both runs carry the two tables (:func:`profile_comparison`, :func:`profile_figure`); the sums over the
bands are the totals of the time series (the run's mass in the slag over the matte density, without reaction; its
merges), which the tests check for both engines.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from settler.output import read_table

from .band_efficiency import merges_between

#: Columns of one run's profile (:func:`band_profile`): name -> (unit, meaning).
PROFILE: dict[str, tuple[str, str]] = {
    "z": ("m", "height of the band's centre above the bottom"),
    "droplet_volume": ("m^3", "droplet volume in the band, mean over the window's profile rows"),
    "merge_rate_under_inlet": ("1/s", "merges in the band under the inlet per second over the window"),
    "merge_rate_elsewhere": ("1/s", "merges in the band outside it per second over the window"),
}
#: Tables a run needs for its profile.
PROFILE_FILES = ("channel_profile.csv", "merges_by_height.csv")
#: Relative tolerance on two runs' band centres.
Z_TOLERANCE = 1e-9


def has_profiles(run) -> bool:
    """Whether the run's folder holds both :data:`PROFILE_FILES`."""
    return all((Path(run.folder) / name).is_file() for name in PROFILE_FILES)


def band_profile(run, window: tuple[float, float]) -> tuple[pd.DataFrame, tuple[float, float]]:
    """The :data:`PROFILE` of ``run`` (an :class:`analysis.runs.Run`) over ``window`` (start, end) [s], and the
    (t0, t1) [s] of the ``merges_by_height`` rows the merge rates are taken between (both inside the window).
    ValueError naming the run and the file when a table is missing or empty, or the window holds no profile row or
    fewer than two merge rows."""
    folder = Path(run.folder)
    missing = [name for name in PROFILE_FILES if not (folder / name).is_file()]
    if missing:
        raise ValueError(f"{folder}: no {', '.join(missing)} (written by both engines since the zone diagnostics; "
                         "an older run lacks them)")
    tables = {name: read_table(folder / name) for name in PROFILE_FILES}
    for name, table in tables.items():
        if table.empty:
            raise ValueError(f"{folder / name}: no rows")
    start, end = window

    def inside(table):
        return table[(table["time"] >= start - 1e-9) & (table["time"] <= end + 1e-9)]

    rows = inside(tables["channel_profile.csv"])
    if rows.empty:
        times = tables["channel_profile.csv"]["time"].to_numpy(dtype=float)
        raise ValueError(f"{folder}: window {start:g}-{end:g} s holds no channel_profile row (rows at "
                         f"{times.min():g}-{times.max():g} s)")
    volume = rows.groupby("z")["droplet_volume"].mean()
    merge_rows = inside(tables["merges_by_height.csv"])
    times = np.unique(merge_rows["time"].to_numpy(dtype=float))
    if len(times) < 2:
        raise ValueError(f"{folder}: window {start:g}-{end:g} s holds {len(times)} merges_by_height row time(s); "
                         "the merge rates need two")
    t0, t1, merges = merges_between(merge_rows, (times[0], times[-1]), where=str(folder))
    merges = merges.set_index("z")
    if len(merges) != len(volume) or not np.allclose(merges.index, volume.index, rtol=Z_TOLERANCE, atol=0.0):
        raise ValueError(f"{folder}: the bands of channel_profile.csv and merges_by_height.csv differ")
    table = pd.DataFrame({"z": volume.index.to_numpy(dtype=float), "droplet_volume": volume.to_numpy(dtype=float),
                          "merge_rate_under_inlet": merges["merges_under_inlet"].to_numpy(dtype=float) / (t1 - t0),
                          "merge_rate_elsewhere": merges["merges_elsewhere"].to_numpy(dtype=float) / (t1 - t0)})
    return table, (t0, t1)


def profile_comparison(full, reduced, window: tuple[float, float]) -> pd.DataFrame:
    """Both runs' :func:`band_profile` side by side (columns ``z`` and ``<column>_full``, ``<column>_reduced``),
    top band first; ``table.attrs["merge_spans"]`` holds each run's (t0, t1) [s]. ValueError when their bands
    differ (different heights or band counts)."""
    a, span_a = band_profile(full, window)
    b, span_b = band_profile(reduced, window)
    if len(a) != len(b) or not np.allclose(a["z"], b["z"], rtol=Z_TOLERANCE, atol=0.0):
        raise ValueError(f"the runs' height bands differ ({len(a)} bands, top band centred at {a['z'].max():.4g} m, "
                         f"against {len(b)} at {b['z'].max():.4g} m): not the same case")
    table = pd.DataFrame({"z": a["z"]})
    for column in list(PROFILE)[1:]:
        table[f"{column}_full"] = a[column].to_numpy()
        table[f"{column}_reduced"] = b[column].to_numpy()
    table = table.sort_values("z", ascending=False).reset_index(drop=True)
    table.attrs["merge_spans"] = {"full": span_a, "reduced": span_b}
    return table


def profile_units() -> dict[str, str]:
    """Column -> unit of :func:`profile_comparison`'s table."""
    units = {"z": PROFILE["z"][0]}
    for column, (unit, _) in list(PROFILE.items())[1:]:
        units.update({f"{column}_full": unit, f"{column}_reduced": unit})
    return units


def profile_summary(table: pd.DataFrame) -> str:
    """A short text table: per band (top first) the droplet volume and the merge rate, reduced over full."""
    def ratio(a, b):
        return f"{a / b:8.2f}" if b > 0 and math.isfinite(a) else "       -"

    lines = ["height profile (reduced / full)      z [mm]  droplet volume   merges/s",]
    for row in table.itertuples(index=False):
        full = row.merge_rate_under_inlet_full + row.merge_rate_elsewhere_full
        reduced = row.merge_rate_under_inlet_reduced + row.merge_rate_elsewhere_reduced
        lines.append(f"{'':36s}{row.z * 1e3:7.1f}  {ratio(row.droplet_volume_reduced, row.droplet_volume_full)}"
                     f"         {ratio(reduced, full)}")
    return "\n".join(lines)


def profile_figure(table: pd.DataFrame, labels=("full", "reduced"), window=None):
    """Two panels against height [mm]: the droplet volume per band [mm^3] and the merges per second per band
    (under the inlet solid, elsewhere dashed), both runs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(9.0, 4.5), sharey=True)
    z = table["z"].to_numpy() * 1e3
    for side, label, colour in (("full", labels[0], "k"), ("reduced", labels[1], "tab:red")):
        left.plot(table[f"droplet_volume_{side}"] * 1e9, z, "o-", color=colour, label=label)
        right.plot(table[f"merge_rate_under_inlet_{side}"], z, "o-", color=colour, label=f"{label}, under the inlet")
        right.plot(table[f"merge_rate_elsewhere_{side}"], z, "s--", color=colour, label=f"{label}, elsewhere")
    left.set_xlabel("droplet volume in the band [mm$^3$]")
    right.set_xlabel("merges per second in the band [1/s]")
    left.set_ylabel("height of the band's centre [mm]")
    for ax in (left, right):
        ax.set_xscale("symlog", linthresh=1.0)
        ax.grid(alpha=0.3)
    left.legend(fontsize=8)
    right.legend(fontsize=8)
    if window is not None:
        fig.suptitle(f"where the droplets are and merge, {window[0]:g}-{window[1]:g} s")
    fig.tight_layout()
    return fig
