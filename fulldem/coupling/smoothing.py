"""Smoothed deposition onto the grid and consistent interpolation back to the droplets (the direct stencil and
the trilinear weights the filtered kernel starts from).

**Kernel.** A droplet's volume, volume flux and drag reaction are spread over the grid with a truncated, discretely
normalised Gaussian of width sigma = max(sigma_cells h, sigma_diameter d) (``smoothing_width`` in the code): droplets larger than a cell
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
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange


#: Stencil half-width in units of sigma (Gaussian weight at the edge e^(-cut^2/2) = 4 % of the peak for 2.5).
DEFAULT_CUT = 2.5


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
def weights_1d(x, lower, spacing, n_cells, staggered, wall_normal, periodic, smoothing_width, cut, index_out,
               weight_out):
    """Normalised 1-D Gaussian weights of the nodes near coordinate x; returns the number of nodes written.

    Nodes are cell centres (staggered = False) or faces (staggered = True) of an axis with n_cells cells.
    wall_normal: faces of the velocity component normal to this (walled) axis; its two boundary faces are excluded.
    periodic: indices wrap (face n_cells is face 0). Weights are written to weight_out, node indices to index_out.
    """
    offset = 0.0 if staggered else 0.5
    s = (x - lower) / spacing - offset  # position in node units
    reach = cut * smoothing_width / spacing
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
    inv = 1.0 / (2.0 * (smoothing_width / spacing) ** 2)
    # exp(-r^2 inv) at consecutive nodes r, r + 1, ... by the recurrence w <- w g, g <- g q (g = exp(-(2r + 1) inv),
    # q = exp(-2 inv)): three exps per axis instead of one per node. g grows like exp(2 reach inv) = exp(cut h/sigma)
    # at most, far from overflow for any kernel wider than a hundredth of a cell; narrower ones take exps per node.
    r = first - s
    recurrence = cut * spacing < 100.0 * smoothing_width
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
def stencils(position, smoothing_width, spacing, lower, shape, periodic, cut, idx, wts, counts):
    """Both 1-D weight sets of one droplet along each axis: ``[0, axis]`` at cell centres (cells, and the faces of
    the two other components), ``[1, axis]`` at the faces normal to that axis (the faces of component ``axis``).

    idx (2, 3, MAX_STENCIL) int64, wts (2, 3, MAX_STENCIL), counts (2, 3) int64: written. The weights of component
    c (0..2 faces, 3 cells) along axis a are set ``1 if c == a else 0``.
    """
    for axis in range(3):
        counts[0, axis] = weights_1d(position[axis], lower[axis], spacing, shape[axis], False, False,
                                     periodic[axis], smoothing_width, cut, idx[0, axis], wts[0, axis])
        counts[1, axis] = weights_1d(position[axis], lower[axis], spacing, shape[axis], True, not periodic[axis],
                                     periodic[axis], smoothing_width, cut, idx[1, axis], wts[1, axis])


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
    smoothing_width = kernel_width(diameter[p], spacing, sigma_cells, sigma_diameter)
    stencils(position[p], smoothing_width, spacing, lower, shape, periodic, cut, idx, wts, counts)
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
def _cic_pair(x, lower, spacing, n_cells, staggered, wall_normal, periodic, wall_faces=False):
    """Linear (cloud-in-cell) weights of the two nodes around coordinate x: (i0, i1, w0, w1), w0 + w1 = 1.

    Nodes are cell centres (staggered = False) or faces (staggered = True) of an axis with n_cells cells;
    wall_normal: the two boundary faces of the wall-normal velocity component are excluded, unless wall_faces
    (``fulldem.near_wall = "wall"``: they take their linear weights like any face, so that a field whose boundary
    faces hold zero, the wall-normal velocity, goes to zero at the wall); periodic: indices wrap.
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
    if wall_normal and not wall_faces:
        low, high = 1, high - 1
    if first < low:
        return low, low, 1.0, 0.0
    if first >= high:
        return high, high, 1.0, 0.0
    return first, first + 1, 1.0 - f, f


@njit(cache=True)
def _cic_nodes(position, p, spacing, lower, shape, periodic, nodes, weights, wall_faces=False):
    """Trilinear nodes of droplet p: nodes[st, axis, 0:2], weights[st, axis, 0:2] with st = 0 at cell centres and
    st = 1 at the faces normal to that axis (the layout of :func:`stencils`; always two nodes). wall_faces: the
    wall-normal boundary faces take their weights (:func:`_cic_pair`)."""
    for axis in range(3):
        for st in range(2):
            i0, i1, w0, w1 = _cic_pair(position[p, axis], lower[axis], spacing, shape[axis], st == 1,
                                       st == 1 and not periodic[axis], periodic[axis], wall_faces)
            nodes[st, axis, 0] = i0
            nodes[st, axis, 1] = i1
            weights[st, axis, 0] = w0
            weights[st, axis, 1] = w1


@njit(cache=True, parallel=True)
def cic_deposit_many(position, values, count, components, out, spacing, lower, shape, periodic, scratch,
                     wall_faces=False):
    """:func:`deposit_many` with trilinear weights (:func:`_cic_pair`): two nodes per axis, fixed loops; the first
    step of :class:`FilteredKernel`. Same arguments, less the Gaussian's and the table's. wall_faces: the
    wall-normal boundary faces take their share (which the filter then drops: the wall takes it)."""
    n_chunks = scratch.shape[0]
    m = components.shape[0]
    for chunk in prange(n_chunks):
        nodes = np.empty((2, 3, 2), dtype=np.int64)
        weights = np.empty((2, 3, 2))
        buf = scratch[chunk]
        _zero_slab(buf, out, m)
        for p in range(chunk * count // n_chunks, (chunk + 1) * count // n_chunks):
            _cic_nodes(position, p, spacing, lower, shape, periodic, nodes, weights, wall_faces)
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
def cic_interpolate_many(position, count, components, fields, out, spacing, lower, shape, periodic, wall_faces=False):
    """:func:`interpolate_many` with trilinear weights (:func:`_cic_pair`; no self weight); the adjoint
    of :func:`cic_deposit_many` with the same ``wall_faces`` (the same weights: a node counted twice at a wall has
    weight 0 the second time)."""
    m = components.shape[0]
    n_chunks = min(count, CHUNKS)
    for chunk in prange(n_chunks):
        nodes = np.empty((2, 3, 2), dtype=np.int64)
        weights = np.empty((2, 3, 2))
        for p in range(chunk * count // n_chunks, (chunk + 1) * count // n_chunks):
            _cic_nodes(position, p, spacing, lower, shape, periodic, nodes, weights, wall_faces)
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
            smoothing_width = kernel_width(diameter[p], spacing, sigma_cells, sigma_diameter)
            stencils(position[p], smoothing_width, spacing, lower, shape, periodic, cut, idx, wts, counts)
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


def thread_count() -> int:
    """Numba threads used by the parallel kernels (sizes the deposition scratch arrays)."""
    return numba.get_num_threads()
