"""Snapshots that ParaView opens, checkpoints that resume a run, and a progress line for long runs.

Snapshots are written with meshio (a maintained library for mesh formats) as VTK XML unstructured grids:
``droplets_NNNNN.vtu`` (one vertex per droplet; point data diameter [m], velocity [m/s], density [kg/m^3],
age [s], ident) and ``fluid_NNNNN.vtu`` (hexahedral cells; cell data velocity at cell centres [m/s], dynamic
pressure [Pa], void fraction [-]). ``snapshots.pvd`` lists them with their simulated times, so ParaView plays
the series with the right time axis. Every file is written atomically.

Checkpoints are single ``.npz`` files holding every array of the state plus counters and the random generators'
states; ``checkpoint.npz`` is replaced atomically, so a run killed at any moment resumes from the last one.
"""

from __future__ import annotations

import io
import json
import sys
import time as _time
from pathlib import Path

import meshio
import numpy as np

from settler.output import atomic_write_bytes, atomic_write_text


def _mesh_bytes(mesh: meshio.Mesh) -> bytes:
    import os
    import tempfile

    fd, tmp = tempfile.mkstemp(suffix=".vtu")
    os.close(fd)
    try:
        meshio.write(tmp, mesh, file_format="vtu", binary=True)
        return Path(tmp).read_bytes()
    finally:
        os.unlink(tmp)


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
        n = droplets.count
        arrays = droplets.arrays()
        cloud = meshio.Mesh(arrays["position"] if n else np.zeros((0, 3)),
                            [("vertex", np.arange(n).reshape(-1, 1))],
                            point_data={"diameter": arrays["diameter"], "velocity": arrays["velocity"],
                                        "density": arrays["density"], "age": arrays["age"],
                                        "ident": arrays["ident"].astype(np.float64)})
        name_d = f"droplets_{index:05d}.vtu"
        atomic_write_bytes(self.out_dir / name_d, _mesh_bytes(cloud))
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


def load_checkpoint(path):
    """Read a checkpoint written by :func:`save_checkpoint` -> (arrays dict, meta dict)."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files if k != "__meta__"}
        meta = json.loads(bytes(data["__meta__"]).decode())
    return arrays, meta


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj)}")


class Progress:
    """A one-line progress report on stderr: simulated time, droplets, wall time and ETA.

    The ETA extrapolates the pace since the first report, not since the start: the first step of a run includes
    the compilation of the Numba kernels (up to a minute on a first run), which would otherwise inflate it."""

    def __init__(self, t_start, t_end, enabled=True, interval=1.0, stream=None):
        self.t_start, self.t_end = t_start, t_end
        self.enabled = enabled
        self.interval = interval
        self.stream = stream or sys.stderr
        self.wall_start = _time.perf_counter()
        self.last = -1e30
        self.first = None  # (simulated time, wall clock) of the first report
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()

    def update(self, t, droplets, extra="", force=False):
        now = _time.perf_counter()
        if not self.enabled or (not force and now - self.last < self.interval):
            return
        self.last = now
        wall = now - self.wall_start
        done = (t - self.t_start) / max(self.t_end - self.t_start, 1e-300)
        if self.first is None:
            self.first = (t, now)
        first_t, first_wall = self.first
        eta = (now - first_wall) * (self.t_end - t) / (t - first_t) if t > first_t else float("nan")
        line = (f"t = {t:8.3f} / {self.t_end:g} s ({100 * done:5.1f} %)  droplets {droplets:8d}  "
                f"wall {wall:7.1f} s  ETA {eta:7.1f} s  {extra}")
        if self.tty:
            self.stream.write("\r" + line[:150].ljust(150))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self):
        if self.enabled and self.tty:
            self.stream.write("\n")
