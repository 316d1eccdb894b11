"""Snapshots that ParaView opens.

Droplets are written with meshio (a maintained library for mesh formats) as VTK XML unstructured grids,
``droplets_NNNNN.vtu`` (one vertex per droplet; point data diameter [m], velocity [m/s], density [kg/m^3],
age [s], ident); the slag as VTK XML image data, ``fluid_NNNNN.vti`` (:mod:`settler.vti`: the uniform grid with
cell data velocity at cell centres [m/s], dynamic pressure [Pa], void fraction [-], float32), which ParaView opens
as an image (slices, volume rendering, contours) and which stores no points or cells. Runs made before
2026-12-03 wrote the slag as hexahedra in ``fluid_NNNNN.vtu``; the readers take both. ``snapshots.pvd`` lists them with their simulated times, so ParaView plays
the series with the right time axis. Every file is written atomically.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import meshio
import numpy as np

from settler.output import atomic_write_bytes, atomic_write_text
from settler.vti import image_bytes

from ..droplets import MERGED


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


class SnapshotWriter:
    """Writes numbered droplet and fluid snapshots and keeps ``snapshots.pvd`` up to date."""

    def __init__(self, out_dir, grid, entries=None):
        self.out_dir = Path(out_dir)
        self.grid = grid
        self.entries = list(entries or [])  # (time, file) pairs

    def write(self, time, droplets, fluid, void_fraction):
        index = len({t for t, _ in self.entries})
        cloud, compression = _droplet_cloud(droplets)
        name_d = f"droplets_{index:05d}.vtu"
        atomic_write_bytes(self.out_dir / name_d, _mesh_bytes(cloud, compression))
        velocity = cell_centre_velocity(self.grid, fluid.u, fluid.v, fluid.w)
        name_f = f"fluid_{index:05d}.vti"
        atomic_write_bytes(self.out_dir / name_f, image_bytes(
            self.grid.shape, self.grid.lower, self.grid.spacing,
            {"velocity": velocity, "pressure": fluid.p, "void_fraction": np.asarray(void_fraction)}))
        self.entries += [(time, name_d), (time, name_f)]
        self._write_pvd()

    def _write_pvd(self):
        rows = "\n".join(f'    <DataSet timestep="{t:.9g}" part="{0 if f.startswith("droplets") else 1}" file="{f}"/>'
                         for t, f in self.entries)
        atomic_write_text(self.out_dir / "snapshots.pvd",
                          '<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1">\n  <Collection>\n'
                          f"{rows}\n  </Collection>\n</VTKFile>\n")
