"""Plain-NumPy twins of the fluid kernels (advection, ghost layers, the pressure operator and CG updates) that
tests/test_fulldem_fluid.py compares the compiled kernels with; not used by runs.
"""

from __future__ import annotations

import numpy as np

from .advection import PAD
from .pressure import _periodic_consistent


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


def max_cell_speed_reference(u, v, w):
    """NumPy twin of :func:`max_cell_speed_kernel`."""
    a = 0.5 * (u[1:] + u[:-1])
    b = 0.5 * (v[:, 1:] + v[:, :-1])
    c = 0.5 * (w[:, :, 1:] + w[:, :, :-1])
    return float(np.sqrt((a * a + b * b + c * c).max()))


def mixture_divergence_reference(u, v, w, ex, ey, ez, qx, qy, qz, source, spacing):
    """NumPy twin of :func:`mixture_divergence_kernel`."""
    fx, fy, fz = ex * u + qx, ey * v + qy, ez * w + qz
    return (np.diff(fx, axis=0) + np.diff(fy, axis=1) + np.diff(fz, axis=2)) / spacing - source


def _face_gradient_reference(phi, axis, spacing, periodic):
    """(phi[i] - phi[i-1]) / h on the faces normal to ``axis``; wall faces 0, periodic face n = face 0."""
    n = phi.shape[axis]
    inner = np.diff(phi, axis=axis) / spacing
    if periodic:
        wrap = (np.take(phi, [0], axis=axis) - np.take(phi, [n - 1], axis=axis)) / spacing
    else:
        wrap = np.zeros_like(np.take(phi, [0], axis=axis))
    return np.concatenate([wrap, inner, wrap], axis=axis)


def apply_operator_reference(phi, ex, ey, ez, spacing, px, py, pz):
    """NumPy twin of :func:`apply_operator_kernel`."""
    out = np.zeros_like(phi)
    for axis, (eps, periodic) in enumerate(((ex, px), (ey, py), (ez, pz))):
        eps = _periodic_consistent(eps, axis) if periodic else eps
        flux = eps * _face_gradient_reference(phi, axis, spacing, periodic)
        out -= np.diff(flux, axis=axis) / spacing
    return out


def subtract_gradient_reference(u, v, w, phi, scale, spacing, px, py, pz):
    """NumPy twin of :func:`subtract_gradient_kernel` (returns new arrays)."""
    out = []
    for axis, (vel, periodic) in enumerate(((u, px), (v, py), (w, pz))):
        grad = _face_gradient_reference(phi, axis, spacing, periodic)
        out.append(vel - scale * grad)
    return tuple(out)


def cg_update_reference(phi, residual, direction, operator_direction, alpha):
    """NumPy twin of :func:`cg_update_kernel` (returns new phi, residual and |r|^2)."""
    phi = phi + alpha * direction
    residual = residual - alpha * operator_direction
    return phi, residual, float(np.sum(residual * residual))
