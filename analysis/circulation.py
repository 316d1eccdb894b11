"""The return flow's circulation in a full run: where the plume takes slag in and gives it back, and where droplets
pass between the sinking and the rising slag.

A full run's plume sinks in the middle of a closed box, so the same slag rises around it (the return flow). Through a
horizontal cell layer at height z the slag sinks at the volume rate

    Q_down(z) = - sum over the layer's cells with w < 0 of w dx dy   [m^3/s]

(the time mean over the window's slag snapshots; :func:`downflux_profile`). Where Q_down grows downward the plume
entrains the return flow's slag, where it shrinks it gives slag back to it (detrains), and continuity makes the
return flow's upward rate at z the same Q_down(z) (no slag feed) or about it.

The droplets are put each snapshot in one of four regions (:data:`REGIONS`): the ``roof`` (the top tenth of the
height), the ``floor`` (the bottom tenth), and in between ``up`` or ``down`` by the sign of the slag's vertical
velocity in the droplet's cell. Followed by ident from a snapshot to the one ``lag`` snapshots later,
:func:`region_flows` counts the droplets per second that pass from each region to each other or are gone (merged
into another droplet, or settled out), and the heights, in tenths of the box, at which droplets pass between
``up`` and ``down`` and from the floor into ``up`` (the mean of the two heights). The lag tells a passage from the
flicker of droplets that sit on the boundary between rising and sinking cells: a real passage gives the same rate
per second at any lag, flicker less and less at longer lags.

Command line::

    python -m analysis.circulation RUN [--window START:END] [--lag N]

RUN is a full run folder whose snapshots keep the slag grid and the droplets' idents (``settler full``'s own
folder; a stored reference keeps too little).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

#: The droplet regions, in the order of :func:`region_flows`'s tables ("gone" is the fifth destination).
REGIONS = ("roof", "floor", "up", "down")
#: The share of the height at the top (roof) and at the bottom (floor) that is not the mid-column [-].
LAYER_SHARE = 0.1
#: The height bands of the passage tables: tenths of the box height.
BANDS = 10


def _slag_grid(run, time):
    """(x, y, z cell-centre axes [m], vertical slag velocity (nx, ny, nz) [m/s]) of the snapshot at ``time``."""
    from .files import slag_grid

    _, centres, velocity = run.slag(time)
    try:
        axes, grid = slag_grid(centres, velocity)
    except ValueError as exc:
        raise ValueError(f"the slag snapshot at t = {time:g} s: {exc}") from None
    return axes, grid[..., 2]


def downflux_profile(run, times) -> pd.DataFrame:
    """Per cell layer, bottom to top: ``z`` [m] (the layer's centre), ``downflux`` Q_down [m^3/s] and
    ``sinking_share`` (the share of the layer's cells where the slag sinks) [-], time means over the slag snapshots
    at ``times`` [s]."""
    total = share = None
    for time in times:
        (xs, ys, zs), w = _slag_grid(run, time)
        area = (xs[1] - xs[0]) * (ys[1] - ys[0])
        q = -np.where(w < 0.0, w, 0.0).sum(axis=(0, 1)) * area
        s = (w < 0.0).mean(axis=(0, 1))
        total, share = (q, s) if total is None else (total + q, share + s)
    if total is None:
        raise ValueError("no slag snapshot in the window")
    return pd.DataFrame({"z": zs, "downflux": total / len(times), "sinking_share": share / len(times)})


def droplet_regions(run, time) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(ident, region index into :data:`REGIONS`, diameter [m], z [m]) of every droplet of the snapshot at
    ``time`` [s]. ValueError where its droplets carry no idents."""
    (xs, ys, zs), w = _slag_grid(run, time)
    _, d = run.droplets(time)
    if "ident" not in d:
        raise ValueError(f"the droplet snapshot at t = {time:g} s carries no idents")
    index = [np.clip(np.floor((np.asarray(d[key]) - axis[0]) / (axis[1] - axis[0]) + 0.5).astype(int), 0,
                     len(axis) - 1) for key, axis in (("x", xs), ("y", ys), ("z", zs))]
    rising = w[index[0], index[1], index[2]] > 0.0
    height = run.case.geometry.height
    z = np.asarray(d["z"], dtype=float)
    region = np.where(rising, REGIONS.index("up"), REGIONS.index("down"))
    region[z >= (1.0 - LAYER_SHARE) * height] = REGIONS.index("roof")
    region[z < LAYER_SHARE * height] = REGIONS.index("floor")
    return np.asarray(d["ident"]).astype(np.int64), region, np.asarray(d["diameter"], dtype=float), z


#: The passages whose heights :func:`region_flows` tables.
PASSAGES = (("up", "down"), ("down", "up"), ("floor", "up"))


def region_flows(run, times, lag: int = 1) -> tuple[pd.DataFrame, dict, pd.DataFrame]:
    """(flows, occupancy, heights) of the droplets followed by ident from each snapshot at ``times`` [s] to the one
    ``lag`` snapshots later: ``flows`` one row per (source, destination) of :data:`REGIONS` and "gone", with
    ``rate`` [1/s] and ``mean_diameter`` [m] (at the source); ``occupancy`` region -> the mean number of droplets
    there [-]; ``heights`` one row per height band (tenths of the box, ``z_low``, ``z_high`` [m]) with a column of
    rates [1/s] per passage of :data:`PASSAGES` ("up->down" ...), placed at the mean of the two heights."""
    if lag < 1 or len(times) <= lag:
        raise ValueError(f"lag {lag}: needs at least lag + 1 = {lag + 1} snapshots in the window, there are "
                         f"{len(times)}")
    height = run.case.geometry.height
    frames = {t: droplet_regions(run, t) for t in times}
    n_regions = len(REGIONS)
    count = np.zeros((n_regions, n_regions + 1))
    diameter = np.zeros_like(count)
    occupancy = np.zeros(n_regions)
    passages = {p: np.zeros(BANDS) for p in PASSAGES}
    span = 0.0
    for first, later in zip(times[:-lag], times[lag:]):
        ident_a, region_a, diameter_a, z_a = frames[first]
        ident_b, region_b, _, z_b = frames[later]
        span += later - first
        occupancy += np.bincount(region_a, minlength=n_regions) * (later - first)
        order = np.argsort(ident_b)
        where = np.searchsorted(ident_b[order], ident_a)
        found = np.zeros(len(ident_a), dtype=bool)
        if len(ident_b):
            found = (where < len(ident_b)) & (ident_b[order][np.minimum(where, len(ident_b) - 1)] == ident_a)
        to = np.full(len(ident_a), n_regions)
        at = order[where[found]]
        to[found] = region_b[at]
        np.add.at(count, (region_a, to), 1.0)
        np.add.at(diameter, (region_a, to), diameter_a)
        mid = np.full(len(ident_a), np.nan)
        mid[found] = 0.5 * (z_a[found] + z_b[at])
        band = np.clip(np.floor(np.nan_to_num(mid) / height * BANDS).astype(int), 0, BANDS - 1)
        for source, dest in PASSAGES:
            chosen = found & (region_a == REGIONS.index(source)) & (to == REGIONS.index(dest))
            passages[(source, dest)] += np.bincount(band[chosen], minlength=BANDS)
    destinations = REGIONS + ("gone",)
    rows = [{"source": REGIONS[a], "destination": destinations[b], "rate": count[a, b] / span,
             "mean_diameter": diameter[a, b] / count[a, b] if count[a, b] else math.nan}
            for a in range(n_regions) for b in range(n_regions + 1)]
    edges = np.linspace(0.0, height, BANDS + 1)
    heights = pd.DataFrame({"z_low": edges[:-1], "z_high": edges[1:],
                            **{f"{s}->{d}": v / span for (s, d), v in passages.items()}})
    return pd.DataFrame(rows), {r: float(o / span) for r, o in zip(REGIONS, occupancy)}, heights


def measure_circulation(run, window: tuple[float, float] | None = None, lag: int = 1) -> dict:
    """Everything the module measures on a full run folder or :class:`analysis.Run` over ``window`` (default: its
    steady window, else its last third): {"window", "snapshots", "downflux" (:func:`downflux_profile`), "flows",
    "occupancy", "heights" (:func:`region_flows`)}."""
    from .runs import load_run
    from .steady import window_snapshots

    run = run if hasattr(run, "timeseries") else load_run(run)
    window, times = window_snapshots(run, window)
    flows, occupancy, heights = region_flows(run, times, lag)
    return {"window": window, "snapshots": times, "downflux": downflux_profile(run, times), "flows": flows,
            "occupancy": occupancy, "heights": heights, "lag": lag}


def report(result) -> str:
    """The tables of :func:`measure_circulation` as text (mm, cm^3/s, droplets per second)."""
    lines = [f"window {result['window'][0]:g}-{result['window'][1]:g} s, {len(result['snapshots'])} snapshots, "
             f"droplets followed over {result['lag']} snapshot(s)"]
    profile = result["downflux"]
    lines.append("slag sinking through each cell layer, top to bottom: z [mm], Q_down [cm^3/s], sinking share")
    lines += [f"  {z * 1e3:7.2f} {q * 1e6:9.3f} {s:6.3f}" for z, q, s in
              zip(profile.z[::-1], profile.downflux[::-1], profile.sinking_share[::-1])]
    lines.append("mean droplets per region: " + ", ".join(f"{r} {n:.0f}" for r, n in result["occupancy"].items()))
    flows = result["flows"]
    destinations = list(dict.fromkeys(flows.destination))
    lines.append("droplets per second from (row) to (column), mean diameter [mm] in brackets:")
    lines.append(" " * 8 + "".join(f"{d:>18s}" for d in destinations))
    for source in REGIONS:
        row = flows[flows.source == source].set_index("destination")
        lines.append(f"{source:>8s}" + "".join(
            f"{row.rate[d]:10.1f} ({row.mean_diameter[d] * 1e3:4.2f})" if row.rate[d] else f"{0.0:10.1f}" + " " * 7
            for d in destinations))
    heights = result["heights"]
    lines.append("passages per second by height band, top to bottom: z [mm] " + " ".join(heights.columns[2:]))
    for _, band in heights[::-1].iterrows():
        lines.append(f"  {band.z_low * 1e3:5.0f}-{band.z_high * 1e3:5.0f} "
                     + " ".join(f"{band[c]:9.1f}" for c in heights.columns[2:]))
    return "\n".join(lines)


def main(argv=None) -> int:
    import argparse
    import sys

    from settler.errors import OutputError

    from .files import NoData
    from .steady import parse_window

    parser = argparse.ArgumentParser(prog="python -m analysis.circulation",
                                     description="the return flow's circulation in a full run: the slag the plume "
                                                 "entrains and detrains by height, and the droplets passing "
                                                 "between sinking and rising slag")
    parser.add_argument("run", help="a full run folder (its slag grid and droplet idents at each snapshot)")
    parser.add_argument("--window", help="START:END [s]; default the run's steady window, else its last third")
    parser.add_argument("--lag", type=int, default=1,
                        help="follow each droplet to the snapshot this many snapshots later (default: 1)")
    args = parser.parse_args(argv)
    try:
        window = parse_window(args.window) if args.window else None
    except ValueError as exc:
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    try:
        result = measure_circulation(args.run, window, args.lag)
    except (ValueError, NoData, OutputError) as exc:
        print(f"{parser.prog}: error: {args.run}: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    print(report(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
