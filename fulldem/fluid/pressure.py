"""Pressure projection for the volume-averaged slag: the variable-coefficient Poisson problem on the MAC grid.

Given a predicted face velocity ``u*`` the projection finds ``phi`` (cell-centred, [m^2/s]) with

    div(eps grad phi) = (div(eps u* + q) - s) / dt,            u = u* - dt grad phi   (interior faces)

so that the discrete mixture continuity ``div(eps u + q) = s`` holds to solver tolerance in every cell. ``eps`` is
the void fraction on faces, ``q`` the particle volume flux on faces [m/s], ``s`` the volume source per cell [1/s]
(:mod:`fulldem.fluid.grid` gives the layout). Wall faces carry imposed normal velocities and get no correction (the
Neumann condition of ``phi``); on a periodic axis the first face stands for the last one too, and its value is the
one used.

Every axis is periodic or walled, so the operator always has the constants as null space: the right-hand side has
its mean removed before the solve and that mean is returned as the *solvability defect* [1/s] (zero to round-off
when the boundary fluxes balance the sources). The solver is preconditioned conjugate gradients on the positive
operator ``A phi = -div(eps grad phi)``; the preconditioner is the constant-coefficient Laplacian inverted exactly
with fast transforms (DCT-II on walled axes, Neumann eigenvalues (2 cos(pi k/n) - 2)/h^2; FFT on periodic axes,
(2 cos(2 pi k/n) - 2)/h^2). With ``eps`` in [eps_min, 1] the preconditioned condition number is at most
1/eps_min, so CG needs a handful of iterations; with ``eps = 1`` the first iteration is the exact solution.

Kernels are ``@njit(cache=True)`` functions of arrays and scalars; each has a plain-NumPy twin (suffix
``_reference``) that tests/test_fulldem_fluid.py checks it against.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from scipy import fft as sfft


#: Threads for scipy.fft on grids of at least FFT_PARALLEL_CELLS cells; smaller grids use one (measured on the
#: 2-core machine, 2026-12-03, a 3-D DCT-II: 40^3 cells 0.42 ms on one thread, 0.50 ms on two; 40 x 40 x 120,
#: 1.53 against 1.06 ms; 64^3, 2.28 against 1.47 ms). pocketfft splits the independent 1-D transforms between the
#: workers, so the result does not depend on their number.
FFT_WORKERS = 2
FFT_PARALLEL_CELLS = 100_000


@njit(cache=True, parallel=True)
def mixture_divergence_kernel(u, v, w, ex, ey, ez, qx, qy, qz, source, spacing, out):
    """out = div(eps u + q) - s per cell [1/s]; face arrays in the grid layout (periodic: face n equals face 0)."""
    nx, ny, nz = out.shape
    inv_h = 1.0 / spacing
    for i in prange(nx):  # each entry written by one iteration: threads change no result
        for j in range(ny):
            for k in range(nz):
                flux = (ex[i + 1, j, k] * u[i + 1, j, k] + qx[i + 1, j, k]
                        - ex[i, j, k] * u[i, j, k] - qx[i, j, k]
                        + ey[i, j + 1, k] * v[i, j + 1, k] + qy[i, j + 1, k]
                        - ey[i, j, k] * v[i, j, k] - qy[i, j, k]
                        + ez[i, j, k + 1] * w[i, j, k + 1] + qz[i, j, k + 1]
                        - ez[i, j, k] * w[i, j, k] - qz[i, j, k])
                out[i, j, k] = flux * inv_h - source[i, j, k]


@njit(cache=True, parallel=True)
def apply_operator_kernel(phi, ex, ey, ez, spacing, px, py, pz, out):
    """out = -div(eps grad phi) [phi / m^2]; no flux through wall faces, periodic axes wrap (face n = face 0)."""
    nx, ny, nz = phi.shape
    inv_h2 = 1.0 / (spacing * spacing)
    for i in prange(nx):  # each entry written by one iteration: threads change no result
        for j in range(ny):
            for k in range(nz):
                c = phi[i, j, k]
                acc = 0.0
                if i + 1 < nx:
                    acc += ex[i + 1, j, k] * (phi[i + 1, j, k] - c)
                elif px:
                    acc += ex[0, j, k] * (phi[0, j, k] - c)
                if i > 0:
                    acc -= ex[i, j, k] * (c - phi[i - 1, j, k])
                elif px:
                    acc -= ex[0, j, k] * (c - phi[nx - 1, j, k])
                if j + 1 < ny:
                    acc += ey[i, j + 1, k] * (phi[i, j + 1, k] - c)
                elif py:
                    acc += ey[i, 0, k] * (phi[i, 0, k] - c)
                if j > 0:
                    acc -= ey[i, j, k] * (c - phi[i, j - 1, k])
                elif py:
                    acc -= ey[i, 0, k] * (c - phi[i, ny - 1, k])
                if k + 1 < nz:
                    acc += ez[i, j, k + 1] * (phi[i, j, k + 1] - c)
                elif pz:
                    acc += ez[i, j, 0] * (phi[i, j, 0] - c)
                if k > 0:
                    acc -= ez[i, j, k] * (c - phi[i, j, k - 1])
                elif pz:
                    acc -= ez[i, j, 0] * (c - phi[i, j, nz - 1])
                out[i, j, k] = -acc * inv_h2


@njit(cache=True, parallel=True)
def subtract_gradient_kernel(u, v, w, phi, scale, spacing, px, py, pz):
    """u -= scale * grad(phi) on the faces where the velocity is free: interior faces and, on periodic axes,
    face 0 (then copied to face n). Wall faces are left alone (their velocity is imposed)."""
    nx, ny, nz = phi.shape
    c = scale / spacing
    for i in prange(nx):  # each entry written by one iteration: threads change no result
        for j in range(ny):
            for k in range(nz):
                if i > 0:
                    u[i, j, k] -= c * (phi[i, j, k] - phi[i - 1, j, k])
                elif px:
                    u[0, j, k] -= c * (phi[0, j, k] - phi[nx - 1, j, k])
                    u[nx, j, k] = u[0, j, k]
                if j > 0:
                    v[i, j, k] -= c * (phi[i, j, k] - phi[i, j - 1, k])
                elif py:
                    v[i, 0, k] -= c * (phi[i, 0, k] - phi[i, ny - 1, k])
                    v[i, ny, k] = v[i, 0, k]
                if k > 0:
                    w[i, j, k] -= c * (phi[i, j, k] - phi[i, j, k - 1])
                elif pz:
                    w[i, j, 0] -= c * (phi[i, j, 0] - phi[i, j, nz - 1])
                    w[i, j, nz] = w[i, j, 0]


@njit(cache=True)
def dot_kernel(a, b):
    """Sum of a * b over flat arrays (numpy.vdot goes through a threaded BLAS that is slow on small vectors)."""
    total = 0.0
    for n in range(a.size):
        total += a[n] * b[n]
    return total


@njit(cache=True)
def cg_update_kernel(phi, residual, direction, operator_direction, alpha):
    """phi += alpha p; r -= alpha A p (flat arrays); returns the new |r|^2."""
    total = 0.0
    for n in range(phi.size):
        phi[n] += alpha * direction[n]
        r = residual[n] - alpha * operator_direction[n]
        residual[n] = r
        total += r * r
    return total


@njit(cache=True, parallel=True)
def cg_direction_kernel(direction, preconditioned, beta):
    """p = z + beta p (flat arrays)."""
    for n in prange(direction.size):
        direction[n] = preconditioned[n] + beta * direction[n]


def _periodic_consistent(face_array, axis):
    """A copy of a face array whose last face along ``axis`` equals its first (periodic axes)."""
    out = np.array(face_array, dtype=float, copy=True)
    index = [slice(None)] * 3
    index[axis] = -1
    first = [slice(None)] * 3
    first[axis] = 0
    out[tuple(index)] = out[tuple(first)]
    return out


class PoissonSolver:
    """Exact inverse of the constant-coefficient operator -L (L the 7-point Laplacian with the grid's boundary
    conditions) by fast transforms, and the preconditioned CG solve of -div(eps grad phi) = rhs.

    Built once per (shape, spacing, periodic) by :func:`poisson_solver`.
    """

    def __init__(self, shape, spacing, periodic):
        self.shape = tuple(int(n) for n in shape)
        self.spacing = float(spacing)
        self.periodic = tuple(bool(p) for p in periodic)
        self.wall_axes = tuple(a for a in range(3) if not self.periodic[a])
        self.periodic_axes = tuple(a for a in range(3) if self.periodic[a])
        h2 = self.spacing**2
        eigen = []
        for a, n in enumerate(self.shape):
            if self.periodic[a]:
                last_periodic = a == self.periodic_axes[-1]
                k = np.arange(n // 2 + 1 if last_periodic else n)
                lam = (2.0 - 2.0 * np.cos(2.0 * np.pi * k / n)) / h2
            else:
                k = np.arange(n)
                lam = (2.0 - 2.0 * np.cos(np.pi * k / n)) / h2
            shape = [1, 1, 1]
            shape[a] = lam.size
            eigen.append(lam.reshape(shape))
        lam = eigen[0] + eigen[1] + eigen[2]
        inverse = np.zeros_like(lam)
        nonzero = lam > 0.0
        inverse[nonzero] = 1.0 / lam[nonzero]
        # The zero mode (constants) is dropped: the preconditioned iterates stay mean-free.
        self.inverse_eigenvalues = inverse
        self.ones_faces = tuple(np.ones(self._face_shape(a)) for a in range(3))
        self._work = np.empty(self.shape)
        self.workers = FFT_WORKERS if int(np.prod(self.shape)) >= FFT_PARALLEL_CELLS else 1

    def _face_shape(self, axis):
        shape = list(self.shape)
        shape[axis] += 1
        return tuple(shape)

    def apply_inverse_laplacian(self, rhs):
        """The mean-free x with -L x = rhs - mean(rhs) (exact to round-off)."""
        x = np.asarray(rhs, dtype=float)
        workers = self.workers
        if self.wall_axes:
            x = sfft.dctn(x, type=2, axes=self.wall_axes, norm="ortho", workers=workers)
        if self.periodic_axes:
            x = sfft.rfftn(x, axes=self.periodic_axes, workers=workers)
        x = x * self.inverse_eigenvalues
        if self.periodic_axes:
            sizes = [self.shape[a] for a in self.periodic_axes]
            x = sfft.irfftn(x, s=sizes, axes=self.periodic_axes, workers=workers)
        if self.wall_axes:
            x = sfft.idctn(x, type=2, axes=self.wall_axes, norm="ortho", workers=workers)
        return x

    def _preconditioner_scaling(self, eps_faces):
        """eps_c^(-1/2) per cell, eps_c the mean of the cell's six face void fractions."""
        ex, ey, ez = eps_faces
        cell = (ex[1:] + ex[:-1] + ey[:, 1:] + ey[:, :-1] + ez[:, :, 1:] + ez[:, :, :-1]) / 6.0
        return 1.0 / np.sqrt(cell)

    def apply_preconditioner(self, residual, scaling=None):
        """z = S (-L)^-1 S r with S = diag(eps_c^(-1/2)) (S = 1 when scaling is None).

        For smooth eps, S A S = -lap + O(grad eps), so the preconditioned spectrum clusters near 1; this is
        symmetric positive (semi)definite as CG needs.
        """
        if scaling is None:
            return self.apply_inverse_laplacian(residual)
        return scaling * self.apply_inverse_laplacian(scaling * residual)

    def apply_operator(self, phi, eps_faces, out=None):
        """-div(eps grad phi) [phi/m^2]."""
        out = np.empty(self.shape) if out is None else out
        ex, ey, ez = eps_faces
        apply_operator_kernel(phi, ex, ey, ez, self.spacing, *self.periodic, out)
        return out

    def solve(self, rhs, eps_faces=None, tolerance=1e-12, max_iterations=200, initial=None):
        """Solve -div(eps grad phi) = rhs for mean-free phi by preconditioned CG.

        rhs must be mean-free (see :func:`project`). Stops when ||r||_2 <= tolerance ||rhs||_2.
        Returns (phi, iterations, relative residual).
        """
        eps = self.ones_faces if eps_faces is None else eps_faces
        scaling = None if eps_faces is None else self._preconditioner_scaling(eps)
        rhs = np.ascontiguousarray(rhs, dtype=float)
        norm_rhs = np.sqrt(dot_kernel(rhs.reshape(-1), rhs.reshape(-1)))
        if norm_rhs == 0.0:
            return np.zeros(self.shape), 0, 0.0
        if initial is None:
            phi = np.zeros(self.shape)
            residual = rhs.copy()
        else:
            phi = np.array(initial, dtype=float)
            residual = rhs - self.apply_operator(phi, eps)
        operator_p = self._work
        flat_phi, flat_r, flat_ap = phi.reshape(-1), residual.reshape(-1), operator_p.reshape(-1)
        z = self.apply_preconditioner(residual, scaling)
        direction = np.ascontiguousarray(z)
        flat_p = direction.reshape(-1)
        rz = dot_kernel(flat_r, direction.reshape(-1))
        relative = np.sqrt(dot_kernel(flat_r, flat_r)) / norm_rhs
        iterations = 0
        while relative > tolerance and iterations < max_iterations:
            self.apply_operator(direction, eps, out=operator_p)
            alpha = rz / dot_kernel(flat_p, flat_ap)
            relative = np.sqrt(cg_update_kernel(flat_phi, flat_r, flat_p, flat_ap, alpha)) / norm_rhs
            iterations += 1
            if relative <= tolerance:
                break
            z = np.ascontiguousarray(self.apply_preconditioner(residual, scaling))
            rz_new = dot_kernel(flat_r, z.reshape(-1))
            cg_direction_kernel(flat_p, z.reshape(-1), rz_new / rz)
            rz = rz_new
        phi -= phi.mean()
        return phi, iterations, float(relative)


@functools.lru_cache(maxsize=16)
def poisson_solver(shape, spacing, periodic) -> PoissonSolver:
    """The (cached) :class:`PoissonSolver` of a grid: ``poisson_solver(grid.shape, grid.spacing, grid.periodic)``."""
    return PoissonSolver(tuple(shape), float(spacing), tuple(bool(p) for p in periodic))


class Projection(NamedTuple):
    """Outcome of one projection.

    phi: (nx, ny, nz) [m^2/s] mean-free potential, u = u* - dt grad phi; iterations: CG iterations;
    residual: final relative CG residual [-]; defect: mean of div(eps u* + q) - s removed before the solve [1/s].
    """

    phi: np.ndarray
    iterations: int
    residual: float
    defect: float


def project(solver, u, v, w, dt, eps_faces, particle_flux, source, tolerance=1e-12, max_iterations=200,
            uniform=False, initial=None):
    """Project (u, v, w) in place onto div(eps u + q) = s (up to the returned solvability defect).

    eps_faces, particle_flux: 3-tuples of face arrays (periodic faces already consistent); source: cell array.
    uniform: eps is identically one (the CG then stops after its first, exact, iteration; initial is ignored).
    initial: a guess of phi for the CG (e.g. from the previous step), or None.
    """
    ex, ey, ez = eps_faces
    qx, qy, qz = particle_flux
    divergence = np.empty(solver.shape)
    mixture_divergence_kernel(u, v, w, ex, ey, ez, qx, qy, qz, source, solver.spacing, divergence)
    defect = float(divergence.mean())
    rhs = (defect - divergence) / dt  # -div(eps grad phi) = -(div - mean) / dt
    if uniform:
        phi, iterations, residual = solver.solve(rhs, None, tolerance, max_iterations)
    else:
        phi, iterations, residual = solver.solve(rhs, eps_faces, tolerance, max_iterations, initial)
    subtract_gradient_kernel(u, v, w, phi, dt, solver.spacing, *solver.periodic)
    return Projection(phi, iterations, residual, defect)
