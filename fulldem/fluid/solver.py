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

Discretisation (advection: :mod:`fulldem.fluid.advection`; walls and disks: :mod:`fulldem.fluid.walls`).

* Viscosity: explicit 7-point Laplacian; no-slip on walls by odd reflection (ghost = -interior), so the tangential
  velocity vanishes on the wall; wall-normal velocities are imposed on the wall faces.
* Time: two-stage SSP Runge-Kutta (Heun), each stage projected (Le & Moin 1991, J. Comput. Phys. 92, 369 style):
  second order in time, TVD with the TVD reconstructions, stable for ``dt <= stable_dt`` i.e.
  ``dt (2 U / h + 6 nu / h^2) <= 1`` (U = sum of the largest |u|, |v|, |w|). Pure viscous limit
  ``dt <= h^2 / (6 nu)``: 0.029 s for h = 5 mm and nu = 0.45/3150, above the 1e-3-1e-2 s steps of the engine;
  an implicit viscous option is therefore not offered.
* Projection: :mod:`fulldem.fluid.pressure` (PCG with a DCT/FFT preconditioner; exact when eps = 1). The returned
  ``p = rho (phi_1 / 2 + phi_2)`` is the pressure whose gradient the fluid actually felt over the step.

The API is :class:`FluidState`, :func:`fulldem.fluid.walls.make_boundary`, :func:`step`, :func:`stable_dt`; kernels are
``@njit(cache=True)`` functions with plain-NumPy twins in :mod:`fulldem.fluid.twins` checked in
tests/test_fulldem_fluid.py.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import pressure as _pressure
from .advection import ADVECTION_SCHEMES, PAD, fill_ghosts_kernel, max_cell_speed_kernel, momentum_rhs_kernel
from .walls import _apply_wall_values, _boundary_velocities, _copy_periodic_faces, _wall_slice


class FluidState(NamedTuple):
    """Fluid fields in the grid layout (:mod:`fulldem.fluid.grid`).

    u (nx+1, ny, nz), v (nx, ny+1, nz), w (nx, ny, nz+1) [m/s] face velocities (the slag's, not the mixture's);
    p (nx, ny, nz) [Pa] dynamic pressure (hydrostatic part removed), zero mean.
    """

    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    p: np.ndarray


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
         pressure_tolerance=1e-12, max_iterations=200, timer=None):
    """Advance the fluid by dt [s]; returns (new :class:`FluidState`, :class:`FluidDiagnostics`).

    grid: :class:`fulldem.fluid.grid.Grid`; boundary: from :func:`make_boundary`; density [kg/m^3]; viscosity [Pa s];
    eps_faces: (ex, ey, ez) void fraction on faces [-] in (0, 1] (None: 1) at the end of the step;
    eps_faces_old: the same at the start of the step (None: eps_faces); eps_cells: cell void fraction, accepted
    for the caller's convenience but not needed (all terms live on faces: the face values carry the physics);
    particle_flux: (qx, qy, qz) particle volume flux on faces [m/s] (None: 0); source: (nx, ny, nz) mixture volume
    source [1/s] (None: 0); force: (fx, fy, fz) face force density on the fluid [N/m^3] (None: 0); body_force:
    uniform mean pressure gradient -grad P_mean [N/m^3], acting as eps b; advection: a key of
    :data:`ADVECTION_SCHEMES`; pressure_tolerance: relative CG residual; timer: a
    :class:`fulldem.tuning.PhaseTimes` whose ``lap`` is called after each part ("fluid: ..." phases), or None. On
    periodic axes the first face's value of every face input is used for the last face too.
    """
    lap = timer.lap if timer is not None else _no_lap
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
    lap("fluid: set-up")

    def projected(velocity, guess):
        _copy_periodic_faces(velocity, grid.periodic)
        _apply_wall_values(velocity, wall_values)
        return _pressure.project(solver, *velocity, dt, eps, flux, sources, pressure_tolerance, max_iterations,
                                 uniform=uniform, initial=guess)

    # Stage 1: forward Euler to t + dt, projected. Its potential is close to the last step's p / rho.
    rhs = _momentum_rhs(grid, work, start, eps, nu, scheme)
    first = [(momentum_start[a] + dt * (rhs[a] + forcing[a])) / eps[a] for a in range(3)]
    guess = state.p / density if np.any(state.p) else None
    lap("fluid: momentum")
    stage1 = projected(first, guess)
    lap("fluid: pressure")
    # Stage 2: the SSP-RK2 average, projected; half of stage 1's correction is already in it, so phi_2 ~ phi_1 / 2.
    rhs = _momentum_rhs(grid, work, first, eps, nu, scheme)
    second = [(0.5 * momentum_start[a] + 0.5 * (eps[a] * first[a] + dt * (rhs[a] + forcing[a]))) / eps[a]
              for a in range(3)]
    lap("fluid: momentum")
    stage2 = projected(second, 0.5 * stage1.phi)
    lap("fluid: pressure")

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
    lap("fluid: diagnostics")
    return FluidState(second[0], second[1], second[2], pressure_field), diagnostics


def _no_lap(name):
    """The timer of an untimed step."""


def viscous_limit(spacing, density, viscosity) -> float:
    """The explicit viscous limit h^2 / (6 nu) [s] of cells of edge ``spacing`` h [m] (nu = viscosity / density):
    the largest stable step without flow (:func:`stable_dt`), which fulldem.driver.check_case enforces; inf for
    nu = 0."""
    return math.inf if viscosity == 0.0 else spacing**2 * density / (6.0 * viscosity)


def stable_dt(grid, state, density, viscosity, cfl=0.5) -> float:
    """Largest step [s] with dt (U / h + 3 nu / h^2) <= cfl, U = max|u| + max|v| + max|w|.

    With the default cfl = 0.5 this is the forward-Euler (hence SSP-RK2) bound 2 U dt / h + 6 nu dt / h^2 <= 1 of
    the TVD schemes; without flow it is the viscous limit h^2 / (6 nu) (:func:`viscous_limit`; 0.029 s for h = 5 mm
    in slag).
    """
    h = grid.spacing
    speed = sum(float(np.abs(a).max()) for a in (state.u, state.v, state.w))
    rate = speed / h + 0.5 / viscous_limit(h, density, viscosity)
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
