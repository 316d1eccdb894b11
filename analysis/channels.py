"""How many channels a slab's feed forms: the downflow sheets of a wide slab fed over a slot (issue 21's wide slab,
``geometry.inlet_length``), counted from the vertical slag velocity along x.

Two measures, because a slab's downflow need not be a row of columns. **By the droplets**: at mid-height (the band
of :data:`settler.output.MID_BAND` of the height) the droplet volume is binned along x in cells of the grid, and a
channel is a maximal run of bins holding at least :data:`DROPLET_SHARE` of the fullest bin's volume
(:func:`droplet_runs`): one run is one curtain, however long. **By the slag**: at a height z the slag velocity
w(x) (averaged over the slab's thickness y, or on its central x-z plane where only that is stored) is split into maximal runs of downflow (w < 0) between rising return flow; a **channel** is a run
that carries at least :data:`MIN_SHARE` of the total downflow integral of max(-w, 0) dx at that height, so that a
one-cell flicker of the return flow is not counted. The count at mid-height is the slab's channel count, the measure
of the channel radius and axis velocity of a single plume (:mod:`settler.output`) having no meaning there; the
counts at a quarter and three quarters of the height say whether channels join or split on the way down.

    python -m analysis.channels RUN_OR_REFERENCE [--figure PATH]
                 # a run folder (every slag snapshot) or a stored reference; --figure draws the mid-height slag
                 # velocity along x against time with the channels found, and the counts against time
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

#: Share of a height's total downflow a run of downflow must carry to count as a channel [-] (chosen: drops one-cell
#: flickers, which carry well under 1 %, and keeps any sheet that carries a twentieth of the downflow).
MIN_SHARE = 0.05
#: Heights at which channels are counted, as fractions of the slag height [-].
HEIGHTS = (0.25, 0.5, 0.75)
#: Share of the fullest x bin's droplet volume a bin must hold to belong to a channel [-] (chosen: a curtain's own
#: bins hold 0.7-1 of the fullest in the stored slab, the return flow beside it under 0.15).
DROPLET_SHARE = 0.25


def droplet_runs(x, volume, lower: float, upper: float, bin_width: float,
                 share: float = DROPLET_SHARE) -> list[tuple[float, float]]:
    """The channels of a band of droplets by where their volume lies along x: droplet centres ``x`` [m] and volumes
    ``volume`` [m^3] binned over [lower, upper] [m] in bins ``bin_width`` [m] wide; each maximal run of bins holding
    at least ``share`` of the fullest bin and, together, at least :data:`MIN_SHARE` of the band's volume is one
    channel (a bin or two of droplets gathered against an end wall is not), returned as its (start, end) [m] (bin
    edges)."""
    x, volume = np.asarray(x, dtype=float), np.asarray(volume, dtype=float)
    bins = max(1, int(round((upper - lower) / bin_width)))
    held, edges = np.histogram(x, bins=bins, range=(lower, upper), weights=volume)
    if held.max() <= 0.0:
        return []
    full = held >= share * held.max()
    runs, k = [], 0
    while k < bins:
        if full[k]:
            j = k
            while j + 1 < bins and full[j + 1]:
                j += 1
            if held[k:j + 1].sum() >= MIN_SHARE * held.sum():
                runs.append((float(edges[k]), float(edges[j + 1])))
            k = j + 1
        else:
            k += 1
    return runs


def droplet_channels(frame, case) -> list[tuple[float, float]]:
    """:func:`droplet_runs` of a snapshot's droplets (a DataFrame with x, z, diameter [m]) in the mid-height band of
    ``case``'s box, binned at its cell size."""
    from settler.output import MID_BAND

    height = case.geometry.height
    z = np.asarray(frame["z"], dtype=float)
    band = np.abs(z - 0.5 * height) <= 0.5 * MID_BAND * height
    volume = np.pi / 6.0 * np.asarray(frame["diameter"], dtype=float) ** 3
    return droplet_runs(np.asarray(frame["x"], dtype=float)[band], volume[band], 0.0, case.geometry.width,
                        case.fulldem.cell_size)


def downflow_runs(x, w, min_share: float = MIN_SHARE) -> list[dict]:
    """The channels of one height: ``x`` (n,) [m] cell centres in increasing order, ``w`` (n,) [m/s] the vertical
    slag velocity there. Each channel a dict: ``start``, ``end`` [m] (outer cell centres), ``centre`` [m] (the
    downflow-weighted mean x), ``share`` [-] of the height's downflow, ``peak`` [m/s] the largest downward speed."""
    x, w = np.asarray(x, dtype=float), np.asarray(w, dtype=float)
    if x.shape != w.shape or x.ndim != 1:
        raise ValueError(f"x and w must be 1-D arrays of one length, got shapes {x.shape} and {w.shape}")
    down = np.maximum(-w, 0.0)
    total = float(down.sum())
    if total <= 0.0:
        return []
    runs, k, n = [], 0, len(x)
    while k < n:
        if down[k] > 0.0:
            j = k
            while j + 1 < n and down[j + 1] > 0.0:
                j += 1
            part = down[k:j + 1]
            share = float(part.sum()) / total
            if share >= min_share:
                runs.append({"start": float(x[k]), "end": float(x[j]),
                             "centre": float((x[k:j + 1] * part).sum() / part.sum()), "share": share,
                             "peak": float(part.max())})
            k = j + 1
        else:
            k += 1
    return runs


def profile_at(x, z, w, height: float) -> tuple[np.ndarray, np.ndarray]:
    """w(x) on the cell layer nearest to ``height`` [m] above the bottom, from cell centres ``x``, ``z`` [m] and
    velocities ``w`` [m/s] of one x-z plane (or of several y layers, which are averaged): (x sorted, mean w)."""
    x, z, w = (np.asarray(a, dtype=float).ravel() for a in (x, z, w))
    levels = np.unique(np.round(z, 12))
    nearest = levels[np.argmin(np.abs(levels - height))]
    layer = np.abs(z - nearest) <= 1e-9 * max(1.0, abs(nearest))
    xs, inverse = np.unique(np.round(x[layer], 12), return_inverse=True)
    mean = np.bincount(inverse, weights=w[layer]) / np.bincount(inverse)
    return xs, mean


def count_channels(x, z, w, slag_height: float, bottom: float = 0.0) -> dict:
    """Channels at each of :data:`HEIGHTS` of a slab: ``{fraction: [channel dicts]}`` (see :func:`downflow_runs`)
    from cell centres ``x``, ``z`` [m] and vertical velocities ``w`` [m/s]; ``bottom`` [m] is z of the floor."""
    return {f: downflow_runs(*profile_at(x, z, w, bottom + f * slag_height)) for f in HEIGHTS}


def run_counts(folder) -> list[dict]:
    """Channel counts of every slag snapshot of a run folder (the whole field averaged over y) or of the stored
    snapshots of a reference (its central x-z plane): rows of ``time`` [s], ``n_25``, ``n_50``, ``n_75`` (counts at a
    quarter, half and three quarters of the height, by the slag), ``centres_50`` (those channels' centres at
    mid-height [m]), ``droplet_channels`` and ``extents`` (the channels by the droplets at mid-height, each (start,
    end) [m])."""
    folder = Path(folder)
    rows = []
    if (folder / "reference.json").is_file():
        from .reference import load_reference

        ref = load_reference(folder.name, folder.parent)
        height = ref.case.geometry.height
        for k, t in enumerate(ref.snapshot_times):
            try:
                x, z, v = ref.slag(k)
            except LookupError:
                continue
            rows.append(_row(float(t), count_channels(x, z, v[:, 2], height),
                             droplet_channels(ref.droplets(k), ref.case)))
        return rows
    from settler.cases import load_case

    from .files import droplets_file, slag_file, snapshot_files

    case = load_case(folder / "case.toml")
    for t, drops, fluid in snapshot_files(folder):
        if fluid is None or drops is None:
            continue
        centres, velocity = slag_file(fluid)
        rows.append(_row(float(t), count_channels(centres[:, 0], centres[:, 2], velocity[:, 2], case.geometry.height),
                         droplet_channels(droplets_file(drops), case)))
    return rows


def mid_height_history(folder) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times (T,) [s], x (X,) [m], w (T, X) [m/s]): the thickness-averaged vertical slag velocity at mid-height of
    every slag snapshot of a run folder."""
    from settler.cases import load_case

    from .files import slag_file, snapshot_files

    folder = Path(folder)
    height = load_case(folder / "case.toml").geometry.height
    times, rows, xs = [], [], None
    for t, _, fluid in snapshot_files(folder):
        if fluid is None:
            continue
        centres, velocity = slag_file(fluid)
        x, w = profile_at(centres[:, 0], centres[:, 2], velocity[:, 2], 0.5 * height)
        xs = x if xs is None else xs
        times.append(float(t))
        rows.append(w)
    return np.array(times), (xs if xs is not None else np.zeros(0)), np.array(rows)


def draw(folder, path) -> None:
    """Two panels: the mid-height slag velocity along x against time (downflow red) with each snapshot's channel
    centres, and the channel counts at a quarter, half and three quarters of the height against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    times, x, w = mid_height_history(folder)
    rows = run_counts(folder)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 6.0), sharex=True, height_ratios=(3, 1.4),
                                      constrained_layout=True)
    limit = float(np.nanmax(np.abs(w))) if w.size else 1.0
    image = top.pcolormesh(times, 1e3 * x, 1e3 * w.T, cmap="RdBu", vmin=-1e3 * limit, vmax=1e3 * limit,
                           shading="nearest")
    for r in rows:
        top.plot([r["time"]] * len(r["centres_50"]), [1e3 * c for c in r["centres_50"]], "k.", ms=4)
        for a, b in r["extents"]:
            top.plot([r["time"], r["time"]], [1e3 * a, 1e3 * b], "-", color="0.25", lw=1.5, alpha=0.6)
    top.set_ylabel("x [mm]")
    top.set_title("slag velocity at mid-height, averaged over the slab's thickness\n(dots: downflow channels; bars: "
                  "where the droplets are)", fontsize=10)
    fig.colorbar(image, ax=top, label="w [mm/s] (negative: down)")
    for key, label, style in (("droplet_channels", "by the droplets, mid-height", "-k"),
                              ("n_25", "downflow, 1/4 of the height", ":"), ("n_50", "downflow, mid-height", "-"),
                              ("n_75", "downflow, 3/4 of the height", "--")):
        bottom.plot([r["time"] for r in rows], [r[key] for r in rows], style, label=label, drawstyle="steps-mid")
    bottom.set_xlabel("time [s]")
    bottom.set_ylabel("channels")
    bottom.legend(fontsize=7, ncols=2)
    import io

    from settler.output import atomic_write_bytes

    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=110, format=Path(path).suffix.lstrip(".") or "png")
    plt.close(fig)
    atomic_write_bytes(path, buffer.getvalue())


def _row(time, counts, by_droplets) -> dict:
    return {"time": time, "droplet_channels": len(by_droplets), "extents": by_droplets,
            **{f"n_{int(round(100 * f))}": len(c) for f, c in counts.items()},
            "centres_50": [round(c["centre"], 4) for c in counts[0.5]]}


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m analysis.channels", description="count a slab's channels")
    parser.add_argument("run", help="a run folder or a stored reference")
    parser.add_argument("--figure", default=None, metavar="PATH", help="draw the channels against time (a run folder)")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    if args.figure and (Path(args.run) / "reference.json").is_file():
        print(f"analysis.channels: --figure draws a run folder's snapshots over time; {args.run} is a stored "
              "reference, which keeps one or two (give the run folder it was stored from)", file=sys.stderr)
        return 2
    try:
        rows = run_counts(args.run)
        if rows and args.figure:
            draw(args.run, args.figure)
    except (OSError, ValueError, LookupError) as exc:
        print(f"analysis.channels: {exc}", file=sys.stderr)
        return 2
    if not rows:
        print(f"analysis.channels: {args.run} holds no slag snapshot", file=sys.stderr)
        return 2
    print("time [s]  by the droplets at mid-height: count (x extents [mm])  |  by the slag's downflow: count at 1/4, "
          "1/2, 3/4 of the height (centres at mid-height [mm])")
    for r in rows:
        extents = ", ".join(f"{1e3 * a:.0f}-{1e3 * b:.0f}" for a, b in r["extents"])
        centres = ", ".join(f"{1e3 * c:.0f}" for c in r["centres_50"])
        print(f"{r['time']:8.2f}  {r['droplet_channels']:3d} ({extents})  |  {r['n_25']} {r['n_50']} {r['n_75']} "
              f"({centres})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
