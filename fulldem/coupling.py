"""Two-way coupling between droplets and the grid: smoothed deposition, consistent interpolation, and the
correction for a droplet's own disturbance of the grid flow.

**Kernel.** A droplet's volume, volume flux and drag reaction are spread over the grid with a truncated, discretely
normalised Gaussian of width ``sigma = max(sigma_cells * h, sigma_diameter * d)``: droplets larger than a cell
(coalesced droplets reach 2 mm in cubic, 40 mm in deep) spread over as many cells as their size needs. The weights
are separable, ``w = w_x w_y w_z``, and sum to one over the nodes of each staggered array, so deposition conserves
what it spreads exactly. Wall-normal boundary faces (whose velocity is imposed) receive nothing; periodic axes wrap.

**Consistency.** Fluid velocity and pressure gradient are interpolated back to a droplet with the *same* weights
used to deposit onto the same faces. Two consequences, both exact in floating point up to summation order:
the drag impulse a droplet receives and the reaction the fluid receives sum to zero; and the pressure-gradient
force on droplets, -V_p (grad p)_interp, plus the fluid's -eps grad p sum to -(grad p) over the faces, which
telescopes to zero in a periodic box (see tests/test_fulldem_coupling.py).

**Self-induced velocity.** A droplet that pushes on the grid with force F sees, at its own position, a disturbance
u_self = M_self F it created itself, along the force the *fluid* receives, -F_drag; using the disturbed velocity
would make droplets not much smaller than sigma settle too fast (the error grows like d/sigma). Following the idea
of Balachandar, Liu & Lakhote (2019, J. Comput. Phys. 376, 160) and Horwitz & Mani (2016, J. Comput. Phys. 318,
85), the undisturbed velocity is estimated as u_interp + M_self F_drag. With the linear drag
F_drag = beta (u_undisturbed - v) this is the same as using u_interp with the increased coefficient
beta / (1 - beta M_self), which keeps the exact exponential drag integrator. beta M_self = d f / (2 sqrt(pi) sigma)
at low Re is at most about 0.6 with sigma >= d/2; it is capped at :data:`SELF_CORRECTION_CAP`.
M_self is the Gaussian-regularised Stokeslet's self-mobility 1/(6 pi^(3/2) mu sigma) (Maxey & Patel 2001), times
a *discrete* factor computed once per sigma/h by solving the grid's own periodic Stokes problem with FFTs
(:func:`discrete_mobility_factor`), times an Oseen factor of the slip Reynolds number rho |u - v| sigma / mu
(:func:`oseen_factor`), which accounts for inertia sweeping the disturbance downstream.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
from numba import njit, prange
from scipy import fft as sfft
from scipy import integrate

#: Stencil half-width in units of sigma (Gaussian weight at the edge e^(-cut^2/2) = 4 % of the peak for 2.5).
DEFAULT_CUT = 2.5
#: Hasimoto (1959) coefficient of the periodic-array correction of a Stokeslet's mobility, 1 - 2.837 a / L.
HASIMOTO = 2.837297
#: Upper bound applied to beta M_self in the self-induced-velocity correction (the correction diverges at 1).
SELF_CORRECTION_CAP = 0.9
#: Largest stencil extent in nodes per axis that the work arrays are sized for.
MAX_STENCIL = 64


@njit(cache=True)
def kernel_width(diameter, spacing, sigma_cells, sigma_diameter):
    """Smoothing width sigma = max(sigma_cells h, sigma_diameter d) [m]."""
    return max(sigma_cells * spacing, sigma_diameter * diameter)


@njit(cache=True)
def weights_1d(x, lower, spacing, n_cells, staggered, wall_normal, periodic, sigma, cut, index_out, weight_out):
    """Normalised 1-D Gaussian weights of the nodes near coordinate x; returns the number of nodes written.

    Nodes are cell centres (staggered = False) or faces (staggered = True) of an axis with n_cells cells.
    wall_normal: faces of the velocity component normal to this (walled) axis; its two boundary faces are excluded.
    periodic: indices wrap (face n_cells is face 0). Weights are written to weight_out, node indices to index_out.
    """
    offset = 0.0 if staggered else 0.5
    s = (x - lower) / spacing - offset  # position in node units
    reach = cut * sigma / spacing
    first = int(math.ceil(s - reach))
    last = int(math.floor(s + reach))
    if last - first + 1 > index_out.shape[0]:
        first = int(math.floor(s)) - index_out.shape[0] // 2 + 1
        last = first + index_out.shape[0] - 1
    if periodic:
        n_nodes = n_cells
        low, high = -1 << 30, 1 << 30
    else:
        n_nodes = n_cells + 1 if staggered else n_cells
        low, high = 0, n_nodes - 1
        if wall_normal:
            low, high = 1, n_nodes - 2
    count = 0
    total = 0.0
    inv = 1.0 / (2.0 * (sigma / spacing) ** 2)
    for node in range(first, last + 1):
        if node < low or node > high:
            continue
        r = node - s
        w = math.exp(-r * r * inv)
        index_out[count] = node % n_nodes if periodic else node
        weight_out[count] = w
        total += w
        count += 1
    if count == 0:  # pathological: a droplet outside the box; use the nearest valid node
        node = min(max(int(round(s)), low), high) if not periodic else int(round(s)) % n_nodes
        index_out[0] = node
        weight_out[0] = 1.0
        return 1
    for c in range(count):
        weight_out[c] /= total
    return count


@njit(cache=True)
def _stencil(position, sigma, spacing, lower, shape, periodic, component, cut, idx, wts, counts):
    """Weights along the three axes for the array of `component` (0..2 face arrays, 3 cells)."""
    for axis in range(3):
        staggered = component == axis
        wall_normal = staggered and not periodic[axis]
        counts[axis] = weights_1d(position[axis], lower[axis], spacing, shape[axis], staggered, wall_normal,
                                  periodic[axis], sigma, cut, idx[axis], wts[axis])


@njit(cache=True, parallel=True)
def deposit(position, diameter, value, count, component, out, spacing, lower, shape, periodic, sigma_cells,
            sigma_diameter, cut, scratch):
    """Add sum_p value[p] * w_p(node) to ``out`` (cells if component == 3, else faces of that component).

    value: (cap,) per-droplet amount (e.g. volume / cell volume). scratch: (n_threads, *out.shape) work array,
    zeroed here, that makes the parallel sum race-free.
    """
    n_chunks = scratch.shape[0]
    scratch[:] = 0.0
    for chunk in prange(n_chunks):
        idx = np.empty((3, MAX_STENCIL), dtype=np.int64)
        wts = np.empty((3, MAX_STENCIL))
        counts = np.empty(3, dtype=np.int64)
        buf = scratch[chunk]
        start = chunk * count // n_chunks
        stop = (chunk + 1) * count // n_chunks
        for p in range(start, stop):
            sigma = kernel_width(diameter[p], spacing, sigma_cells, sigma_diameter)
            _stencil(position[p], sigma, spacing, lower, shape, periodic, component, cut, idx, wts, counts)
            v = value[p]
            for a in range(counts[0]):
                ia = idx[0, a]
                wa = wts[0, a] * v
                for b in range(counts[1]):
                    ib = idx[1, b]
                    wab = wa * wts[1, b]
                    for c in range(counts[2]):
                        buf[ia, ib, idx[2, c]] += wab * wts[2, c]
    for chunk in range(n_chunks):
        out += scratch[chunk]


@njit(cache=True, parallel=True)
def interpolate(position, diameter, count, component, field, out, spacing, lower, shape, periodic, sigma_cells,
                sigma_diameter, cut):
    """out[p] = sum_nodes w_p(node) field[node] for the array of ``component`` (0..2 faces, 3 cells)."""
    for p in prange(count):
        idx = np.empty((3, MAX_STENCIL), dtype=np.int64)
        wts = np.empty((3, MAX_STENCIL))
        counts = np.empty(3, dtype=np.int64)
        sigma = kernel_width(diameter[p], spacing, sigma_cells, sigma_diameter)
        _stencil(position[p], sigma, spacing, lower, shape, periodic, component, cut, idx, wts, counts)
        acc = 0.0
        for a in range(counts[0]):
            ia = idx[0, a]
            for b in range(counts[1]):
                ib = idx[1, b]
                wab = wts[0, a] * wts[1, b]
                for c in range(counts[2]):
                    acc += wab * wts[2, c] * field[ia, ib, idx[2, c]]
        out[p] = acc


@njit(cache=True, parallel=True)
def self_weight(position, diameter, count, component, out, spacing, lower, shape, periodic, sigma_cells,
                sigma_diameter, cut):
    """out[p] = sum_nodes w_p(node)^2: a droplet's own deposit seen back at itself (to remove self-volume)."""
    for p in prange(count):
        idx = np.empty((3, MAX_STENCIL), dtype=np.int64)
        wts = np.empty((3, MAX_STENCIL))
        counts = np.empty(3, dtype=np.int64)
        sigma = kernel_width(diameter[p], spacing, sigma_cells, sigma_diameter)
        _stencil(position[p], sigma, spacing, lower, shape, periodic, component, cut, idx, wts, counts)
        acc = 1.0
        for axis in range(3):
            s2 = 0.0
            for a in range(counts[axis]):
                s2 += wts[axis, a] * wts[axis, a]
            acc *= s2
        out[p] = acc


@njit(cache=True)
def pressure_gradient_faces(p, spacing, periodic, gx, gy, gz):
    """Face-centred pressure gradient (p[i] - p[i-1]) / h; wall boundary faces get 0 (they carry no droplet
    weight). Periodic axes wrap."""
    nx, ny, nz = p.shape
    for i in range(gx.shape[0]):
        for j in range(ny):
            for k in range(nz):
                if 0 < i < nx:
                    gx[i, j, k] = (p[i, j, k] - p[i - 1, j, k]) / spacing
                elif periodic[0]:
                    gx[i, j, k] = (p[0, j, k] - p[nx - 1, j, k]) / spacing
                else:
                    gx[i, j, k] = 0.0
    for i in range(nx):
        for j in range(gy.shape[1]):
            for k in range(nz):
                if 0 < j < ny:
                    gy[i, j, k] = (p[i, j, k] - p[i, j - 1, k]) / spacing
                elif periodic[1]:
                    gy[i, j, k] = (p[i, 0, k] - p[i, ny - 1, k]) / spacing
                else:
                    gy[i, j, k] = 0.0
    for i in range(nx):
        for j in range(ny):
            for k in range(gz.shape[2]):
                if 0 < k < nz:
                    gz[i, j, k] = (p[i, j, k] - p[i, j, k - 1]) / spacing
                elif periodic[2]:
                    gz[i, j, k] = (p[i, j, 0] - p[i, j, nz - 1]) / spacing
                else:
                    gz[i, j, k] = 0.0


# ------------------------------------------------------------------------------------------ self-induced velocity
@njit(cache=True)
def gaussian_self_mobility(sigma, viscosity):
    """Self-mobility of a Gaussian-regularised Stokeslet averaged with the same Gaussian, 1/(6 pi^1.5 mu sigma)
    [m/(N s)] (Maxey & Patel 2001: a Gaussian of width sigma = a / sqrt(pi) reproduces Stokes drag on radius a)."""
    return 1.0 / (6.0 * math.pi**1.5 * viscosity * sigma)


def _oseen_inner(s, re):
    """int_-1^1 (1 - c^2) s^2 / (s^2 + Re^2 c^2) dc = 2a[(1 + a^2) arctan(1/a) - a], a = s/Re (closed form)."""
    if re == 0.0:
        return 4.0 / 3.0
    a = s / re
    if a > 1e3:  # series in 1/a avoids cancellation: 4/3 - 4/(15 a^2) + ...
        return 4.0 / 3.0 - 4.0 / (15.0 * a * a)
    return 2.0 * a * ((1.0 + a * a) * math.atan(1.0 / a) - a)


def _oseen_integral(re):
    return integrate.quad(lambda s: math.exp(-s * s) * _oseen_inner(s, re), 0.0, 9.0, epsabs=1e-13,
                          epsrel=1e-11, limit=400)[0]


@functools.lru_cache(maxsize=1)
def oseen_table():
    """Table (log10 Re_sigma, factor) of the Oseen factor, computed once by quadrature."""
    logs = np.linspace(-3.0, 4.0, 57)
    stokes = _oseen_integral(0.0)
    factors = np.array([_oseen_integral(10.0**x) / stokes for x in logs])
    return logs, factors


def oseen_factor(re_sigma):
    """u_self(Re)/u_self(0) for a Gaussian-regularised Oseenlet along the slip direction [-].

    u_self(Re) / u_self(0) = I(Re) / I(0), I(Re) = int_0^inf ds int_-1^1 dc exp(-s^2)(1 - c^2) s^2/(s^2 + Re^2 c^2),
    Re = rho |u - v| sigma / mu: the Fourier-space Oseen tensor averaged over the Gaussian (derived in the module
    docstring's references' manner). 1 at Re = 0, falling like 1/Re for large Re.
    """
    logs, factors = oseen_table()
    x = np.log10(np.maximum(np.asarray(re_sigma, dtype=float), 10.0 ** logs[0]))
    inside = np.interp(np.minimum(x, logs[-1]), logs, factors)
    return np.where(x > logs[-1], factors[-1] * 10.0 ** (logs[-1] - x), inside)


@functools.lru_cache(maxsize=64)
def discrete_mobility_factor(sigma_cells_ratio: float, cut: float = DEFAULT_CUT, n: int = 48, samples: int = 4):
    """Self-mobility of a droplet on the MAC grid divided by the continuous Gaussian value (dimensionless).

    A unit z-force is spread on the z-faces of a periodic n^3 grid with the coupling kernel (sigma = ratio * h), the
    discrete Stokes problem mu L u - grad p + f = 0, div u = 0 is solved exactly with FFTs (MAC symbols
    g_a = 2 sin(k_a h / 2) / h), u_z is interpolated back with the same weights, Hasimoto's periodic-image term is
    added back, and the result is averaged over ``samples`` sub-cell positions. Viscosity and h cancel out.
    """
    h, mu = 1.0, 1.0
    shape = (n, n, n)
    periodic = np.array([True, True, True])
    lower = np.zeros(3)
    k = 2.0 * np.pi * sfft.fftfreq(n, d=h)
    g2 = (2.0 * np.sin(k * h / 2.0) / h) ** 2
    gx2, gy2, gz2 = np.meshgrid(g2, g2, g2, indexing="ij")
    gsum = gx2 + gy2 + gz2
    gsum[0, 0, 0] = 1.0
    transfer = (1.0 - gz2 / gsum) / (mu * gsum)
    transfer[0, 0, 0] = 0.0  # no mean flow: the periodic box's uniform counter-force
    rng = np.random.default_rng(12345)
    sigma = sigma_cells_ratio * h
    values = []
    for _ in range(samples):
        pos = np.array([[n / 2 + rng.uniform(0, 1), n / 2 + rng.uniform(0, 1), n / 2 + rng.uniform(0, 1)]])
        diam = np.array([0.0])
        force = np.zeros(shape)
        scratch = np.zeros((1, *shape))
        deposit(pos, diam, np.array([1.0]), 1, 2, force, h, lower, np.array(shape), periodic, sigma_cells_ratio,
                0.0, cut, scratch)
        uz = np.real(sfft.ifftn(sfft.fftn(force / h**3) * transfer))
        out = np.zeros(1)
        interpolate(pos, diam, 1, 2, uz, out, h, lower, np.array(shape), periodic, sigma_cells_ratio, 0.0, cut)
        values.append(out[0])
    periodic_mobility = float(np.mean(values))
    unbounded = periodic_mobility + HASIMOTO / (6.0 * math.pi * mu * n * h)
    return unbounded / gaussian_self_mobility(sigma, mu)


@njit(cache=True)
def corrected_drag_coefficient(beta, sigma, viscosity, discrete_factor, oseen):
    """beta / (1 - beta M_self): the drag coefficient to use with the interpolated (disturbed) fluid velocity [kg/s].

    M_self = discrete_factor * oseen / (6 pi^1.5 mu sigma) is the droplet's own self-mobility on the grid.
    """
    m_self = discrete_factor * oseen * gaussian_self_mobility(sigma, viscosity)
    return beta / (1.0 - min(beta * m_self, SELF_CORRECTION_CAP))


def thread_count() -> int:
    """Numba threads used by the parallel kernels (sizes the deposition scratch arrays)."""
    return numba.get_num_threads()
