"""Whether two full-engine run folders hold the same run bit for bit: every array of their final ``checkpoint.npz``
(droplets, slag velocity and pressure, feed state), every entry of its metadata (time, step count, counters, the
random generators' states, the resolved case; not its wall-clock time) and every value of their CSV outputs except
the wall-clock columns; a CSV output present in one folder only is a difference. This is how an engine change that
must not change results is checked, for example the slot inlet added to the reference set's engine
(data/reference/README.md, "one engine").

    python -m analysis.identity RUN_A RUN_B      # exit 0: identical; 1: what differs, one line each
"""

from __future__ import annotations

import sys
import zipfile
from pathlib import Path

import numpy as np

#: Columns that record the machine's clock, not the run.
CLOCK_COLUMNS = ("wall_time",)
#: The CSV outputs of a full run that are compared (those present in both folders).
CSV_FILES = ("timeseries.csv", "channel_profile.csv", "zone_profile.csv", "zones.csv", "lift_by_size.csv",
             "merges_by_size.csv", "merges_by_height.csv")


def differences(a, b) -> list[str]:
    """What differs between run folders ``a`` and ``b`` (empty: the same run bit for bit), one line per item."""
    import pandas as pd

    a, b = Path(a), Path(b)
    out = []
    with np.load(a / "checkpoint.npz") as ca, np.load(b / "checkpoint.npz") as cb:
        names = sorted((set(ca.files) | set(cb.files)) - {"__meta__"})
        for name in names:
            if name not in ca.files or name not in cb.files:
                out.append(f"checkpoint.npz: {name} only in {'b' if name in cb.files else 'a'}")
            elif not np.array_equal(ca[name], cb[name]):
                out.append(f"checkpoint.npz: {name} differs")
        meta_a, meta_b = (_meta(c) for c in (ca, cb))
        for key in sorted(set(meta_a) | set(meta_b)):
            if key == "counters" and isinstance(meta_a.get(key), dict) and isinstance(meta_b.get(key), dict):
                ka, kb = meta_a[key], meta_b[key]  # entry by entry: a counter added by a newer engine is named
                for name in sorted(set(ka) | set(kb)):
                    if name not in ka or name not in kb:
                        out.append(f"checkpoint.npz: metadata counters.{name} only in {'b' if name in kb else 'a'}")
                    elif ka[name] != kb[name]:
                        out.append(f"checkpoint.npz: metadata counters.{name} differs")
            elif key not in CLOCK_COLUMNS and meta_a.get(key) != meta_b.get(key):
                out.append(f"checkpoint.npz: metadata {key} differs")
    compared = 0
    for file in CSV_FILES:
        if (a / file).exists() != (b / file).exists():
            out.append(f"{file}: only in {'a' if (a / file).exists() else 'b'}")
            continue
        if not (a / file).exists():
            continue
        compared += 1
        ta, tb = pd.read_csv(a / file, comment="#"), pd.read_csv(b / file, comment="#")
        if list(ta.columns) != list(tb.columns) or len(ta) != len(tb):
            out.append(f"{file}: columns or rows differ ({ta.shape} against {tb.shape})")
            continue
        for column in ta.columns:
            if column not in CLOCK_COLUMNS and not ta[column].equals(tb[column]):
                out.append(f"{file}: column {column} differs")
    if compared == 0:
        out.append("no CSV output to compare")
    return out


def _meta(checkpoint) -> dict:
    """The JSON metadata of an open checkpoint (empty without one)."""
    import json

    if "__meta__" not in checkpoint.files:
        return {}
    return json.loads(bytes(checkpoint["__meta__"]).decode())


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python -m analysis.identity RUN_A RUN_B", file=sys.stderr)
        return 2
    try:
        found = differences(*argv)
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        print(f"analysis.identity: {exc}", file=sys.stderr)
        return 2
    for line in found:
        print(line)
    if not found:
        print(f"{argv[0]} and {argv[1]}: the same run bit for bit (checkpoint arrays and metadata, CSV values; "
              "clock excepted)")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
