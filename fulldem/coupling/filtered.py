"""The filtered smoothing kernel (``fulldem.kernel = "filtered"``, the default): trilinear deposits followed by a
separable discrete Gaussian filter of the grid fields, of the same variance as the direct stencil
(:mod:`fulldem.coupling.smoothing`).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit, prange
from scipy import fft as sfft

from .mobility import HASIMOTO, _stokes_transfer, gaussian_self_mobility
from .smoothing import CHUNKS, DEFAULT_CUT, _cic_pair, cic_deposit_many, cic_interpolate_many


def filter_taps(sigma_nodes, cut=DEFAULT_CUT):
    """Discrete Gaussian taps g_t ~ exp(-t^2 / (2 s^2)), |t| <= reach = max(1, floor(cut sigma_nodes)), summing to
    one, with s chosen (bisection) so that their variance sum t^2 g_t is exactly sigma_nodes^2: truncation does
    not narrow the kernel. Returns (reach, taps)."""
    reach = max(1, int(math.floor(cut * sigma_nodes)))
    t = np.arange(-reach, reach + 1)

    def taps_for(width):
        g = np.exp(-(t**2) / (2.0 * width**2))
        return g / g.sum()

    if sigma_nodes**2 >= np.mean(t**2):
        raise ValueError(f"filter_taps: sigma {sigma_nodes} nodes is too wide for {reach} nodes each way")
    low, high = 1e-3, 1e3
    for _ in range(200):
        mid = math.sqrt(low * high)
        if np.sum(t**2 * taps_for(mid)) < sigma_nodes**2:
            low = mid
        else:
            high = mid
    return reach, taps_for(math.sqrt(low * high))


def filter_matrix(n_cells, faces, periodic, sigma_nodes, cut=DEFAULT_CUT):
    """The 1-D filter of :class:`FilteredKernel` along one axis as a dense matrix G (nodes x nodes) [-].

    Taps of :func:`filter_taps`. Node j's content goes to nodes j + t; beyond a wall it is mirrored back: about the wall (cells), or about
    the boundary face (faces normal to a walled axis, whose boundary faces hold nothing: what would land on one
    stays at j). Every column then sums to one (conservation) and G is symmetric (adjointness), both checked here.
    Periodic axes wrap over n_cells nodes (a face array's last node, the copy of node 0, is left out).
    """
    n_nodes = n_cells + 1 if faces else n_cells
    reach, taps = filter_taps(sigma_nodes, cut)
    g = np.zeros((n_nodes, n_nodes))
    valid = range(n_cells) if periodic else (range(1, n_cells) if faces else range(n_cells))
    for j in valid:
        for t, w in zip(range(-reach, reach + 1), taps):
            k = j + t
            if periodic:
                k %= n_cells
            elif faces:
                for _ in range(64):
                    if k < 0:
                        k = -k
                    elif k > n_cells:
                        k = 2 * n_cells - k
                    else:
                        break
                if k == 0 or k == n_cells:
                    k = j
            else:
                for _ in range(64):
                    if k < 0:
                        k = -1 - k
                    elif k > n_cells - 1:
                        k = 2 * n_cells - 1 - k
                    else:
                        break
            g[k, j] += w
    cols = g.sum(axis=0)[list(valid)]
    if not (np.allclose(g, g.T, rtol=0.0, atol=1e-14) and np.allclose(cols, 1.0, rtol=0.0, atol=1e-14)):
        raise ValueError(f"filter_matrix: {n_cells} cells are too few for a filter of {reach} nodes each way")
    return g


def banded(g):
    """Rows of a sparse square matrix as (index (n, w) int64, weight (n, w)), padded with zero weights."""
    rows = [np.nonzero(row)[0] for row in g]
    width = max(1, max(len(r) for r in rows))
    index = np.zeros((g.shape[0], width), dtype=np.int64)
    weight = np.zeros((g.shape[0], width))
    for i, r in enumerate(rows):
        index[i, :len(r)] = r
        index[i, len(r):] = i
        weight[i, :len(r)] = g[i, r]
    return index, weight


@njit(cache=True, parallel=True)
def filter_axis(src, dst, axis, index, weight):
    """dst = G src along ``axis`` (G as rows ``index``, ``weight`` of :func:`banded`); dst is overwritten."""
    nx, ny, nz = src.shape
    width = index.shape[1]
    if axis == 0:
        for i in prange(nx):
            for j in range(ny):
                for k in range(nz):
                    dst[i, j, k] = 0.0
            for t in range(width):
                w = weight[i, t]
                if w == 0.0:
                    continue
                ii = index[i, t]
                for j in range(ny):
                    for k in range(nz):
                        dst[i, j, k] += w * src[ii, j, k]
    elif axis == 1:
        for i in prange(nx):
            for j in range(ny):
                for k in range(nz):
                    dst[i, j, k] = 0.0
                for t in range(width):
                    w = weight[j, t]
                    if w == 0.0:
                        continue
                    jj = index[j, t]
                    for k in range(nz):
                        dst[i, j, k] += w * src[i, jj, k]
    else:
        for i in prange(nx):
            for j in range(ny):
                for k in range(nz):
                    acc = 0.0
                    for t in range(width):
                        acc += weight[k, t] * src[i, j, index[k, t]]
                    dst[i, j, k] = acc


@njit(cache=True, parallel=True)
def filtered_self_weight(position, count, spacing, lower, periodic, gx, gy, gz, out):
    """out[p] = sum_cells W_p(cell)^2 for the filtered kernel W_p = G (trilinear weights of p) at the cells: a
    droplet's own deposit seen back at itself. gx, gy, gz: G G of each axis's cell filter (dense)."""
    n_chunks = min(count, CHUNKS)
    for chunk in prange(n_chunks):
        for p in range(chunk * count // n_chunks, (chunk + 1) * count // n_chunks):
            acc = 1.0
            for axis in range(3):
                g2 = gx if axis == 0 else (gy if axis == 1 else gz)
                i0, i1, w0, w1 = _cic_pair(position[p, axis], lower[axis], spacing, g2.shape[0], False, False,
                                           periodic[axis])
                acc *= w0 * w0 * g2[i0, i0] + 2.0 * w0 * w1 * g2[i0, i1] + w1 * w1 * g2[i1, i1]
            out[p] = acc


def filtered_width_allowed(sigma_cells) -> bool:
    """Whether the filtered kernel can have width sigma_cells [cells]: its trilinear step alone has variance 1/6
    cell^2 per axis, so the Gaussian filter after it needs sigma_cells^2 > 1/6."""
    return sigma_cells**2 > 1.0 / 6.0 + 1e-12


class FilteredKernel:
    """The two-step coupling kernel: trilinear (cloud-in-cell) weights to the nearest nodes of each staggered array,
    then a separable discrete Gaussian filter G on the grid (the "two-step" filtering of Capecelatro & Desjardins
    2013, J. Comput. Phys. 238, 1).

    Deposition is D = G C^T and interpolation I = C G with the same trilinear weights C and the symmetric G, so
    I = D^T exactly and every consistency property of the direct kernel holds (drag and reaction sum to zero; the
    pressure-gradient forces telescope), and G's columns sum to one, so deposition conserves what it spreads. The
    filter's width sigma_g = h sqrt(sigma_cells^2 - 1/6) makes the kernel's variance per axis (linear hat h^2/6
    plus sigma_g^2) that of the direct Gaussian of width sigma_cells h. The cost is per droplet 8 nodes instead of
    about 6^3, plus a few passes over the grid per field: at 10^5 droplets several times less than the direct
    kernel. Only droplets whose kernel width is sigma_cells h (d <= sigma_cells h / sigma_diameter) use it; wider
    ones use the direct Gaussian (see :meth:`fulldem.stepper.Simulation.deposit_many`).
    """

    def __init__(self, shape, periodic, sigma_cells, cut=DEFAULT_CUT):
        if not filtered_width_allowed(sigma_cells):
            raise ValueError(f"FilteredKernel: sigma_cells = {sigma_cells} must exceed 1/sqrt(6) = 0.408")
        self.shape = tuple(int(n) for n in shape)
        self.periodic = tuple(bool(p) for p in periodic)
        self.sigma_cells = float(sigma_cells)
        self.sigma_filter = math.sqrt(sigma_cells**2 - 1.0 / 6.0)  # in cells
        self.cut = cut
        # (faces?, axis) -> banded G; cell-centred nodes unless the array's component is that axis
        self.bands = {}
        g_cells = []
        for axis, n in enumerate(self.shape):
            for faces in (False, True):
                g = filter_matrix(n, faces, self.periodic[axis], self.sigma_filter, cut)
                self.bands[faces, axis] = banded(g)
                if not faces:
                    g_cells.append(np.ascontiguousarray(g @ g))
        self.g2 = tuple(g_cells)
        self._work = {}

    def _buffers(self, shape):
        if shape not in self._work:
            self._work[shape] = (np.empty(shape), np.empty(shape))
        return self._work[shape]

    def filter(self, field, component, out=None):
        """G applied to ``field``, the array of ``component`` (0..2 faces, 3 cells); into ``out`` if given."""
        a, b = self._buffers(field.shape)
        out = np.empty(field.shape) if out is None else out
        filter_axis(field, a, 0, *self.bands[component == 0, 0])
        filter_axis(a, b, 1, *self.bands[component == 1, 1])
        filter_axis(b, out, 2, *self.bands[component == 2, 2])
        return out

    def self_weight(self, position, count, spacing, lower, out):
        """out[p] = sum over cells of droplet p's filtered weight squared (see :func:`filtered_self_weight`)."""
        filtered_self_weight(position, count, spacing, np.asarray(lower, dtype=float),
                             np.asarray(self.periodic), *self.g2, out)


@functools.lru_cache(maxsize=16)
def filtered_mobility_factor(sigma_cells: float, cut: float = DEFAULT_CUT, n: int = 48, samples: int = 8):
    """:func:`discrete_mobility_factor` for the :class:`FilteredKernel`: self-mobility on the MAC grid, averaged
    over ``samples`` sub-cell positions (the filtered kernel's shape depends on where in its cell the droplet is),
    divided by the continuous Gaussian value for sigma = sigma_cells h."""
    h, mu = 1.0, 1.0
    shape = (n, n, n)
    periodic = np.array([True, True, True])
    lower = np.zeros(3)
    kernel = FilteredKernel(shape, (True,) * 3, sigma_cells, cut)
    transfer = _stokes_transfer(n, h, mu)
    rng = np.random.default_rng(12345)
    values = []
    components = np.array([2], dtype=np.int64)
    for _ in range(samples):
        pos = np.array([[n / 2 + rng.uniform(0, 1), n / 2 + rng.uniform(0, 1), n / 2 + rng.uniform(0, 1)]])
        raw = np.zeros(shape)
        cic_deposit_many(pos, np.ones((1, 1)), 1, components, (raw,), h, lower, np.array(shape), periodic,
                         np.zeros((1, 1, *shape)))
        force = kernel.filter(raw, 2)
        uz = kernel.filter(np.real(sfft.ifftn(sfft.fftn(force / h**3) * transfer)), 2)
        out = np.zeros((1, 1))
        cic_interpolate_many(pos, 1, components, (uz,), out, h, lower, np.array(shape), periodic)
        values.append(out[0, 0])
    unbounded = float(np.mean(values)) + HASIMOTO / (6.0 * math.pi * mu * n * h)
    return unbounded / gaussian_self_mobility(sigma_cells * h, mu)
