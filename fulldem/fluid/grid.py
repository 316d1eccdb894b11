"""The uniform Cartesian grid and the staggered (MAC) layout shared by the fluid solver and the coupling.

Layout (one name per thing, used by every kernel):

* cells: ``shape = (nx, ny, nz)`` cubes of side ``spacing`` [m]; cell (i, j, k) has its centre at
  ``lower + (i + 1/2, j + 1/2, k + 1/2) * spacing``. Cell-centred fields (pressure, void fraction) have shape
  ``(nx, ny, nz)``.
* faces: the x-velocity ``u`` lives on x-faces, shape ``(nx + 1, ny, nz)``, face (i, j, k) at
  ``lower + (i, j + 1/2, k + 1/2) * spacing``; likewise ``v`` on y-faces ``(nx, ny + 1, nz)`` and ``w`` on z-faces
  ``(nx, ny, nz + 1)``. On a periodic axis the last face is the first one again and is kept equal to it.
* axes: x = 0, y = 1, z = 2; gravity along -z; the box is ``[lower, lower + shape * spacing]``.
* boundaries: each axis is either ``periodic`` or bounded by no-slip walls (with the inlet and outlet patches of
  the case, see :mod:`fulldem.fluid`).

Kernels receive the grid as plain numbers (``shape``, ``spacing``, ``lower``, ``periodic``), never this object.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Grid(NamedTuple):
    """A uniform grid: ``shape`` (nx, ny, nz) cells of side ``spacing`` [m] from corner ``lower`` [m]."""

    shape: tuple[int, int, int]
    spacing: float
    lower: tuple[float, float, float] = (0.0, 0.0, 0.0)
    periodic: tuple[bool, bool, bool] = (False, False, False)

    @classmethod
    def for_box(cls, size, spacing, lower=(0.0, 0.0, 0.0), periodic=(False, False, False)) -> "Grid":
        """The grid covering a box of edge lengths ``size`` [m] with cubic cells of about ``spacing`` [m].

        The cell count per axis is rounded, then the spacing adjusted so cells are cubes that fill the box exactly;
        a box whose edges are not commensurate to within 1e-9 relative raises ValueError.
        """
        size = np.asarray(size, dtype=float)
        counts = np.maximum(1, np.round(size / spacing).astype(int))
        h = size[0] / counts[0]
        if not np.allclose(counts * h, size, rtol=1e-9, atol=0.0):
            raise ValueError(f"grid: box {tuple(size)} m cannot be divided into cubic cells near {spacing} m; "
                             f"choose a spacing that divides every edge (counts {tuple(counts)})")
        return cls(tuple(int(c) for c in counts), float(h), tuple(float(x) for x in lower),
                   tuple(bool(p) for p in periodic))

    @property
    def size(self) -> np.ndarray:
        """Edge lengths of the box [m]."""
        return np.asarray(self.shape) * self.spacing

    @property
    def upper(self) -> np.ndarray:
        """Far corner of the box [m]."""
        return np.asarray(self.lower) + self.size

    @property
    def cell_volume(self) -> float:
        """Volume of one cell [m^3]."""
        return self.spacing**3

    def face_shape(self, axis: int) -> tuple[int, int, int]:
        """Shape of the face-centred array for the velocity component along ``axis``."""
        shape = list(self.shape)
        shape[axis] += 1
        return tuple(shape)

    def cell_centres(self, axis: int) -> np.ndarray:
        """1-D coordinates of the cell centres along ``axis`` [m]."""
        return self.lower[axis] + (np.arange(self.shape[axis]) + 0.5) * self.spacing

    def face_positions(self, axis: int) -> np.ndarray:
        """1-D coordinates of the faces normal to ``axis`` along ``axis`` [m]."""
        return self.lower[axis] + np.arange(self.shape[axis] + 1) * self.spacing

    def zeros_faces(self):
        """Three zero face arrays (u, v, w)."""
        return tuple(np.zeros(self.face_shape(a)) for a in range(3))

    def zeros_cells(self):
        """A zero cell-centred array."""
        return np.zeros(self.shape)
