"""How many channels a slab's feed forms: the downflow sheets of a wide slab fed over a slot (issue 21's wide slab,
``geometry.inlet_length``), counted from the vertical slag velocity along x.

At a height z the slag velocity w(x) (averaged over the slab's thickness y, or on its central x-z plane where only
that is stored) is split into maximal runs of downflow (w < 0) between rising return flow; a **channel** is a run
that carries at least :data:`MIN_SHARE` of the total downflow integral of max(-w, 0) dx at that height, so that a
one-cell flicker of the return flow is not counted. The count at mid-height is the slab's channel count, the measure
of the channel radius and axis velocity of a single plume (:mod:`settler.output`) having no meaning there; the
counts at a quarter and three quarters of the height say whether channels join or split on the way down.

    python -m analysis.channels RUN_OR_REFERENCE     # a run folder (every slag snapshot) or a stored reference
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
    quarter, half and three quarters of the height) and ``centres_50`` (channel centres at mid-height [m])."""
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
            rows.append(_row(float(t), count_channels(x, z, v[:, 2], height)))
        return rows
    from settler.cases import load_case

    from .files import slag_file, snapshot_files

    height = load_case(folder / "case.toml").geometry.height
    for t, _, fluid in snapshot_files(folder):
        if fluid is None:
            continue
        centres, velocity = slag_file(fluid)
        rows.append(_row(float(t), count_channels(centres[:, 0], centres[:, 2], velocity[:, 2], height)))
    return rows


def _row(time, counts) -> dict:
    return {"time": time, **{f"n_{int(round(100 * f))}": len(c) for f, c in counts.items()},
            "centres_50": [round(c["centre"], 4) for c in counts[0.5]]}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m analysis.channels RUN_OR_REFERENCE", file=sys.stderr)
        return 2
    try:
        rows = run_counts(argv[0])
    except (OSError, ValueError, LookupError) as exc:
        print(f"analysis.channels: {exc}", file=sys.stderr)
        return 2
    if not rows:
        print(f"analysis.channels: {argv[0]} holds no slag snapshot", file=sys.stderr)
        return 2
    print("time [s]  channels at 1/4, 1/2, 3/4 of the height   centres at mid-height [mm]")
    for r in rows:
        centres = ", ".join(f"{1e3 * c:.0f}" for c in r["centres_50"])
        print(f"{r['time']:8.2f}  {r['n_25']:3d} {r['n_50']:3d} {r['n_75']:3d}   {centres}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
