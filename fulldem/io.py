"""Snapshots that ParaView opens, checkpoints that resume a run, and a progress line for long runs.

Snapshots are written with meshio (a maintained library for mesh formats) as VTK XML unstructured grids:
``droplets_NNNNN.vtu`` (one vertex per droplet; point data diameter [m], velocity [m/s], density [kg/m^3],
age [s], ident) and ``fluid_NNNNN.vtu`` (hexahedral cells; cell data velocity at cell centres [m/s], dynamic
pressure [Pa], void fraction [-]). ``snapshots.pvd`` lists them with their simulated times, so ParaView plays
the series with the right time axis. Every file is written atomically.

Checkpoints are single ``.npz`` files holding every array of the state plus counters and the random generators'
states; ``checkpoint.npz`` is replaced atomically, so a run killed at any moment resumes from the last one.
A file that is not such a checkpoint (truncated, not an .npz, no metadata) raises :class:`CheckpointError`.

:class:`Progress` reports a run's progress: a tqdm bar in a terminal or a notebook, plain lines elsewhere.
"""

from __future__ import annotations

import io
import json
import os
import sys
import tempfile
import time as _time
import zipfile
import zlib
from pathlib import Path

import meshio
import numpy as np

from settler.output import atomic_write_bytes, atomic_write_text

from .droplets import MERGED


def _mesh_bytes(mesh: meshio.Mesh, compression="zlib") -> bytes:
    """The .vtu file of ``mesh`` as bytes (meshio writes only to files: a temporary one, always removed)."""
    fd, tmp = tempfile.mkstemp(suffix=".vtu")
    try:
        os.close(fd)
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression=compression)
        return Path(tmp).read_bytes()
    finally:
        Path(tmp).unlink(missing_ok=True)


def _droplet_cloud(droplets) -> tuple[meshio.Mesh, str | None]:
    """The droplets as a meshio mesh (one vertex cell per droplet) and the compression to write it with.

    A snapshot without droplets needs care, because meshio (5.3) cannot read back what it writes for one: its
    reader fails on a compressed binary array with no data blocks (every array of an empty mesh) and on a piece
    with no cells. So it is written uncompressed, with zero points and a single polygon of zero points (VTK reads
    and draws it as nothing; a cell without points of VTK's own, VTK_EMPTY_CELL, is one meshio cannot read).
    """
    n = droplets.count
    arrays = droplets.arrays()
    point_data = {"diameter": arrays["diameter"], "velocity": arrays["velocity"], "density": arrays["density"],
                  "age": arrays["age"], "ident": arrays["ident"].astype(np.float64),
                  "merged": ((arrays["flags"] & MERGED) != 0).astype(np.float64)}
    if n:
        return meshio.Mesh(arrays["position"], [("vertex", np.arange(n).reshape(-1, 1))],
                           point_data=point_data), "zlib"
    point_data = {k: np.ascontiguousarray(v, dtype=np.float64) for k, v in point_data.items()}
    return meshio.Mesh(np.zeros((0, 3)), [("polygon", np.zeros((1, 0), dtype=np.int64))],
                       point_data=point_data), None


def cell_centre_velocity(grid, u, v, w):
    """Velocity averaged from faces to cell centres, (nx, ny, nz, 3) [m/s]."""
    out = np.empty((*grid.shape, 3))
    out[..., 0] = 0.5 * (u[:-1] + u[1:])
    out[..., 1] = 0.5 * (v[:, :-1] + v[:, 1:])
    out[..., 2] = 0.5 * (w[:, :, :-1] + w[:, :, 1:])
    return out


def _hexahedra(grid):
    nx, ny, nz = grid.shape
    xs, ys, zs = (grid.lower[a] + np.arange(grid.shape[a] + 1) * grid.spacing for a in range(3))
    points = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)

    def node(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    cells = np.stack([node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                      node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)],
                     axis=1)
    return points, cells


class SnapshotWriter:
    """Writes numbered droplet and fluid snapshots and keeps ``snapshots.pvd`` up to date."""

    def __init__(self, out_dir, grid, entries=None):
        self.out_dir = Path(out_dir)
        self.grid = grid
        self.entries = list(entries or [])  # (time, file) pairs
        self._hex = None

    def write(self, time, droplets, fluid, void_fraction):
        index = len({t for t, _ in self.entries})
        cloud, compression = _droplet_cloud(droplets)
        name_d = f"droplets_{index:05d}.vtu"
        atomic_write_bytes(self.out_dir / name_d, _mesh_bytes(cloud, compression))
        if self._hex is None:
            self._hex = _hexahedra(self.grid)
        points, cells = self._hex
        velocity = cell_centre_velocity(self.grid, fluid.u, fluid.v, fluid.w).reshape(-1, 3)
        mesh = meshio.Mesh(points, [("hexahedron", cells)],
                           cell_data={"velocity": [velocity], "pressure": [fluid.p.ravel()],
                                      "void_fraction": [void_fraction.ravel()]})
        name_f = f"fluid_{index:05d}.vtu"
        atomic_write_bytes(self.out_dir / name_f, _mesh_bytes(mesh))
        self.entries += [(time, name_d), (time, name_f)]
        self._write_pvd()

    def _write_pvd(self):
        rows = "\n".join(f'    <DataSet timestep="{t:.9g}" part="{0 if f.startswith("droplets") else 1}" file="{f}"/>'
                         for t, f in self.entries)
        atomic_write_text(self.out_dir / "snapshots.pvd",
                          '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                          f"{rows}\n  </Collection>\n</VTKFile>\n")


def save_checkpoint(path, arrays: dict, meta: dict):
    """Write arrays and JSON metadata into one .npz, atomically."""
    buf = io.BytesIO()
    np.savez(buf, __meta__=np.frombuffer(json.dumps(meta, default=_json_default).encode(), dtype=np.uint8),
             **arrays)
    atomic_write_bytes(path, buf.getvalue())


class CheckpointError(ValueError):
    """A checkpoint that cannot be read: truncated, not an .npz, or an .npz without settler's metadata."""


def load_checkpoint(path):
    """Read a checkpoint written by :func:`save_checkpoint` -> (arrays dict, meta dict).

    A missing or unreadable file raises the usual OSError; a file that is not a complete checkpoint raises
    :class:`CheckpointError` with a one-line message naming the file and what is wrong.
    """
    path = Path(path)

    def bad(reason):
        return CheckpointError(f"{path} is truncated or not a checkpoint written by settler full: {reason}")

    with open(path, "rb") as fh:  # FileNotFoundError / PermissionError pass through as they are
        try:
            data = np.load(fh, allow_pickle=False)
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
            raise bad(f"not an .npz archive ({_reason(exc)})") from exc
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise bad("a single .npy array, not an .npz archive")
        with data:
            if "__meta__" not in data.files:
                raise bad("no __meta__ entry")
            try:
                arrays = {k: data[k] for k in data.files if k != "__meta__"}
                raw = data["__meta__"]
            except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
                raise bad(f"an array cannot be read ({_reason(exc)})") from exc
    try:
        meta = json.loads(bytes(raw).decode())
    except (ValueError, TypeError) as exc:
        raise bad(f"__meta__ is not JSON ({_reason(exc)})") from exc
    if not isinstance(meta, dict):
        raise bad("__meta__ is not a JSON object")
    return arrays, meta


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    text = text if len(text) <= 100 else text[:97] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj)}")


def _in_notebook() -> bool:
    """True inside a Jupyter/IPython kernel (as tqdm.auto decides between its notebook and terminal bars)."""
    if "ipykernel" not in sys.modules or "IPython" not in sys.modules:
        return False
    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and getattr(shell, "kernel", None) is not None


class Progress:
    """Progress of a run over simulated time: a tqdm bar in a terminal or notebook, plain lines elsewhere.

    Where ``stream`` is a terminal, or in a Jupyter/IPython kernel (with the default stream), the progress is a
    tqdm bar over simulated time (tqdm.auto's widget in a notebook): the time as description, the droplet count
    and ``extra`` as postfix, the width fitted to the terminal (or ``ncols``). Elsewhere (log files, pipes) it is
    one plain line per ``interval`` wall seconds, like LIGGGHTS' thermo output::

        t =    1.250 / 10 s ( 12.5 %)  droplets     3125  wall    60.2 s  ETA   301.4 s  Re_cell ...

    Both leave out the first step's pace: it includes the compilation of the Numba kernels (up to a minute on a
    first run). The plain lines' ETA extrapolates the pace since the first report; the bar starts its rate
    estimate (tqdm's exponential moving average) at the first update.

    Every :meth:`update` records the latest state, even one not shown; :meth:`close` shows it (the bar at 100 %
    once ``t`` reached ``t_end``; a last plain line unless that state was already printed) and closes the bar.
    ``close(t)`` records a final time first. ``bar`` forces the choice (True: tqdm bar, False: plain lines).
    """

    def __init__(self, t_start, t_end, enabled=True, interval=1.0, stream=None, *, ncols=None, bar=None):
        self.t_start, self.t_end = float(t_start), float(t_end)
        self.enabled = enabled
        self.interval = interval
        self.stream = stream if stream is not None else sys.stderr
        self.wall_start = _time.perf_counter()
        self.last = -1e30
        self.first = None  # (simulated time, wall clock) of the first report
        self.tty = bool(getattr(self.stream, "isatty", None) and self.stream.isatty())
        notebook = (stream is None or stream is sys.stderr or stream is sys.stdout) and _in_notebook()
        self.state = None  # (t, droplets, extra) of the latest update
        self.shown = True  # whether that state has been shown
        self.closed = False
        self._bar = None
        if enabled and (bar if bar is not None else (self.tty or notebook)):
            self._bar = self._make_bar(notebook, ncols)

    def _make_bar(self, notebook, ncols):
        try:
            if notebook:
                from tqdm.auto import tqdm
            else:
                from tqdm import tqdm
        except ImportError:
            return None  # plain lines
        options = {} if notebook else {"file": self.stream}
        return tqdm(total=self.total, unit="s", ncols=ncols, dynamic_ncols=ncols is None and not notebook,
                    mininterval=min(self.interval, 0.2), miniters=0, leave=True,
                    desc=self._description(self.t_start),
                    bar_format="{desc} {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}{postfix}]", **options)

    @property
    def total(self) -> float:
        """Simulated time of the whole run [s], as the bar's total (1 for a run that has nothing left to do)."""
        return self.t_end - self.t_start if self.t_end > self.t_start else 1.0

    @property
    def is_bar(self) -> bool:
        """Whether the progress is shown as a tqdm bar (else as plain lines)."""
        return self._bar is not None

    def _description(self, t):
        return f"t = {t:.3f}/{self.t_end:g} s"

    def _done(self, t):
        """The bar's position for simulated time t: exactly its total once t is within round-off of t_end."""
        if t >= self.t_end - 1e-9 * max(1.0, abs(self.t_end)):
            return self.total
        return min(max(t - self.t_start, 0.0), self.total)

    def update(self, t, droplets, extra="", force=False):
        """Record simulated time ``t`` [s] and the droplet count; show them if ``interval`` has passed or ``force``."""
        if not self.enabled or self.closed:
            return
        self.state, self.shown = (t, droplets, extra), False
        now = _time.perf_counter()
        if not force and now - self.last < (self._bar.mininterval if self._bar is not None else self.interval):
            return
        self.last = now
        if self._bar is not None:
            self._update_bar(t, droplets, extra, force)
        else:
            self._line(t, droplets, extra, now)
        self.shown = True

    def _update_bar(self, t, droplets, extra, force):
        bar = self._bar
        bar.set_description_str(self._description(t), refresh=False)
        bar.set_postfix_str(f"droplets {droplets}" + (f"  {extra}" if extra else ""), refresh=False)
        done = self._done(t)
        if self.first is None:
            # Jump to the first position without a rate sample: the first step includes the compilation.
            self.first = (t, _time.perf_counter())
            bar.n = bar.initial = bar.last_print_n = done
            bar.last_print_t = bar._time()
            bar.refresh()
        elif force:
            bar.n = done
            bar.refresh()
        else:
            bar.update(done - bar.n)

    def _line(self, t, droplets, extra, now):
        wall = now - self.wall_start
        done = (t - self.t_start) / max(self.t_end - self.t_start, 1e-300)
        if self.first is None:
            self.first = (t, now)
        first_t, first_wall = self.first
        eta = (now - first_wall) * (self.t_end - t) / (t - first_t) if t > first_t else float("nan")
        line = (f"t = {t:8.3f} / {self.t_end:g} s ({100 * done:5.1f} %)  droplets {droplets:8d}  "
                f"wall {wall:7.1f} s  ETA {eta:7.1f} s  {extra}")
        self.stream.write(line + "\n")
        self.stream.flush()

    def close(self, t=None):
        """Show the latest state (``t`` [s], if given, is the final time) and close the bar; idempotent."""
        if not self.enabled or self.closed:
            return
        if t is not None:
            droplets, extra = self.state[1:] if self.state else (0, "")
            self.state, self.shown = (t, droplets, extra), False
        try:
            if self.state is not None and not self.shown:
                self.update(*self.state, force=True)
        finally:
            self.closed = True
            if self._bar is not None:
                self._bar.close()
