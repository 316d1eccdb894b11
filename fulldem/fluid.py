"""The slag as a volume-averaged incompressible Newtonian fluid with inertia on the MAC grid (model A).

Equations (SI; ``eps`` void fraction, ``q`` particle volume flux [m/s], ``s`` volume source [1/s], ``f`` face force
density [N/m^3], ``b`` uniform imposed body force [N/m^3], ``p`` dynamic pressure [Pa], hydrostatic part removed)::

    div(eps u + q) = s                                                       (mixture continuity, every cell)
    rho [d(eps u)/dt + div(eps u u)] = -eps grad p + mu lap u + f + eps b    (momentum, every free face)

The momentum equation is model A (Zhou, Kuang, Chu & Yu 2010, J. Fluid Mech. 661, 482) in conservative form, so
that the discrete fluid momentum ``P = rho h^3 sum_faces eps u`` changes only by the face forces: with the fluid
continuity d(eps)/dt + div(eps u) = 0 it equals rho eps (du/dt + u.grad u) of the non-conservative form. The
viscous term is mu lap u (the eps inside the stress of model A is dropped, as the brief of this engine asks).
``b`` is a *mean pressure gradient* (-grad P_mean = b): like the pressure it acts on the fluid fraction, eps b, and
the droplets carry the rest (below); a uniform ``b`` is then balanced by a linear pressure exactly, with no
spurious currents whatever eps is.

Momentum bookkeeping for the coupling. Over one step the fluid momentum changes by exactly (to round-off, periodic
box) ``dt h^3 sum_faces [f + eps (b - grad p)]`` with ``p`` the returned pressure (advection and viscous fluxes
telescope). A droplet must therefore feel ``V_p * interp(-grad p + b)`` interpolated with the SAME face weights
W_pf used to deposit its volume into 1 - eps (so sum_p V_p W_pf = (1 - eps_f) h^3); then droplets and fluid
together receive ``h^3 sum_f (-grad p + b) = b * volume``: the pressure gradient telescopes to zero.
:func:`pressure_force_density` gives (-grad p + b) on faces (0 on wall faces, which carry no fluid equation). For
exact conservation when eps changes between steps, pass the previous step's face void fraction as
``eps_faces_old`` (the time derivative is (eps_new u_new - eps_old u_old)/dt).

Discretisation.

* Space: staggered MAC (:mod:`fulldem.grid`); momentum control volumes centred on faces; the advecting velocity on
  a control-volume face is the mean of the two neighbouring face fluid fluxes ``eps u`` (consistent with
  continuity); the advected velocity is reconstructed by an upwind-biased, limited scheme from
  :data:`ADVECTION_SCHEMES`. Default ``koren``: the kappa = 1/3 upwind-biased (third-order) reconstruction where the
  flow is smooth, limited by Koren's TVD limiter near steep gradients and extrema. Why: cell Reynolds numbers of
  10-1000 in the droplet plume make central differences oscillate (cell Peclet > 2) and unlimited QUICK overshoot,
  while first-order upwind adds a numerical viscosity U h / 2 that would exceed the slag's (nu = 1.4e-4 m^2/s) at
  U > 0.06 m/s for h = 5 mm. The flux form makes advection conserve momentum exactly.
* Viscosity: explicit 7-point Laplacian; no-slip on walls by odd reflection (ghost = -interior), so the tangential
  velocity vanishes on the wall; wall-normal velocities are imposed on the wall faces.
* Time: two-stage SSP Runge-Kutta (Heun), each stage projected (Le & Moin 1991, J. Comput. Phys. 92, 369 style):
  second order in time, TVD with the TVD reconstructions, stable for ``dt <= stable_dt`` i.e.
  ``dt (2 U / h + 6 nu / h^2) <= 1`` (U = sum of the largest |u|, |v|, |w|). Pure viscous limit
  ``dt <= h^2 / (6 nu)``: 0.029 s for h = 5 mm and nu = 0.45/3150, above the 1e-3-1e-2 s steps of the engine;
  an implicit viscous option is therefore not offered.
* Projection: :mod:`fulldem.pressure` (PCG with a DCT/FFT preconditioner; exact when eps = 1). The returned
  ``p = rho (phi_1 / 2 + phi_2)`` is the pressure whose gradient the fluid actually felt over the step.

Boundaries. Each axis is periodic or walled (``grid.periodic``). On walls: no penetration, no slip. Two patches:

* inlet: a disk on the top wall (z = top); the slag enters downward with a uniform velocity over the disk, each
  top face weighted by the exact fraction of its area the disk covers (:func:`disk_coverage`), scaled so that the
  slag volume inflow ``sum eps w h^2`` equals ``boundary.inflow_flux`` [m^3/s] to round-off;
* outlet: a disk on a side wall with uniform outward velocity (again coverage-weighted) whose flux is set every step
  so that the mixture volume balance closes exactly (inflow + integral of s dV - particle flux through walls). This
  "mass-balanced outflow" imposes the outlet's velocity profile and leaves its pressure free: it is the net flux a
  pressure outlet would pass, and it makes the all-Neumann pressure problem solvable.

The API is :class:`FluidState`, :func:`make_boundary`, :func:`step`, :func:`stable_dt`; kernels are
``@njit(cache=True)`` functions with plain-NumPy twins (suffix ``_reference``) checked in
tests/test_fulldem_fluid.py.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from . import pressure as _pressure
from .boundaries import SIDES, side_axis, side_is_upper

#: Ghost layers on each side of the padded work arrays (the reconstructions reach two faces upwind).
PAD = 2


class AdvectionScheme(NamedTuple):
    """A reconstruction of the advected velocity on a control-volume face (code: the kernel's switch value)."""

    code: int
    citation: str


#: Advection schemes by name. Face value from the upwind-far (U), upwind (C) and downwind (D) velocities.
ADVECTION_SCHEMES = {
    "koren": AdvectionScheme(0, "kappa = 1/3 upwind-biased with Koren's TVD limiter; B. Koren (1993), in Numerical "
                                "Methods for Advection-Diffusion Problems, Vieweg, 117-138"),
    "van_leer": AdvectionScheme(1, "MUSCL with van Leer's limiter; B. van Leer (1974), J. Comput. Phys. 14, 361"),
    "quick": AdvectionScheme(2, "QUICK, unlimited (kappa = 1/2); B.P. Leonard (1979), Comput. Methods Appl. Mech. "
                                "Eng. 19, 59"),
    "central": AdvectionScheme(3, "second-order central, unlimited (oscillates at cell Reynolds number > 2)"),
    "upwind": AdvectionScheme(4, "first-order upwind; Courant, Isaacson & Rees (1952), Commun. Pure Appl. Math. 5, "
                                 "243"),
    "none": AdvectionScheme(5, "no advection: unsteady Stokes flow"),
}


# ------------------------------------------------------------------------------------------------------ records


class FluidState(NamedTuple):
    """Fluid fields in the grid layout (:mod:`fulldem.grid`).

    u (nx+1, ny, nz), v (nx, ny+1, nz), w (nx, ny, nz+1) [m/s] face velocities (the slag's, not the mixture's);
    p (nx, ny, nz) [Pa] dynamic pressure (hydrostatic part removed), zero mean.
    """

    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    p: np.ndarray


class InletDisk(NamedTuple):
    """A velocity inlet on the top wall: disk centre (x, y) [m] and radius [m]."""

    centre: tuple[float, float]
    radius: float


class OutletDisk(NamedTuple):
    """A mass-balanced outflow disk on a side wall.

    side: 'x-', 'x+', 'y-' or 'y+'; centre: (transverse, height) [m], transverse = y on x walls, x on y walls,
    height = z; radius [m].
    """

    side: str
    centre: tuple[float, float]
    radius: float


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


class FluidDiagnostics(NamedTuple):
    """Numbers reported by :func:`step`.

    cell_reynolds: max over cells of rho |u| h / mu with |u| from face averages [-]; courant: max |u| dt / h [-];
    viscous_number: nu dt / h^2 [-] (explicit limit 1/6); pressure_iterations: CG iterations of both stages;
    pressure_residual: largest final relative CG residual [-]; divergence_residual: max |div(eps u + q) - s| after
    the step [1/s]; solvability_defect: mean of div(eps u* + q) - s removed before the pressure solve [1/s] (zero
    to round-off when the boundary fluxes balance the sources); inflow_flux, outflow_flux: slag volume through the
    inlet and outlet [m^3/s].
    """

    cell_reynolds: float
    courant: float
    viscous_number: float
    pressure_iterations: int
    pressure_residual: float
    divergence_residual: float
    solvability_defect: float
    inflow_flux: float
    outflow_flux: float


def rest_state(grid) -> FluidState:
    """Slag at rest with zero pressure."""
    u, v, w = grid.zeros_faces()
    return FluidState(u, v, w, grid.zeros_cells())


# --------------------------------------------------------------------------------------------------- boundary


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


# ------------------------------------------------------------------------------------------------------ kernels


@njit(cache=True, inline="always")
def face_value(upwind_far, upwind, downwind, scheme):
    """Reconstructed velocity on a control-volume face from the upwind-far, upwind and downwind values.

    scheme: the ``code`` of an entry of :data:`ADVECTION_SCHEMES`.
    """
    if scheme == 4:
        return upwind
    if scheme == 3:
        return 0.5 * (upwind + downwind)
    back = upwind - upwind_far
    ahead = downwind - upwind
    if scheme == 2:
        return upwind + 0.125 * (back + 3.0 * ahead)
    if back * ahead <= 0.0:  # local extremum: TVD limiters fall back to upwind
        return upwind
    if scheme == 0:
        # 1/2 psi(r) back with psi = max(0, min(2r, (1 + 2r)/3, 2)), r = ahead / back (Koren)
        slope = min(abs(ahead), (abs(back) + 2.0 * abs(ahead)) / 6.0, abs(back))
        return upwind + math.copysign(slope, back)
    return upwind + back * ahead / (back + ahead)  # van Leer


def face_value_reference(upwind_far, upwind, downwind, scheme):
    """NumPy twin of :func:`face_value` (broadcasting)."""
    upwind_far, upwind, downwind = np.broadcast_arrays(*(np.asarray(x, dtype=float)
                                                         for x in (upwind_far, upwind, downwind)))
    if scheme == 4:
        return upwind.copy()
    if scheme == 3:
        return 0.5 * (upwind + downwind)
    back = upwind - upwind_far
    ahead = downwind - upwind
    if scheme == 2:
        return upwind + 0.125 * (back + 3.0 * ahead)
    monotone = back * ahead > 0.0
    if scheme == 0:
        slope = np.minimum(np.minimum(np.abs(ahead), (np.abs(back) + 2.0 * np.abs(ahead)) / 6.0), np.abs(back))
        limited = upwind + np.copysign(slope, back)
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            limited = upwind + back * ahead / (back + ahead)
    return np.where(monotone, limited, upwind)


@njit(cache=True)
def _ghost_source(g, n, face_like, periodic):
    """Core index and sign that ghost position g (core coordinates) copies along an axis of n cells."""
    if periodic:
        return ((g % n) + n) % n, 1.0
    if face_like:  # wall-normal velocity: even about the wall face
        if g < 0:
            return -g, 1.0
        return 2 * n - g, 1.0
    if g < 0:  # tangential velocity: odd about the wall, so it vanishes there
        return -g - 1, -1.0
    return 2 * n - 1 - g, -1.0


@njit(cache=True)
def fill_ghosts_kernel(padded, component, nx, ny, nz, px, py, pz):
    """Fill the PAD ghost layers of a padded face array in place (axes in order x, y, z, so edges and corners
    are filled too). component: the axis the array's faces are normal to (-1: a cell-centred array).
    On a periodic axis the core's last face is also set equal to its first."""
    for axis in range(3):
        if axis == 0:
            n, periodic = nx, px
        elif axis == 1:
            n, periodic = ny, py
        else:
            n, periodic = nz, pz
        face_like = axis == component
        core = n + 1 if face_like else n
        if face_like and periodic:
            _copy_slab(padded, axis, n + PAD, PAD, 1.0)
        for g in (-2, -1, core, core + 1):
            src, sign = _ghost_source(g, n, face_like, periodic)
            _copy_slab(padded, axis, g + PAD, src + PAD, sign)


@njit(cache=True)
def _copy_slab(a, axis, dst, src, sign):
    n0, n1, n2 = a.shape
    if axis == 0:
        for j in range(n1):
            for k in range(n2):
                a[dst, j, k] = sign * a[src, j, k]
    elif axis == 1:
        for i in range(n0):
            for k in range(n2):
                a[i, dst, k] = sign * a[i, src, k]
    else:
        for i in range(n0):
            for j in range(n1):
                a[i, j, dst] = sign * a[i, j, src]


def fill_ghosts_reference(padded, component, shape, periodic):
    """NumPy twin of :func:`fill_ghosts_kernel` (returns a new array)."""
    out = np.array(padded, dtype=float, copy=True)
    for axis in range(3):
        n = shape[axis]
        face_like = axis == component
        core = n + 1 if face_like else n
        index = np.arange(-PAD, core + PAD)
        sign = np.ones(index.size)
        source = index.copy()
        if periodic[axis]:
            source = np.mod(index, n)
        else:
            low, high = index < 0, index >= core
            if face_like:
                source[low], source[high] = -index[low], 2 * n - index[high]
            else:
                source[low], source[high] = -index[low] - 1, 2 * n - 1 - index[high]
                sign[low | high] = -1.0
        shape_b = [1, 1, 1]
        shape_b[axis] = index.size
        out = np.take(out, source + PAD, axis=axis) * sign.reshape(shape_b)
    return out


@njit(cache=True)
def momentum_rhs_kernel(component, vel, flux_x, flux_y, flux_z, nx, ny, nz, spacing, nu, px, py, pz, scheme, out):
    """out = -div(eps u u_c) + nu lap u_c [m/s^2] on the faces of component c whose velocity is free.

    vel: padded velocity component c; flux_*: padded fluid fluxes eps u, eps v, eps w [m/s], ghosts filled by
    :func:`fill_ghosts_kernel`; out: unpadded face array of component c (other entries untouched).
    scheme: the code of an entry of :data:`ADVECTION_SCHEMES` (5: no advection).
    """
    c = component
    lo0 = 1 if (c == 0 and not px) else 0
    lo1 = 1 if (c == 1 and not py) else 0
    lo2 = 1 if (c == 2 and not pz) else 0
    viscous = nu / (spacing * spacing)
    for i in range(lo0, nx):
        for j in range(lo1, ny):
            for k in range(lo2, nz):
                a, b, e = i + PAD, j + PAD, k + PAD
                out[i, j, k] = viscous * (vel[a + 1, b, e] + vel[a - 1, b, e] + vel[a, b + 1, e] + vel[a, b - 1, e]
                                          + vel[a, b, e + 1] + vel[a, b, e - 1] - 6.0 * vel[a, b, e])
    if scheme == 5:
        return
    flux_c = flux_x if c == 0 else (flux_y if c == 1 else flux_z)
    inv_h = 1.0 / spacing
    for d in range(3):
        flux_d = flux_x if d == 0 else (flux_y if d == 1 else flux_z)
        di = 1 if d == 0 else 0
        dj = 1 if d == 1 else 0
        dk = 1 if d == 2 else 0
        # Range of control volumes whose upper face (along d) carries a flux: from the lower face of the first
        # free one; on a wall of axis d (d != c) the first and last faces lie on the wall, where u_c = 0.
        wall_tangential = d != c and not (px if d == 0 else (py if d == 1 else pz))
        s0, s1, s2 = lo0 - di, lo1 - dj, lo2 - dk
        e0, e1, e2 = nx, ny, nz
        if wall_tangential:
            s0, s1, s2 = lo0, lo1, lo2
            e0, e1, e2 = nx - di, ny - dj, nz - dk
        # Carrier: mean of the face fluxes at offsets first and (di, dj, dk) from the control volume's index.
        if d == c:
            _advect_pass(out, vel, flux_c, 0, 0, 0, di, dj, dk, s0, s1, s2, e0, e1, e2, lo0, lo1, lo2, nx, ny, nz,
                         scheme, inv_h)
        else:
            f0 = di - (1 if c == 0 else 0)
            f1 = dj - (1 if c == 1 else 0)
            f2 = dk - (1 if c == 2 else 0)
            _advect_pass(out, vel, flux_d, f0, f1, f2, di, dj, dk, s0, s1, s2, e0, e1, e2, lo0, lo1, lo2, nx, ny, nz,
                         scheme, inv_h)


@njit(cache=True)
def _advect_pass(out, vel, carrier_flux, f0, f1, f2, di, dj, dk, s0, s1, s2, e0, e1, e2, lo0, lo1, lo2, nx, ny, nz,
                 scheme, inv_h):
    """Advective fluxes through the control-volume faces normal to one axis (unit offset (di, dj, dk)), each
    computed once and given to both neighbouring control volumes, so that advection telescopes exactly.

    The carrier (fluid flux eps u on the control-volume face) is the mean of carrier_flux at offsets (f0, f1, f2)
    and (di, dj, dk) from the control volume's own padded index; the carried velocity is reconstructed
    upwind-biased. Control volumes with index >= (lo0, lo1, lo2) and < (nx, ny, nz) receive the fluxes.
    """
    for i in range(s0, e0):
        for j in range(s1, e1):
            for k in range(s2, e2):
                a, b, e = i + PAD, j + PAD, k + PAD
                carrier = 0.5 * (carrier_flux[a + f0, b + f1, e + f2] + carrier_flux[a + di, b + dj, e + dk])
                if carrier >= 0.0:
                    value = face_value(vel[a - di, b - dj, e - dk], vel[a, b, e], vel[a + di, b + dj, e + dk],
                                       scheme)
                else:
                    value = face_value(vel[a + 2 * di, b + 2 * dj, e + 2 * dk], vel[a + di, b + dj, e + dk],
                                       vel[a, b, e], scheme)
                flux = carrier * value * inv_h
                if i >= lo0 and j >= lo1 and k >= lo2:
                    out[i, j, k] -= flux
                if i + di < nx and j + dj < ny and k + dk < nz:
                    out[i + di, j + dj, k + dk] += flux


def momentum_rhs_reference(component, vel, fluxes, shape, spacing, nu, periodic, scheme):
    """NumPy twin of :func:`momentum_rhs_kernel`; returns the face array (zero on faces that are not free)."""
    c = component
    unit = np.eye(3, dtype=int)
    lo = [1 if (a == c and not periodic[a]) else 0 for a in range(3)]
    hi = list(shape)

    def view(array, offset):
        return array[tuple(slice(PAD + lo[a] + offset[a], PAD + hi[a] + offset[a]) for a in range(3))]

    zero = np.zeros(3, dtype=int)
    total = np.zeros(tuple(hi[a] - lo[a] for a in range(3)))
    for d in range(3):
        e = unit[d]

        def control_flux(shift):
            if d == c:
                carrier = 0.5 * (view(fluxes[c], shift) + view(fluxes[c], shift + e))
            else:
                carrier = 0.5 * (view(fluxes[d], shift + e - unit[c]) + view(fluxes[d], shift + e))
            ahead = carrier >= 0.0
            far = np.where(ahead, view(vel, shift - e), view(vel, shift + 2 * e))
            near = np.where(ahead, view(vel, shift), view(vel, shift + e))
            down = np.where(ahead, view(vel, shift + e), view(vel, shift))
            g = carrier * face_value_reference(far, near, down, scheme)
            if d != c and not periodic[d]:
                face = np.arange(lo[d], hi[d]) + shift[d] + 1
                on_wall = (face == 0) | (face == shape[d])
                index = [slice(None)] * 3
                index[d] = on_wall
                g[tuple(index)] = 0.0
            return g

        total += nu * (view(vel, e) - 2.0 * view(vel, zero) + view(vel, -e)) / spacing**2
        if scheme != 5:
            total -= (control_flux(zero) - control_flux(-e)) / spacing
    face_shape = list(shape)
    face_shape[c] += 1
    out = np.zeros(face_shape)
    out[tuple(slice(lo[a], hi[a]) for a in range(3))] = total
    return out


@njit(cache=True)
def max_cell_speed_kernel(u, v, w):
    """Largest cell-centre speed [m/s], the cell velocity being the mean of its two faces per component."""
    nx, ny, nz = w.shape[0], w.shape[1], u.shape[2]
    best = 0.0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                a = 0.5 * (u[i, j, k] + u[i + 1, j, k])
                b = 0.5 * (v[i, j, k] + v[i, j + 1, k])
                c = 0.5 * (w[i, j, k] + w[i, j, k + 1])
                speed = a * a + b * b + c * c
                if speed > best:
                    best = speed
    return math.sqrt(best)


def max_cell_speed_reference(u, v, w):
    """NumPy twin of :func:`max_cell_speed_kernel`."""
    a = 0.5 * (u[1:] + u[:-1])
    b = 0.5 * (v[:, 1:] + v[:, :-1])
    c = 0.5 * (w[:, :, 1:] + w[:, :, :-1])
    return float(np.sqrt((a * a + b * b + c * c).max()))


# ------------------------------------------------------------------------------------------------ orchestration


def _faces(grid, arrays, default):
    """Face arrays as float64 copies, periodic last face = first face; default fill when arrays is None."""
    out = []
    for axis in range(3):
        shape = grid.face_shape(axis)
        if arrays is None:
            array = np.full(shape, default)
        else:
            array = np.array(arrays[axis], dtype=float, copy=True)
            if array.shape != shape:
                raise ValueError(f"fluid: face array {axis} has shape {array.shape}, expected {shape}")
            if grid.periodic[axis]:
                array[_wall_slice(axis, True)] = array[_wall_slice(axis, False)]
        out.append(array)
    return out


class _Workspace:
    """Padded work arrays of one grid (allocated once per grid shape)."""

    def __init__(self, grid):
        self.velocity = []
        self.flux = []
        for axis in range(3):
            shape = tuple(n + 2 * PAD for n in grid.face_shape(axis))
            self.velocity.append(np.zeros(shape))
            self.flux.append(np.zeros(shape))
        self.core = tuple(tuple(slice(PAD, PAD + n) for n in grid.face_shape(axis)) for axis in range(3))


_WORKSPACES: dict = {}


def _workspace(grid):
    key = (tuple(grid.shape), tuple(grid.periodic))
    if key not in _WORKSPACES:
        _WORKSPACES[key] = _Workspace(grid)
    return _WORKSPACES[key]


def _momentum_rhs(grid, work, velocity, eps, nu, scheme):
    """-div(eps u u) + nu lap u for the three components (free faces; zero elsewhere) [m/s^2]."""
    nx, ny, nz = grid.shape
    px, py, pz = (bool(p) for p in grid.periodic)
    for axis in range(3):
        work.velocity[axis][work.core[axis]] = velocity[axis]
        work.flux[axis][work.core[axis]] = eps[axis] * velocity[axis]
        fill_ghosts_kernel(work.velocity[axis], axis, nx, ny, nz, px, py, pz)
        fill_ghosts_kernel(work.flux[axis], axis, nx, ny, nz, px, py, pz)
    out = []
    for axis in range(3):
        rhs = np.zeros(grid.face_shape(axis))
        momentum_rhs_kernel(axis, work.velocity[axis], work.flux[0], work.flux[1], work.flux[2], nx, ny, nz,
                            grid.spacing, nu, px, py, pz, scheme, rhs)
        out.append(rhs)
    return out


def step(grid, state, boundary, density, viscosity, dt, eps_faces=None, eps_cells=None, particle_flux=None,
         source=None, force=None, body_force=(0.0, 0.0, 0.0), *, eps_faces_old=None, advection="koren",
         pressure_tolerance=1e-12, max_iterations=200):
    """Advance the fluid by dt [s]; returns (new :class:`FluidState`, :class:`FluidDiagnostics`).

    grid: :class:`fulldem.grid.Grid`; boundary: from :func:`make_boundary`; density [kg/m^3]; viscosity [Pa s];
    eps_faces: (ex, ey, ez) void fraction on faces [-] in (0, 1] (None: 1) at the end of the step;
    eps_faces_old: the same at the start of the step (None: eps_faces); eps_cells: cell void fraction, accepted
    for the caller's convenience but not needed (all terms live on faces: the face values carry the physics);
    particle_flux: (qx, qy, qz) particle volume flux on faces [m/s] (None: 0); source: (nx, ny, nz) mixture volume
    source [1/s] (None: 0); force: (fx, fy, fz) face force density on the fluid [N/m^3] (None: 0); body_force:
    uniform mean pressure gradient -grad P_mean [N/m^3], acting as eps b; advection: a key of
    :data:`ADVECTION_SCHEMES`; pressure_tolerance: relative CG residual. On periodic axes the first face's value
    of every face input is used for the last face too.
    """
    del eps_cells  # see the docstring: the discretisation needs void fractions on faces only
    if advection not in ADVECTION_SCHEMES:
        raise ValueError(f"fluid.step: advection {advection!r} is not one of {sorted(ADVECTION_SCHEMES)}")
    if dt <= 0.0 or density <= 0.0 or viscosity < 0.0:
        raise ValueError(f"fluid.step: need dt > 0, density > 0, viscosity >= 0 (got {dt}, {density}, {viscosity})")
    scheme = ADVECTION_SCHEMES[advection].code
    nu = viscosity / density
    uniform = eps_faces is None and eps_faces_old is None
    eps = _faces(grid, eps_faces, 1.0)
    eps_old = eps if eps_faces_old is None else _faces(grid, eps_faces_old, 1.0)
    if min(float(e.min()) for e in eps + eps_old) <= 0.0:
        raise ValueError("fluid.step: face void fractions must be positive")
    flux = _faces(grid, particle_flux, 0.0)
    forcing = _faces(grid, force, 0.0)
    sources = grid.zeros_cells() if source is None else np.asarray(source, dtype=float)
    body = np.asarray(body_force, dtype=float)
    for axis in range(3):
        forcing[axis] += eps[axis] * body[axis]
        forcing[axis] /= density
    solver = _pressure.poisson_solver(tuple(grid.shape), grid.spacing, tuple(grid.periodic))
    work = _workspace(grid)
    wall_values, inflow, outflow = _boundary_velocities(grid, boundary, eps, flux, sources)

    start = [np.array(a, dtype=float, copy=True) for a in (state.u, state.v, state.w)]
    _copy_periodic_faces(start, grid.periodic)
    _apply_wall_values(start, wall_values)
    momentum_start = [eps_old[a] * start[a] for a in range(3)]

    def projected(velocity, guess):
        _copy_periodic_faces(velocity, grid.periodic)
        _apply_wall_values(velocity, wall_values)
        return _pressure.project(solver, *velocity, dt, eps, flux, sources, pressure_tolerance, max_iterations,
                                 uniform=uniform, initial=guess)

    # Stage 1: forward Euler to t + dt, projected. Its potential is close to the last step's p / rho.
    rhs = _momentum_rhs(grid, work, start, eps, nu, scheme)
    first = [(momentum_start[a] + dt * (rhs[a] + forcing[a])) / eps[a] for a in range(3)]
    guess = state.p / density if np.any(state.p) else None
    stage1 = projected(first, guess)
    # Stage 2: the SSP-RK2 average, projected; half of stage 1's correction is already in it, so phi_2 ~ phi_1 / 2.
    rhs = _momentum_rhs(grid, work, first, eps, nu, scheme)
    second = [(0.5 * momentum_start[a] + 0.5 * (eps[a] * first[a] + dt * (rhs[a] + forcing[a]))) / eps[a]
              for a in range(3)]
    stage2 = projected(second, 0.5 * stage1.phi)

    pressure_field = density * (0.5 * stage1.phi + stage2.phi)
    divergence = np.empty(grid.shape)
    _pressure.mixture_divergence_kernel(*second, *eps, *flux, sources, grid.spacing, divergence)
    speed = max_cell_speed_kernel(*second)
    h = grid.spacing
    diagnostics = FluidDiagnostics(
        cell_reynolds=density * speed * h / viscosity if viscosity > 0.0 else math.inf,
        courant=speed * dt / h,
        viscous_number=nu * dt / h**2,
        pressure_iterations=stage1.iterations + stage2.iterations,
        pressure_residual=max(stage1.residual, stage2.residual),
        divergence_residual=float(np.abs(divergence).max()),
        solvability_defect=stage2.defect,
        inflow_flux=inflow,
        outflow_flux=outflow,
    )
    return FluidState(second[0], second[1], second[2], pressure_field), diagnostics


def stable_dt(grid, state, density, viscosity, cfl=0.5) -> float:
    """Largest step [s] with dt (U / h + 3 nu / h^2) <= cfl, U = max|u| + max|v| + max|w|.

    With the default cfl = 0.5 this is the forward-Euler (hence SSP-RK2) bound 2 U dt / h + 6 nu dt / h^2 <= 1 of
    the TVD schemes; without flow it is the viscous limit h^2 / (6 nu) (0.029 s for h = 5 mm in slag).
    """
    h = grid.spacing
    speed = sum(float(np.abs(a).max()) for a in (state.u, state.v, state.w))
    rate = speed / h + 3.0 * (viscosity / density) / h**2
    return math.inf if rate == 0.0 else cfl / rate


def _unique_faces(grid, axis):
    """Slice of the face array of ``axis`` without the duplicate last face of a periodic axis."""
    index = [slice(None)] * 3
    if grid.periodic[axis]:
        index[axis] = slice(0, grid.shape[axis])
    return tuple(index)


def total_momentum(grid, state, density, eps_faces=None) -> np.ndarray:
    """Fluid momentum rho h^3 sum_faces eps u [kg m/s], (3,); each periodic face counted once."""
    eps = _faces(grid, eps_faces, 1.0)
    velocity = (state.u, state.v, state.w)
    return np.array([density * grid.cell_volume * float(np.sum((eps[a] * velocity[a])[_unique_faces(grid, a)]))
                     for a in range(3)])


def pressure_force_density(grid, pressure_field, body_force=(0.0, 0.0, 0.0)):
    """(-grad p + b) on faces [N/m^3], zero on wall faces (where the fluid has no momentum equation).

    A droplet of volume V_p feels V_p times this, interpolated with the weights that deposit its volume into
    1 - eps (see the module docstring); the fluid felt eps times it.
    """
    out = grid.zeros_faces()
    _pressure.subtract_gradient_kernel(*out, np.asarray(pressure_field, dtype=float), 1.0, grid.spacing,
                                       *(bool(p) for p in grid.periodic))
    for axis in range(3):
        index = [slice(None)] * 3
        if not grid.periodic[axis]:
            index[axis] = slice(1, grid.shape[axis])
        out[axis][tuple(index)] += body_force[axis]
    return out


def mixture_divergence(grid, state, eps_faces=None, particle_flux=None, source=None) -> np.ndarray:
    """div(eps u + q) - s per cell [1/s]."""
    eps = _faces(grid, eps_faces, 1.0)
    flux = _faces(grid, particle_flux, 0.0)
    sources = grid.zeros_cells() if source is None else np.asarray(source, dtype=float)
    out = np.empty(grid.shape)
    _pressure.mixture_divergence_kernel(state.u, state.v, state.w, *eps, *flux, sources, grid.spacing, out)
    return out
