"""Two-way coupling between droplets and the grid: smoothed deposition, consistent interpolation, and the
correction for a droplet's own disturbance of the grid flow.

**Kernel.** A droplet's volume, volume flux and drag reaction are spread over the grid with a truncated, discretely
normalised Gaussian of width ``sigma = max(sigma_cells * h, sigma_diameter * d)``: droplets larger than a cell
(coalesced droplets reach 2 mm in cubic, 40 mm in deep) spread over as many cells as their size needs. The weights
are separable, ``w = w_x w_y w_z``, and sum to one over the nodes of each staggered array, so deposition conserves
what it spreads exactly. Wall-normal boundary faces (whose velocity is imposed) receive nothing; periodic axes wrap.
Two ways of applying it (``fulldem.kernel``): *direct*, a stencil of about (2 cut sigma / h)^3 nodes per droplet;
and *filtered* (the default, :class:`FilteredKernel`), trilinear weights to the 8 nearest nodes followed by a
separable discrete Gaussian filter of the grid fields, of the same variance, several times cheaper at 10^5
droplets. Droplets wider than ``sigma_cells h`` always use the direct stencil.

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
#: Chunks of droplets of the parallel interpolation (each allocates its stencil buffers once): a few per thread for
#: load balance on a shared machine. A constant, not numba.get_num_threads(), which would stop the kernels caching.
CHUNKS = 64


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
    # exp(-r^2 inv) at consecutive nodes r, r + 1, ... by the recurrence w <- w g, g <- g q (g = exp(-(2r + 1) inv),
    # q = exp(-2 inv)): three exps per axis instead of one per node. g grows like exp(2 reach inv) = exp(cut h/sigma)
    # at most, far from overflow for any kernel wider than a hundredth of a cell; narrower ones take exps per node.
    r = first - s
    recurrence = cut * spacing < 100.0 * sigma
    w = math.exp(-r * r * inv)
    g = math.exp(-(2.0 * r + 1.0) * inv) if recurrence else 0.0
    q = math.exp(-2.0 * inv) if recurrence else 0.0
    for node in range(first, last + 1):
        if not recurrence:
            r = node - s
            w = math.exp(-r * r * inv)
        if low <= node <= high:
            index_out[count] = node % n_nodes if periodic else node
            weight_out[count] = w
            total += w
            count += 1
        if recurrence:
            w *= g
            g *= q
    if count == 0:  # pathological: a droplet outside the box; use the nearest valid node
        node = min(max(int(round(s)), low), high) if not periodic else int(round(s)) % n_nodes
        index_out[0] = node
        weight_out[0] = 1.0
        return 1
    scale = 1.0 / total
    for c in range(count):
        weight_out[c] *= scale
    return count


@njit(cache=True)
def stencils(position, sigma, spacing, lower, shape, periodic, cut, idx, wts, counts):
    """Both 1-D weight sets of one droplet along each axis: ``[0, axis]`` at cell centres (cells, and the faces of
    the two other components), ``[1, axis]`` at the faces normal to that axis (the faces of component ``axis``).

    idx (2, 3, MAX_STENCIL) int64, wts (2, 3, MAX_STENCIL), counts (2, 3) int64: written. The weights of component
    c (0..2 faces, 3 cells) along axis a are set ``1 if c == a else 0``.
    """
    for axis in range(3):
        counts[0, axis] = weights_1d(position[axis], lower[axis], spacing, shape[axis], False, False,
                                     periodic[axis], sigma, cut, idx[0, axis], wts[0, axis])
        counts[1, axis] = weights_1d(position[axis], lower[axis], spacing, shape[axis], True, not periodic[axis],
                                     periodic[axis], sigma, cut, idx[1, axis], wts[1, axis])


#: Stencil-table modes of :func:`deposit_many` / :func:`interpolate_many`: compute the weights (no table), compute
#: and store them in the table, or load them from it. A fluid step's three passes are all at x^n: the first stores,
#: the other two load (the weights are the same numbers, so adjointness stays exact).
COMPUTE, STORE, LOAD = 0, 1, 2
#: Nodes per axis kept in a stencil table: 6 covers sigma <= 1.2 h with cut 2.5 (every droplet of up to 2.4 cells
#: at sigma_cells = 1); a wider droplet's row is marked not stored and recomputed.
TABLE_WIDTH = 6


def stencil_table(capacity, width=TABLE_WIDTH):
    """Empty stencil table (first node (cap, 2, 3) int64, node count (cap, 2, 3) int64, weights (cap, 2, 3, width))
    for the STORE / LOAD modes; rows as in :func:`stencils`."""
    return (np.zeros((capacity, 2, 3), dtype=np.int64), np.zeros((capacity, 2, 3), dtype=np.int64),
            np.zeros((capacity, 2, 3, width)))


#: No stencil table (COMPUTE mode).
NO_TABLE = stencil_table(0, 1)


@njit(cache=True)
def droplet_stencils(p, position, diameter, spacing, lower, shape, periodic, sigma_cells, sigma_diameter, cut, idx,
                     wts, counts, table_first, table_count, table_weights, mode):
    """:func:`stencils` of droplet p: computed (``mode`` COMPUTE), computed and stored in row p of the table
    (STORE), or loaded from it (LOAD).

    The nodes of one set are consecutive (modulo the axis length on periodic axes), so a row keeps the first node.
    """
    if mode == LOAD and table_count[p, 0, 0] > 0:
        for st in range(2):
            for axis in range(3):
                k = table_count[p, st, axis]
                counts[st, axis] = k
                n_nodes = shape[axis]
                first = table_first[p, st, axis]
                for i in range(k):
                    node = first + i
                    if periodic[axis] and node >= n_nodes:
                        node -= n_nodes
                    idx[st, axis, i] = node
                    wts[st, axis, i] = table_weights[p, st, axis, i]
        return
    sigma = kernel_width(diameter[p], spacing, sigma_cells, sigma_diameter)
    stencils(position[p], sigma, spacing, lower, shape, periodic, cut, idx, wts, counts)
    if mode == STORE:
        width = table_weights.shape[3]
        fits = True
        for st in range(2):
            for axis in range(3):
                fits = fits and counts[st, axis] <= width
        if not fits:
            table_count[p, 0, 0] = 0  # recomputed when loaded
            return
        for st in range(2):
            for axis in range(3):
                table_count[p, st, axis] = counts[st, axis]
                table_first[p, st, axis] = idx[st, axis, 0]
                for i in range(counts[st, axis]):
                    table_weights[p, st, axis, i] = wts[st, axis, i]


@njit(cache=True, inline="always")
def _stencil_sets(component):
    """Which stencil set (1: faces, 0: cell centres) each axis x, y, z uses for grid array ``component`` (0-2 the
    face arrays of u, v, w: faces along their own axis; 3 the cells)."""
    return (1 if component == 0 else 0), (1 if component == 1 else 0), (1 if component == 2 else 0)


@njit(cache=True)
def _zero_slab(buf, out, m):
    """Zero the part of one chunk's work slab ``buf`` (m, NX, NY, NZ) that the m arrays ``out`` cover."""
    for k in range(m):
        o = out[k]
        for i in range(o.shape[0]):
            for j in range(o.shape[1]):
                for l in range(o.shape[2]):
                    buf[k, i, j, l] = 0.0


@njit(cache=True)
def _add_slabs(scratch, k, i, o):
    """o[i] += the chunks' partial deposits scratch[:, k, i] of array k (one x-plane; the parallel sum's last
    step)."""
    for j in range(o.shape[1]):
        for l in range(o.shape[2]):
            acc = 0.0
            for chunk in range(scratch.shape[0]):
                acc += scratch[chunk, k, i, j, l]
            o[i, j, l] += acc


@njit(cache=True, parallel=True)
def deposit_many(position, diameter, values, count, components, out, spacing, lower, shape, periodic, sigma_cells,
                 sigma_diameter, cut, scratch, table_first, table_count, table_weights,
                 mode):
    """Add sum_p values[k, p] * w_p(node) to ``out[k]`` for k = 0..m-1, one stencil computation per droplet.

    values: (m, cap) per-droplet amounts (e.g. volume / cell volume); components: (m,) int64, the array of each
    quantity (0..2 faces of that component, 3 cells); out: tuple of m arrays of those shapes, added to.
    scratch: (n_chunks, m, NX, NY, NZ) work array with NX, NY, NZ >= every out[k]'s shape (NX = nx + 1 etc. fits
    all four), one slab per chunk of droplets so the parallel sum is race-free; its chunks are zeroed here.
    The weights are those of :func:`interpolate_many` (adjointness), normalised (conservation). table_*, mode:
    see :func:`droplet_stencils` (:data:`NO_TABLE`, COMPUTE: none). :func:`cic_deposit_many` is the trilinear
    counterpart (the first step of :class:`FilteredKernel`).
    """
    n_chunks = scratch.shape[0]
    m = components.shape[0]
    for chunk in prange(n_chunks):
        # stencil buffers once per chunk of droplets, not per droplet
        idx = np.empty((2, 3, MAX_STENCIL), dtype=np.int64)
        wts = np.empty((2, 3, MAX_STENCIL))
        counts = np.empty((2, 3), dtype=np.int64)
        buf = scratch[chunk]
        _zero_slab(buf, out, m)
        start = chunk * count // n_chunks
        stop = (chunk + 1) * count // n_chunks
        for p in range(start, stop):
            droplet_stencils(p, position, diameter, spacing, lower, shape, periodic, sigma_cells, sigma_diameter,
                             cut, idx, wts, counts, table_first, table_count, table_weights, mode)
            for k in range(m):
                v = values[k, p]
                if v == 0.0:
                    continue
                sx, sy, sz = _stencil_sets(components[k])
                nz = counts[sz, 2]
                for a in range(counts[sx, 0]):
                    ia = idx[sx, 0, a]
                    wa = wts[sx, 0, a] * v
                    for b in range(counts[sy, 1]):
                        ib = idx[sy, 1, b]
                        wab = wa * wts[sy, 1, b]
                        row = buf[k, ia, ib]
                        for cc in range(nz):
                            row[idx[sz, 2, cc]] += wab * wts[sz, 2, cc]
    for k in range(m):
        o = out[k]
        for i in prange(o.shape[0]):
            _add_slabs(scratch, k, i, o)


@njit(cache=True, parallel=True)
def interpolate_many(position, diameter, count, components, fields, out, own, spacing, lower, shape, periodic,
                     sigma_cells, sigma_diameter, cut, table_first, table_count, table_weights, mode):
    """out[k, p] = sum_nodes w_p(node) fields[k][node] for k = 0..m-1, one stencil computation per droplet.

    components: (m,) int64 (0..2 faces, 3 cells); fields: tuple of m arrays of those shapes; out: (m, cap).
    own: (cap,) or (0,): if not empty, also own[p] = sum_cells w_p(cell)^2 (see :func:`self_weight`).
    table_*, mode: see :func:`droplet_stencils` (:data:`NO_TABLE`, COMPUTE: none); trilinear counterpart:
    :func:`cic_interpolate_many`.
    """
    m = components.shape[0]
    n_chunks = min(count, CHUNKS)
    with_own = own.shape[0] > 0
    for chunk in prange(n_chunks):
        idx = np.empty((2, 3, MAX_STENCIL), dtype=np.int64)
        wts = np.empty((2, 3, MAX_STENCIL))
        counts = np.empty((2, 3), dtype=np.int64)
        start = chunk * count // n_chunks
        stop = (chunk + 1) * count // n_chunks
        for p in range(start, stop):
            droplet_stencils(p, position, diameter, spacing, lower, shape, periodic, sigma_cells, sigma_diameter,
                             cut, idx, wts, counts, table_first, table_count, table_weights, mode)
            for k in range(m):
                field = fields[k]
                sx, sy, sz = _stencil_sets(components[k])
                nz = counts[sz, 2]
                acc = 0.0
                for a in range(counts[sx, 0]):
                    ia = idx[sx, 0, a]
                    for b in range(counts[sy, 1]):
                        ib = idx[sy, 1, b]
                        wab = wts[sx, 0, a] * wts[sy, 1, b]
                        row = field[ia, ib]
                        for cc in range(nz):
                            acc += wab * wts[sz, 2, cc] * row[idx[sz, 2, cc]]
                out[k, p] = acc
            if with_own:
                own[p] = _sum_of_squares(wts, counts, 3)


@njit(cache=True)
def _cic_pair(x, lower, spacing, n_cells, staggered, wall_normal, periodic):
    """Linear (cloud-in-cell) weights of the two nodes around coordinate x: (i0, i1, w0, w1), w0 + w1 = 1.

    Nodes are cell centres (staggered = False) or faces (staggered = True) of an axis with n_cells cells;
    wall_normal: the two boundary faces of the wall-normal velocity component are excluded; periodic: indices wrap.
    On a walled axis a weight that would fall beyond the last valid node (the mirror half-cell next to a wall, or a
    wall-normal boundary face) goes to that node: then i1 = i0 and w1 = 0, so the weights always sum to one.
    """
    offset = 0.0 if staggered else 0.5
    s = (x - lower) / spacing - offset
    first = int(math.floor(s))
    f = s - first
    if periodic:
        i0 = first % n_cells
        i1 = i0 + 1
        if i1 == n_cells:
            i1 = 0
        return i0, i1, 1.0 - f, f
    high = n_cells if staggered else n_cells - 1
    low = 0
    if wall_normal:
        low, high = 1, high - 1
    if first < low:
        return low, low, 1.0, 0.0
    if first >= high:
        return high, high, 1.0, 0.0
    return first, first + 1, 1.0 - f, f


@njit(cache=True)
def _cic_nodes(position, p, spacing, lower, shape, periodic, nodes, weights):
    """Trilinear nodes of droplet p: nodes[st, axis, 0:2], weights[st, axis, 0:2] with st = 0 at cell centres and
    st = 1 at the faces normal to that axis (the layout of :func:`stencils`; always two nodes)."""
    for axis in range(3):
        for st in range(2):
            i0, i1, w0, w1 = _cic_pair(position[p, axis], lower[axis], spacing, shape[axis], st == 1,
                                       st == 1 and not periodic[axis], periodic[axis])
            nodes[st, axis, 0] = i0
            nodes[st, axis, 1] = i1
            weights[st, axis, 0] = w0
            weights[st, axis, 1] = w1


@njit(cache=True, parallel=True)
def cic_deposit_many(position, values, count, components, out, spacing, lower, shape, periodic, scratch):
    """:func:`deposit_many` with trilinear weights (:func:`_cic_pair`): two nodes per axis, fixed loops; the first
    step of :class:`FilteredKernel`. Same arguments, less the Gaussian's and the table's."""
    n_chunks = scratch.shape[0]
    m = components.shape[0]
    for chunk in prange(n_chunks):
        nodes = np.empty((2, 3, 2), dtype=np.int64)
        weights = np.empty((2, 3, 2))
        buf = scratch[chunk]
        _zero_slab(buf, out, m)
        for p in range(chunk * count // n_chunks, (chunk + 1) * count // n_chunks):
            _cic_nodes(position, p, spacing, lower, shape, periodic, nodes, weights)
            for k in range(m):
                v = values[k, p]
                if v == 0.0:
                    continue
                sx, sy, sz = _stencil_sets(components[k])
                l0, l1 = nodes[sz, 2, 0], nodes[sz, 2, 1]
                wl0, wl1 = weights[sz, 2, 0], weights[sz, 2, 1]
                for a in range(2):
                    ia = nodes[sx, 0, a]
                    wa = weights[sx, 0, a] * v
                    for b in range(2):
                        ib = nodes[sy, 1, b]
                        wab = wa * weights[sy, 1, b]
                        buf[k, ia, ib, l0] += wab * wl0
                        buf[k, ia, ib, l1] += wab * wl1
    for k in range(m):
        o = out[k]
        for i in prange(o.shape[0]):
            _add_slabs(scratch, k, i, o)


@njit(cache=True, parallel=True)
def cic_interpolate_many(position, count, components, fields, out, spacing, lower, shape, periodic):
    """:func:`interpolate_many` with trilinear weights (:func:`_cic_pair`; no self weight); the adjoint
    of :func:`cic_deposit_many` (the same weights: a node counted twice at a wall has weight 0 the second time)."""
    m = components.shape[0]
    n_chunks = min(count, CHUNKS)
    for chunk in prange(n_chunks):
        nodes = np.empty((2, 3, 2), dtype=np.int64)
        weights = np.empty((2, 3, 2))
        for p in range(chunk * count // n_chunks, (chunk + 1) * count // n_chunks):
            _cic_nodes(position, p, spacing, lower, shape, periodic, nodes, weights)
            for k in range(m):
                field = fields[k]
                sx, sy, sz = _stencil_sets(components[k])
                l0, l1 = nodes[sz, 2, 0], nodes[sz, 2, 1]
                wl0, wl1 = weights[sz, 2, 0], weights[sz, 2, 1]
                acc = 0.0
                for a in range(2):
                    ia = nodes[sx, 0, a]
                    wa = weights[sx, 0, a]
                    for b in range(2):
                        ib = nodes[sy, 1, b]
                        acc += wa * weights[sy, 1, b] * (wl0 * field[ia, ib, l0] + wl1 * field[ia, ib, l1])
                out[k, p] = acc


@njit(cache=True)
def _sum_of_squares(wts, counts, component):
    acc = 1.0
    for axis in range(3):
        st = 1 if component == axis else 0
        s2 = 0.0
        for a in range(counts[st, axis]):
            s2 += wts[st, axis, a] * wts[st, axis, a]
        acc *= s2
    return acc


def deposit(position, diameter, value, count, component, out, spacing, lower, shape, periodic, sigma_cells,
            sigma_diameter, cut, scratch):
    """Add sum_p value[p] * w_p(node) to ``out`` (cells if component == 3, else faces of that component).

    value: (cap,) per-droplet amount (e.g. volume / cell volume). scratch: (n_chunks, *out.shape) work array (one
    slab per chunk of droplets, which makes the parallel sum race-free). One quantity of :func:`deposit_many`.
    """
    deposit_many(position, diameter, np.asarray(value, dtype=float).reshape(1, -1), count,
                 np.array([component], dtype=np.int64), (out,), spacing, lower, shape, periodic, sigma_cells,
                 sigma_diameter, cut, scratch.reshape(scratch.shape[0], 1, *scratch.shape[1:]), *NO_TABLE, COMPUTE)


def interpolate(position, diameter, count, component, field, out, spacing, lower, shape, periodic, sigma_cells,
                sigma_diameter, cut):
    """out[p] = sum_nodes w_p(node) field[node] for the array of ``component`` (0..2 faces, 3 cells)."""
    values = np.empty((1, max(count, 1)))
    interpolate_many(position, diameter, count, np.array([component], dtype=np.int64), (field,), values, NO_OWN,
                     spacing, lower, shape, periodic, sigma_cells, sigma_diameter, cut, *NO_TABLE, COMPUTE)
    out[:count] = values[0, :count]


@njit(cache=True, parallel=True)
def self_weight(position, diameter, count, component, out, spacing, lower, shape, periodic, sigma_cells,
                sigma_diameter, cut):
    """out[p] = sum_nodes w_p(node)^2: a droplet's own deposit seen back at itself (to remove self-volume)."""
    n_chunks = min(count, CHUNKS)
    for chunk in prange(n_chunks):
        idx = np.empty((2, 3, MAX_STENCIL), dtype=np.int64)
        wts = np.empty((2, 3, MAX_STENCIL))
        counts = np.empty((2, 3), dtype=np.int64)
        for p in range(chunk * count // n_chunks, (chunk + 1) * count // n_chunks):
            sigma = kernel_width(diameter[p], spacing, sigma_cells, sigma_diameter)
            stencils(position[p], sigma, spacing, lower, shape, periodic, cut, idx, wts, counts)
            out[p] = _sum_of_squares(wts, counts, component)


#: Empty ``own`` argument of :func:`interpolate_many`: no self weights wanted.
NO_OWN = np.zeros(0)


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


# ------------------------------------------------------------------------------------------ filtered kernel
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


def _stokes_transfer(n, h, mu):
    """FFT symbol of the periodic MAC Stokes solve for the z-velocity from a z-force (no mean flow)."""
    k = 2.0 * np.pi * sfft.fftfreq(n, d=h)
    g2 = (2.0 * np.sin(k * h / 2.0) / h) ** 2
    gx2, gy2, gz2 = np.meshgrid(g2, g2, g2, indexing="ij")
    gsum = gx2 + gy2 + gz2
    gsum[0, 0, 0] = 1.0
    transfer = (1.0 - gz2 / gsum) / (mu * gsum)
    transfer[0, 0, 0] = 0.0  # no mean flow: the periodic box's uniform counter-force
    return transfer


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
    transfer = _stokes_transfer(n, h, mu)
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
