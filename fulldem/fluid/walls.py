"""The fluid's walls and disks: no-slip walls, the slag inlet on the roof and the outlet in a side wall.

Boundaries. Each axis is periodic or walled (``grid.periodic``). On walls: no penetration, no slip. Two patches:

* inlet: a disk on the top wall (z = top); the slag enters downward with a uniform velocity over the disk, each
  top face weighted by the exact fraction of its area the disk covers (:func:`disk_coverage`), scaled so that the
  slag volume inflow ``sum eps w h^2`` equals ``boundary.inflow_flux`` [m^3/s] to round-off;
* outlet: a disk on a side wall with uniform outward velocity (again coverage-weighted) whose flux is set every step
  so that the mixture volume balance closes exactly (inflow + integral of s dV - particle flux through walls). This
  "mass-balanced outflow" imposes the outlet's velocity profile and leaves its pressure free: it is the net flux a
  pressure outlet would pass, and it makes the all-Neumann pressure problem solvable.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..boundaries import SIDES, InletDisk, OutletDisk, side_axis, side_is_upper


class FluidBoundary(NamedTuple):
    """Boundary data built once by :func:`make_boundary`.

    periodic: per-axis flags (copied from the grid); inlet_weight: (nx, ny) fraction of each top z-face covered by
    the inlet disk, or None; outlet_axis: 0 or 1 (-1: no outlet); outlet_upper: the outlet is on the upper wall of
    that axis; outlet_weight: fraction of each face of that wall covered by the outlet disk, shape (ny, nz) on x
    walls and (nx, nz) on y walls, or None; inflow_flux: slag volume inflow through the inlet [m^3/s] (a feed that
    varies in time: ``boundary._replace(inflow_flux=...)``).
    """

    periodic: tuple[bool, bool, bool]
    inlet_weight: np.ndarray | None
    outlet_axis: int
    outlet_upper: bool
    outlet_weight: np.ndarray | None
    inflow_flux: float


def _region_below_left(x, y, r):
    """Area of {X <= x, Y <= y, X^2 + Y^2 <= r^2} (disk at the origin) [m^2]; vectorised over x, y."""
    x = np.clip(np.asarray(x, dtype=float), -r, r)
    y = np.asarray(y, dtype=float)

    def primitive(t):  # integral of sqrt(r^2 - X^2) from -r to t
        t = np.clip(t, -r, r)
        return 0.5 * (t * np.sqrt(np.maximum(r * r - t * t, 0.0)) + r * r * np.arcsin(t / r)) + 0.25 * np.pi * r * r

    # Inside |X| < xb the lower edge -sqrt(r^2 - X^2) is below y and the upper one above it: height y + sqrt(..).
    # Outside, the chord lies entirely below y (full height, y >= 0) or entirely above it (nothing, y < 0).
    xb = np.sqrt(np.maximum(r * r - y * y, 0.0))
    upper = y >= 0.0
    outer_left = np.where(upper, 2.0 * (primitive(np.minimum(x, -xb)) - primitive(-r)), 0.0)
    mid_end = np.clip(x, -xb, xb)
    middle = y * (mid_end + xb) + primitive(mid_end) - primitive(-xb)
    outer_right = np.where(upper & (x > xb), 2.0 * (primitive(x) - primitive(xb)), 0.0)
    return outer_left + middle + outer_right


def disk_coverage(face_lower, spacing, counts, centre, radius) -> np.ndarray:
    """Exact fraction of each square face of a wall covered by a disk.

    face_lower: (a0, b0) [m] corner of the wall in its two in-plane coordinates; spacing [m]; counts (na, nb);
    centre (a, b) [m]; radius [m] -> (na, nb) array of covered area fractions in [0, 1].
    """
    a_edges = face_lower[0] + spacing * np.arange(counts[0] + 1) - centre[0]
    b_edges = face_lower[1] + spacing * np.arange(counts[1] + 1) - centre[1]
    corner = _region_below_left(a_edges[:, None], b_edges[None, :], radius)
    area = corner[1:, 1:] - corner[:-1, 1:] - corner[1:, :-1] + corner[:-1, :-1]
    return np.clip(area / spacing**2, 0.0, 1.0)


#: (axis, upper wall) of each side name, from the one encoding in fulldem.boundaries.
_SIDES = {name: (side_axis(code), side_is_upper(code)) for name, code in SIDES.items()}


def _check_disk_inside(name, centre, radius, lower, upper):
    for c, lo, hi in zip(centre, lower, upper):
        if not (lo + radius <= c + 1e-12 and c - 1e-12 <= hi - radius) or radius <= 0.0:
            raise ValueError(f"{name}: disk centre {tuple(centre)} m, radius {radius} m must lie inside the wall "
                             f"[{tuple(lower)}, {tuple(upper)}] m with positive radius")


def make_boundary(grid, inlet=None, outlet=None, inflow_flux=0.0) -> FluidBoundary:
    """Boundary patches of a grid.

    inlet: :class:`InletDisk` (or (centre, radius)) on the top wall, requires a walled z axis; outlet:
    :class:`OutletDisk` (or (side, centre, radius)) on a walled side; inflow_flux: slag volume inflow [m^3/s]
    (>= 0, needs an inlet when positive). Coverage weights are computed exactly once here.
    """
    periodic = tuple(bool(p) for p in grid.periodic)
    for axis in range(3):
        if not periodic[axis] and grid.shape[axis] < 2:
            raise ValueError(f"make_boundary: a walled axis needs at least 2 cells, axis {axis} has "
                             f"{grid.shape[axis]}")
    lower, upper, h = np.asarray(grid.lower), grid.upper, grid.spacing
    inlet_weight = None
    if inlet is not None:
        inlet = inlet if isinstance(inlet, InletDisk) else (InletDisk(**inlet) if isinstance(inlet, dict)
                                                            else InletDisk(*inlet))
        if periodic[2]:
            raise ValueError("make_boundary: an inlet on the top wall needs a walled z axis (grid.periodic[2] is True)")
        _check_disk_inside("inlet", inlet.centre, inlet.radius, lower[:2], upper[:2])
        inlet_weight = disk_coverage(lower[:2], h, grid.shape[:2], inlet.centre, inlet.radius)
    if inflow_flux < 0.0 or (inflow_flux > 0.0 and inlet is None):
        raise ValueError(f"make_boundary: inflow_flux = {inflow_flux} m^3/s must be >= 0 and needs an inlet")
    outlet_axis, outlet_upper, outlet_weight = -1, False, None
    if outlet is not None:
        outlet = outlet if isinstance(outlet, OutletDisk) else (OutletDisk(**outlet) if isinstance(outlet, dict)
                                                                else OutletDisk(*outlet))
        if outlet.side not in _SIDES:
            raise ValueError(f"make_boundary: outlet side {outlet.side!r} must be one of {sorted(_SIDES)}")
        outlet_axis, outlet_upper = _SIDES[outlet.side]
        if periodic[outlet_axis]:
            raise ValueError(f"make_boundary: outlet side {outlet.side!r} is on a periodic axis")
        transverse = 1 - outlet_axis
        plane_lower = (lower[transverse], lower[2])
        plane_upper = (upper[transverse], upper[2])
        _check_disk_inside("outlet", outlet.centre, outlet.radius, plane_lower, plane_upper)
        outlet_weight = disk_coverage(plane_lower, h, (grid.shape[transverse], grid.shape[2]), outlet.centre,
                                      outlet.radius)
    return FluidBoundary(periodic, inlet_weight, outlet_axis, outlet_upper, outlet_weight, float(inflow_flux))


def _wall_slice(axis, upper):
    index = [slice(None)] * 3
    index[axis] = -1 if upper else 0
    return tuple(index)


def _boundary_flux_out(grid, velocity, eps, flux):
    """Net outward mixture volume flux sum (eps u + q) . n h^2 through all wall faces [m^3/s]."""
    total = 0.0
    for axis in range(3):
        if grid.periodic[axis]:
            continue
        for upper, sign in ((False, -1.0), (True, 1.0)):
            sl = _wall_slice(axis, upper)
            total += sign * float(np.sum(eps[axis][sl] * velocity[axis][sl] + flux[axis][sl]))
    return total * grid.spacing**2


def _boundary_velocities(grid, boundary, eps, flux, source):
    """Wall-normal face velocities for this step: (list of (axis, slice, values)), inflow, outflow [m^3/s]."""
    h2 = grid.spacing**2
    values = []
    walls = list(grid.zeros_faces())
    inflow = 0.0
    if boundary.inlet_weight is not None and boundary.inflow_flux > 0.0:
        top = eps[2][:, :, -1] * boundary.inlet_weight
        speed = boundary.inflow_flux / (float(np.sum(top)) * h2)
        walls[2][:, :, -1] = -speed * boundary.inlet_weight
        inflow = -float(np.sum(eps[2][:, :, -1] * walls[2][:, :, -1])) * h2
    outflow = 0.0
    if boundary.outlet_weight is not None:
        # Outward flux needed: sources minus what already leaves through the walls (inlet, particle flux).
        needed = float(np.sum(source)) * grid.spacing**3 - _boundary_flux_out(grid, walls, eps, flux)
        axis = boundary.outlet_axis
        sl = _wall_slice(axis, boundary.outlet_upper)
        weight = boundary.outlet_weight
        open_area = float(np.sum(eps[axis][sl] * weight)) * h2
        outward = 1.0 if boundary.outlet_upper else -1.0
        walls[axis][sl] = outward * (needed / open_area) * weight
        outflow = needed
    for axis in range(3):
        if not grid.periodic[axis]:
            for upper in (False, True):
                sl = _wall_slice(axis, upper)
                values.append((axis, sl, walls[axis][sl].copy()))
    return values, inflow, outflow


def _apply_wall_values(velocity, wall_values):
    for axis, sl, values in wall_values:
        velocity[axis][sl] = values


def _copy_periodic_faces(velocity, periodic):
    for axis in range(3):
        if periodic[axis]:
            velocity[axis][_wall_slice(axis, True)] = velocity[axis][_wall_slice(axis, False)]
