"""Strict reader for the initial-droplet list of ``settler full CASE --droplets FILE``.

The file is a UTF-8 CSV (comma-separated) with a header line naming its columns, in any order, from
:data:`COLUMNS` (SI units): ``x``, ``y``, ``z`` [m] the droplet centre, ``diameter`` [m] and, optionally,
``density`` [kg/m^3] (the case's matte density when absent). Lines whose first non-blank character is ``#`` are
comments, a ``#`` later in a line starts a trailing comment, and blank lines are skipped. Example::

    # two droplets of 1 mm
    x,y,z,diameter,density
    0.010,0.010,0.020,0.001,5200
    0.012,0.010,0.020,0.001,5200

:func:`read_droplet_list` refuses anything the engine could not start from with a :class:`DropletListError`: one
line naming the file, the data row (1-based, comments and the header not counted) with its line number in the
file, the column, the value and what is allowed.
"""

from __future__ import annotations

import difflib
import math
import re
from pathlib import Path

import numpy as np

from ..dem.diagnostics import near_pairs
from ..droplets import DropletStore


#: Required columns and their units.
REQUIRED_COLUMNS = {"x": "m", "y": "m", "z": "m", "diameter": "m"}
#: Optional columns and their units (density: the case's matte density where absent).
OPTIONAL_COLUMNS = {"density": "kg/m^3"}
#: Every allowed column and its unit, required ones first.
COLUMNS = {**REQUIRED_COLUMNS, **OPTIONAL_COLUMNS}

_NUMBER = r"[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)"
_NUMBER_RE = re.compile(_NUMBER, re.IGNORECASE)
_BLANK = "[ \t]*"


class DropletListError(ValueError):
    """A droplet list the engine cannot start from. ``str()`` is one line naming the file, the data row (1-based)
    and its line in the file, the column, the value and what is allowed; the parts are also attributes (None
    where they do not apply)."""

    def __init__(self, path, problem, *, row=None, line=None, column=None, value=None):
        self.path, self.problem = str(path), problem
        self.row, self.line, self.column, self.value = row, line, column, value
        where = []
        if row is not None:
            where.append(f"data row {row}" + (f" (line {line})" if line is not None else ""))
        elif line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column '{column}'")
        text = f"droplet list {self.path}: " + (", ".join(where) + ": " if where else "") + problem
        super().__init__(" ".join(text.split()))  # one line, whatever the file's names and values hold


def _allowed_columns() -> str:
    req = ", ".join(f"{c} [{u}]" for c, u in REQUIRED_COLUMNS.items())
    opt = ", ".join(f"{c} [{u}]" for c, u in OPTIONAL_COLUMNS.items())
    return f"required {req}; optional {opt}"


def _fmt(v) -> str:
    return f"{float(v):.9g}"


def _vec(v) -> str:
    return "(" + ", ".join(_fmt(a) for a in v) + ")"


def _more(n_bad: int, what: str) -> str:
    if n_bad <= 1:
        return ""
    return f" ({n_bad - 1} more {what if n_bad > 2 else what.rstrip('s')} like it)"


def _read_text(path: Path) -> str:
    if not path.exists():
        raise DropletListError(path, "no such file")
    if path.is_dir():
        raise DropletListError(path, "is a folder, not a CSV file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise DropletListError(path, f"cannot be read ({exc.strerror or exc})") from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise DropletListError(path, f"is not UTF-8 text (byte {data[exc.start:exc.start + 1]!r} at offset "
                                     f"{exc.start}); save it as UTF-8 CSV", line=line) from None


def _parse_header(path: Path, text: str, line: int) -> list[str]:
    names = [c.strip() for c in text.split(",")]
    allowed = f"allowed columns: {_allowed_columns()}"
    if all(_NUMBER_RE.fullmatch(n) for n in names):
        raise DropletListError(path, f"the first line {text.strip()!r} looks like data; a header line naming the "
                                     f"columns is required ({allowed})", line=line)
    for k, name in enumerate(names):
        if name == "":
            raise DropletListError(path, f"header column {k + 1} has no name (a stray comma?); {allowed}",
                                   line=line)
        if name not in COLUMNS:
            close = difflib.get_close_matches(name.lower(), list(COLUMNS), n=1, cutoff=0.6)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            sep = " (columns are separated by commas)" if any(s in name for s in ";\t ") else ""
            raise DropletListError(path, f"unknown column {name!r} in the header{sep}{hint}; {allowed}",
                                   line=line, column=name)
        if names.index(name) != k:
            raise DropletListError(path, f"column {name!r} appears twice in the header", line=line, column=name)
    missing = [c for c in REQUIRED_COLUMNS if c not in names]
    if missing:
        raise DropletListError(path, f"missing required column(s) {', '.join(missing)} in the header "
                                     f"{text.strip()!r}; {allowed}", line=line)
    return names


def _bad_cell(path: Path, text: str, names: list[str], row: int, line: int):
    """The error for a data line that failed the fast whole-line check."""
    cells = text.split(",")
    if len(cells) != len(names):
        raise DropletListError(path, f"has {len(cells)} values, the header names {len(names)} columns "
                                     f"({','.join(names)})", row=row, line=line)
    for name, cell in zip(names, cells):
        if not _NUMBER_RE.fullmatch(cell.strip()):
            shown = repr(cell.strip()) if cell.strip() else "an empty cell"
            raise DropletListError(path, f"{shown} is not a number; allowed: a decimal number in "
                                         f"{COLUMNS[name]}", row=row, line=line, column=name, value=cell.strip())
    raise DropletListError(path, "cannot be read as numbers", row=row, line=line)  # not reached


def read_droplet_list(path, *, lower, upper, slag_density, default_density, overlap_limit) -> DropletStore:
    """Droplets from a CSV list (see the module docstring) -> :class:`~fulldem.droplets.DropletStore`.

    lower, upper: corners of the box [m] (3,) whose walls and floor (z = lower[2]) bound every droplet's sphere;
    slag_density [kg/m^3]: every droplet density must exceed it (lighter ones would not settle);
    default_density [kg/m^3]: density of every droplet when the file has no density column;
    overlap_limit [-]: two droplets may overlap, (d_i + d_j)/2 - distance, by at most this fraction of the
    smaller diameter (0: no overlap at all); two at the same centre are always refused.

    A file with a header line and no data rows is valid and gives a store with zero droplets. Refuses, with a
    one-line :class:`DropletListError`: a missing path, a folder, text that is not UTF-8, an empty file (no
    header), a header naming an unknown, repeated or empty column or lacking a required one, a data row with the
    wrong number of values, a cell that is not a number or is NaN/inf, a diameter <= 0 or larger than the box's
    smallest edge, a density not above slag_density, a sphere not fully inside the box, and two droplets that
    overlap too much or share a centre. Positions, diameters and densities are stored exactly as read.
    """
    path = Path(path)
    lower = np.asarray(lower, dtype=float).reshape(3)
    upper = np.asarray(upper, dtype=float).reshape(3)
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(upper > lower)):
        raise ValueError(f"read_droplet_list: box lower {lower} / upper {upper} is not a box")
    if not (math.isfinite(overlap_limit) and overlap_limit >= 0):
        raise ValueError(f"read_droplet_list: overlap_limit = {overlap_limit} must be finite and >= 0")
    text = _read_text(path)

    # header: the first line that is neither blank nor a comment; then the data lines, with their line numbers
    names, data, data_lines = None, [], []
    for number, raw in enumerate(text.splitlines(), start=1):
        body = raw.split("#", 1)[0]
        if not body.strip():
            continue
        if names is None:
            names = _parse_header(path, body, number)
        else:
            data.append(body)
            data_lines.append(number)
    if names is None:
        raise DropletListError(path, "is empty: a header line is required, e.g. 'x,y,z,diameter,density' "
                                     f"(allowed columns: {_allowed_columns()})")

    # cells: a fast whole-line check, then the first bad line cell by cell
    ncol = len(names)
    line_re = re.compile(_BLANK + _NUMBER + (f"(?:{_BLANK},{_BLANK}{_NUMBER})" + "{%d}" % (ncol - 1)) + _BLANK,
                         re.IGNORECASE)
    for k, body in enumerate(data):
        if not line_re.fullmatch(body):
            _bad_cell(path, body, names, k + 1, data_lines[k])
    n = len(data)
    values = np.array(",".join(data).split(","), dtype=float).reshape(n, ncol) if n else np.zeros((0, ncol))
    col = {name: values[:, k] for k, name in enumerate(names)}
    lines = np.asarray(data_lines, dtype=np.int64)

    def fail(k, problem, column=None, value=None, n_bad=1, what="rows"):
        raise DropletListError(path, problem + _more(n_bad, what), row=int(k) + 1, line=int(lines[k]),
                               column=column, value=value)

    density_rule = f"a finite number > slag density {_fmt(slag_density)} kg/m^3 (lighter droplets do not settle)"
    for name in names:
        bad = np.flatnonzero(~np.isfinite(col[name]))
        if bad.size:
            k = bad[0]
            allowed = density_rule if name == "density" else f"a finite number in {COLUMNS[name]}"
            fail(k, f"value {_fmt(col[name][k])} is not allowed; allowed: {allowed}", name, col[name][k], bad.size)

    d = col["diameter"]
    bad = np.flatnonzero(d <= 0)
    if bad.size:
        fail(bad[0], f"diameter {_fmt(d[bad[0]])} m is not allowed; allowed: diameter > 0 m", "diameter",
             d[bad[0]], bad.size)
    edges = upper - lower
    bad = np.flatnonzero(d > edges.min())
    if bad.size:
        k = bad[0]
        fail(k, f"diameter {_fmt(d[k])} m is larger than the box's smallest edge {_fmt(edges.min())} m (box "
                f"{_vec(lower)} to {_vec(upper)} m); allowed: 0 < diameter <= {_fmt(edges.min())} m", "diameter",
             d[k], bad.size)

    if "density" in col:
        density = col["density"]
        bad = np.flatnonzero(density <= slag_density)
        if bad.size:
            k = bad[0]
            fail(k, f"density {_fmt(density[k])} kg/m^3 is not allowed; allowed: {density_rule}", "density",
                 density[k], bad.size)
    else:
        if not (math.isfinite(default_density) and default_density > slag_density):
            raise DropletListError(path, f"has no density column and the default (matte) density "
                                         f"{_fmt(default_density)} kg/m^3 is not allowed; allowed: {density_rule}")
        density = np.full(n, float(default_density))

    pos = np.column_stack([col["x"], col["y"], col["z"]])
    r = 0.5 * d
    below = pos - r[:, None] < lower
    above = pos + r[:, None] > upper
    outside = below | above
    bad = np.flatnonzero(outside.any(axis=1))
    if bad.size:
        k = bad[0]
        axis = int(np.flatnonzero(outside[k])[0])
        name = "xyz"[axis]
        if below[k, axis]:
            wall = "the floor" if axis == 2 else f"the wall {name} = {_fmt(lower[axis])} m"
            reach = f"{name} - d/2 = {_fmt(pos[k, axis] - r[k])} m < {_fmt(lower[axis])} m"
        else:
            wall = "the top" if axis == 2 else f"the wall {name} = {_fmt(upper[axis])} m"
            reach = f"{name} + d/2 = {_fmt(pos[k, axis] + r[k])} m > {_fmt(upper[axis])} m"
        centre = "its centre is outside" if not (lower[axis] <= pos[k, axis] <= upper[axis]) else "it reaches"
        fail(k, f"droplet at {_vec(pos[k])} m of diameter {_fmt(d[k])} m is not inside the box {_vec(lower)} to "
                f"{_vec(upper)} m: {centre} {wall} ({reach}); allowed: the whole sphere inside the box", name,
             pos[k, axis], bad.size, "droplets")

    if n > 1:
        i, j, dist, overlap = near_pairs(pos, d)
        if len(i):
            too_much = (overlap > overlap_limit * np.minimum(d[i], d[j])) | (dist == 0.0)
            if too_much.any():
                i, j, dist, overlap = i[too_much], j[too_much], dist[too_much], overlap[too_much]
                order = np.lexsort((np.maximum(i, j), np.minimum(i, j)))
                a, b = int(min(i[order[0]], j[order[0]])), int(max(i[order[0]], j[order[0]]))
                others = _more(int(too_much.sum()), "pairs")
                if dist[order[0]] == 0.0:
                    problem = (f"droplets at data rows {a + 1} (line {lines[a]}) and {b + 1} (line {lines[b]}) "
                               f"have the same centre {_vec(pos[a])} m{others}; allowed: distinct centres "
                               f"(contacts cannot separate coincident droplets)")
                else:
                    dmin = min(d[a], d[b])
                    problem = (f"droplets at data rows {a + 1} (line {lines[a]}) and {b + 1} (line {lines[b]}) "
                               f"overlap by {_fmt(overlap[order[0]])} m = {_fmt(overlap[order[0]] / dmin)} of the "
                               f"smaller diameter (centres {_vec(pos[a])} and {_vec(pos[b])} m, diameters "
                               f"{_fmt(d[a])} and {_fmt(d[b])} m){others}; allowed: overlap <= "
                               f"{_fmt(overlap_limit)} x the smaller diameter")
                err = DropletListError(path, problem)  # the message names both rows; the attributes the first
                err.row, err.line = a + 1, int(lines[a])
                raise err

    store = DropletStore(max(1024, 2 * n))
    if n:
        store.add(pos, d, density)
    return store
