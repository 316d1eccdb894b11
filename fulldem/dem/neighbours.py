"""Verlet neighbour lists for polydisperse droplets, built by cell binning.

A list holds every pair closer than (d_i + d_j)/2 + skin at build time, in compressed-sparse-row form: the partners
of droplet i are ``index[start[i]:start[i + 1]]``. It stays valid while no droplet has moved (plus grown in radius)
by more than skin/2 since the build (:func:`needs_rebuild`), so contacts are found without searching cells every step.

* *half* list: each pair once (for pair loops that update both droplets);
* *full* list: each pair in both rows (for loops over droplets that write only their own row: no write races).

Polydispersity. Cells have the side ``cell_size >= d_cell + skin`` where d_cell is a typical large diameter (the
99th percentile by default, :func:`cell_size_for`): a pair of droplets no larger than d_cell is always found in the
3 x 3 x 3 block of cells around either one. A pair that involves a larger droplet is owned by the larger of the two,
which searches every cell within (d_large + skin) of its own; the smaller one does not look for it. So nothing is
missed however large the coalesced droplets grow (2 mm in the cubic case, 40 mm in the deep one), and the many fed
droplets still search only 27 small cells.

Periodic axes use the minimum image (the box must be at least twice the largest cutoff long on those axes); the
cells of a periodic axis divide it exactly. On bounded axes the cells span the droplets' bounding box only (the
settler's droplets occupy a small part of the box early on), and positions outside are clamped into the end cells,
which cannot lose a pair (clamping never increases a distance in cell units).

Arrays: ``start`` (n + 1,) int64, ``index`` (capacity,) int32 (capacity >= start[n], grown by doubling when a
build needs more), positions [m] (cap, 3), diameters [m] (cap,).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


#: Cells per droplet above which the cell size is enlarged (keeps the cell arrays small in mostly empty boxes).
MAX_CELLS_PER_DROPLET = 8

#: A re-sort changes the slowest axis of the cell order only if the new one's fullest slab holds fewer than this
#: fraction of the current one's droplets (no flip-flopping between nearly equal axes).
AXIS_SWITCH = 0.8

#: Smallest row width of the one-pass scan's scratch array (partners of one droplet among the small ones).
MIN_ROW_STRIDE = 8

#: Chunks of the parallel bounding box (a few per thread; below 16 droplets a chunk, one).
BOX_CHUNKS = 8


def cell_size_for(diameter, skin, quantile=0.99, cap=None) -> float:
    """Cell side [m] for binning: the ``quantile`` of the diameters [m] (at most ``cap`` [m]) plus the skin [m].

    Droplets larger than the cell's diameter are handled by a wider search of their own, so any value is correct;
    this one keeps the common droplets' search to 27 cells of about their own size.
    """
    diameter = np.asarray(diameter, dtype=float)
    typical = float(np.quantile(diameter, quantile)) if diameter.size else 0.0
    if cap is not None:
        typical = min(typical, float(cap))
    return typical + float(skin)


@njit(cache=True, inline="always")
def _minimum_image(delta, period, inverse_period):
    """Shortest periodic copy of a separation component (period 0 with inverse 0: a bounded axis, unchanged)."""
    return delta - period * np.rint(delta * inverse_period)


@njit(cache=True, inline="always")
def _axis_range(cell, reach, ncell, periodic):
    """Cells to visit along one axis: (first, last, wrap). Periodic: each cell at most once, even if reach is wide."""
    if periodic:
        if 2 * reach + 1 >= ncell:
            return 0, ncell - 1, False
        return cell - reach, cell + reach, True
    return max(0, cell - reach), min(ncell - 1, cell + reach), False


@njit(cache=True, parallel=True)
def bounding_box(position, count):
    """Lowest and highest coordinates (3,), (3,) [m] of the first ``count`` droplets (one pass, in parallel chunks:
    a minimum does not depend on the order it is taken in)."""
    chunks = BOX_CHUNKS if count >= 16 * BOX_CHUNKS else 1
    lows = np.full((chunks, 3), np.inf)
    highs = np.full((chunks, 3), -np.inf)
    for c in prange(chunks):
        for p in range(c * count // chunks, (c + 1) * count // chunks):
            for a in range(3):
                lows[c, a] = min(lows[c, a], position[p, a])
                highs[c, a] = max(highs[c, a], position[p, a])
    low = np.full(3, np.inf)
    high = np.full(3, -np.inf)
    for c in range(chunks):
        for a in range(3):
            low[a] = min(low[a], lows[c, a])
            high[a] = max(high[a], highs[c, a])
    return low, high


@njit(cache=True)
def fullest_slabs(cell_xyz, count, shape):
    """The most droplets in one slab of cells across each column of ``cell_xyz`` (column k: cell coordinates along
    an axis with ``shape[k]`` cells), (3,) int64, in one pass."""
    histogram = np.zeros((3, max(shape[0], shape[1], shape[2])), dtype=np.int64)
    for p in range(count):
        for k in range(3):
            histogram[k, cell_xyz[p, k]] += 1
    most = np.zeros(3, dtype=np.int64)
    for k in range(3):
        most[k] = histogram[k].max()
    return most


@njit(cache=True, parallel=True)
def bin_droplets(position, count, grid_lower, cell_size, shape, periodic, axes, cell_xyz, cell_id):
    """Cell coordinates (count, 3) int64 and linear cell index (count,) of each droplet (written in place).

    Periodic axes wrap; bounded axes clamp to the end cells. The axes are taken in the order ``axes`` (fastest
    first): column k of cell_xyz is the coordinate along axis axes[k], and the linear index is
    c_0 + n_0 (c_1 + n_1 c_2) in that order.
    """
    for p in prange(count):
        linear = 0
        stride = 1
        for k in range(3):
            a = axes[k]
            c = int(math.floor((position[p, a] - grid_lower[a]) / cell_size[a]))
            n = shape[a]
            if periodic[a]:
                c = c % n
                if c < 0:
                    c += n
            else:
                c = min(max(c, 0), n - 1)
            cell_xyz[p, k] = c
            linear += c * stride
            stride *= n
        cell_id[p] = linear


@njit(cache=True)
def counting_sort(cell_id, count, cell_start, cell_droplets, slot):
    """Stable counting sort by cell: the droplets of cell c are ``cell_droplets[cell_start[c]:cell_start[c + 1]]``,
    in increasing index order, and droplet p sits at ``cell_droplets[slot[p]]``.

    cell_start (ncell + 1,) int64, cell_droplets (>= count,) int64 and slot (>= count,) int64 are written in place.
    """
    ncell = cell_start.shape[0] - 1
    for c in range(ncell + 1):
        cell_start[c] = 0
    for p in range(count):
        cell_start[cell_id[p] + 1] += 1
    for c in range(ncell):
        cell_start[c + 1] += cell_start[c]
    # cell_start[c] is used as the insertion cursor of cell c, then shifted back
    for p in range(count):
        c = cell_id[p]
        cell_droplets[cell_start[c]] = p
        slot[p] = cell_start[c]
        cell_start[c] += 1
    for c in range(ncell, 0, -1):
        cell_start[c] = cell_start[c - 1]
    cell_start[0] = 0


@njit(cache=True, inline="always")
def _pair_within(position, diameter, i, j, skin, periodic_any, period, inverse_period):
    dx = position[j, 0] - position[i, 0]
    dy = position[j, 1] - position[i, 1]
    dz = position[j, 2] - position[i, 2]
    if periodic_any:
        dx = _minimum_image(dx, period[0], inverse_period[0])
        dy = _minimum_image(dy, period[1], inverse_period[1])
        dz = _minimum_image(dz, period[2], inverse_period[2])
    cut = 0.5 * (diameter[i] + diameter[j]) + skin
    return dx * dx + dy * dy + dz * dz < cut * cut


@njit(cache=True, inline="always")
def _scan_range(i, first, last, position, diameter, is_large, any_large, skin, periodic_any, period,
                inverse_period, cell_droplets, rows, cursor, limit):
    """Partners of small droplet i among ``cell_droplets[first:last]``, written to ``rows`` from ``cursor`` on
    while below ``limit``; returns (found, cursor): all partners are counted, written or not."""
    found = 0
    for k in range(first, last):
        j = cell_droplets[k]
        keep = j != i
        if any_large:
            keep = keep & (not is_large[j])
        keep = keep & _pair_within(position, diameter, i, j, skin, periodic_any, period, inverse_period)
        if keep & (cursor < limit):
            rows[cursor] = j
            cursor += 1
        found += keep
    return found, cursor


@njit(cache=True, parallel=True)
def scan_small(position, diameter, count, is_large, skin, period, inverse_period, shape, periodic, cell_xyz,
               cell_start, cell_droplets, slot, half, rows, stride, counts):
    """Pairs between droplets of at most the cell's diameter, from the 27 cells around each droplet, in one pass.

    Writes at most ``stride`` partners of droplet i from ``rows[i * stride]`` on (a count x stride scratch array,
    compacted by :func:`compact_rows`) and counts[i] = all its partners; more than ``stride`` means the row was cut
    and the caller must scan again with a wider stride. Large droplets are skipped (their pairs are found by
    :func:`scan_large`). Along the fastest axis the neighbour cells of a row are consecutive in the sorted order
    (unless that axis is periodic and wraps), so they are scanned as one range.

    A half list stores a pair in the row of the droplet in the lower cell (linear index), or of the lower droplet
    index within one cell: each droplet scans only the 13 neighbour cells above its own and the droplets after it
    in its own cell (from ``slot[i] + 1``: a cell's droplets are in index order), half the distance tests of the
    full stencil. A partner's index may then be lower than the row's; once the droplets are sorted by cell (as the
    stepper keeps them) it almost always is higher.
    """
    periodic_any = periodic[0] or periodic[1] or periodic[2]
    any_large = False
    for p in range(count):
        if is_large[p]:
            any_large = True
            break
    for i in prange(count):
        if is_large[i]:
            counts[i] = 0
            continue
        found = 0
        cursor = i * stride
        limit = cursor + stride
        own_row = shape[0] * (cell_xyz[i, 1] + shape[1] * cell_xyz[i, 2])
        own_cell = own_row + cell_xyz[i, 0]
        zf, zl, zw = _axis_range(cell_xyz[i, 2], 1, shape[2], periodic[2])
        yf, yl, yw = _axis_range(cell_xyz[i, 1], 1, shape[1], periodic[1])
        xf, xl, xw = _axis_range(cell_xyz[i, 0], 1, shape[0], periodic[0])
        for tz in range(zf, zl + 1):
            cz = tz % shape[2] if zw else tz
            for ty in range(yf, yl + 1):
                cy = ty % shape[1] if yw else ty
                row = shape[0] * (cy + shape[1] * cz)
                if half and row < own_row:
                    continue
                if not xw:
                    first = cell_start[row + xf]
                    if half and row == own_row:
                        first = slot[i] + 1  # skips the row's cells below i's own and i's predecessors in it
                    got, cursor = _scan_range(i, first, cell_start[row + xl + 1], position, diameter, is_large,
                                              any_large, skin, periodic_any, period, inverse_period, cell_droplets,
                                              rows, cursor, limit)
                    found += got
                else:
                    for tx in range(xf, xl + 1):
                        cell = tx % shape[0] + row
                        first = cell_start[cell]
                        if half and row == own_row:
                            if cell < own_cell:
                                continue
                            if cell == own_cell:
                                first = slot[i] + 1
                        got, cursor = _scan_range(i, first, cell_start[cell + 1], position, diameter, is_large,
                                                  any_large, skin, periodic_any, period, inverse_period,
                                                  cell_droplets, rows, cursor, limit)
                        found += got
        counts[i] = found


@njit(cache=True, parallel=True)
def compact_rows(scratch, stride, counts, start, count, index):
    """Copy row i of a one-pass :func:`scan_small` (``scratch[i * stride:]``, counts[i] entries) to
    ``index[start[i]:]``."""
    for i in prange(count):
        base = i * stride
        to = start[i]
        for k in range(counts[i]):
            index[to + k] = scratch[base + k]


@njit(cache=True, inline="always")
def _scan_large_one(i, position, diameter, skin, period, inverse_period, cell_size, shape, periodic, cell_xyz,
                    cell_start, cell_droplets, is_large, half, fill, index, cursor, counts):
    """The pairs large droplet i owns (see :func:`scan_large`)."""
    reach = diameter[i] + skin
    zf, zl, zw = _axis_range(cell_xyz[i, 2], int(math.ceil(reach / cell_size[2])), shape[2], periodic[2])
    yf, yl, yw = _axis_range(cell_xyz[i, 1], int(math.ceil(reach / cell_size[1])), shape[1], periodic[1])
    xf, xl, xw = _axis_range(cell_xyz[i, 0], int(math.ceil(reach / cell_size[0])), shape[0], periodic[0])
    for tz in range(zf, zl + 1):
        cz = tz % shape[2] if zw else tz
        for ty in range(yf, yl + 1):
            cy = ty % shape[1] if yw else ty
            row = shape[0] * (cy + shape[1] * cz)
            for tx in range(xf, xl + 1):
                cx = tx % shape[0] if xw else tx
                cell = cx + row
                for k in range(cell_start[cell], cell_start[cell + 1]):
                    j = cell_droplets[k]
                    if j == i:
                        continue
                    if is_large[j] and (diameter[j] > diameter[i] or (diameter[j] == diameter[i] and j < i)):
                        continue  # j owns this pair
                    if not _pair_within(position, diameter, i, j, skin, True, period, inverse_period):
                        continue
                    if fill:
                        index[cursor[i]] = j
                        cursor[i] += 1
                    counts[i] += 1
                    if not half:
                        if fill:
                            index[cursor[j]] = i
                            cursor[j] += 1
                        counts[j] += 1


@njit(cache=True)
def scan_large(position, diameter, large, skin, period, inverse_period, cell_size, shape, periodic, cell_xyz,
               cell_start, cell_droplets, is_large, half, index, cursor, counts):
    """Pairs owned by the droplets larger than the cell's diameter (serial; :func:`scan_large_half` runs a half
    list's in parallel).

    A pair with a large droplet is owned by the larger of the two (ties: the lower index), which searches every cell
    within d_large + skin. Count pass (``index`` of length 0): adds to counts. Fill pass: appends to rows at
    ``cursor`` (and advances it); a full list also appends the owner to the partner's row.
    """
    fill = index.shape[0] > 0
    for q in range(large.shape[0]):
        _scan_large_one(large[q], position, diameter, skin, period, inverse_period, cell_size, shape, periodic,
                        cell_xyz, cell_start, cell_droplets, is_large, half, fill, index, cursor, counts)


@njit(cache=True, parallel=True)
def scan_large_half(position, diameter, large, skin, period, inverse_period, cell_size, shape, periodic, cell_xyz,
                    cell_start, cell_droplets, is_large, half, index, cursor, counts):
    """:func:`scan_large` for a half list, in parallel: each large droplet writes only its own row and count."""
    fill = index.shape[0] > 0
    for q in prange(large.shape[0]):
        _scan_large_one(large[q], position, diameter, skin, period, inverse_period, cell_size, shape, periodic,
                        cell_xyz, cell_start, cell_droplets, is_large, True, fill, index, cursor, counts)


@njit(cache=True)
def longest_jump(start, index, count):
    """Largest |j - i| over the list's entries (i's row holding j)."""
    jump = 0
    for i in range(count):
        for k in range(start[i], start[i + 1]):
            jump = max(jump, abs(index[k] - i))
    return jump


@njit(cache=True, parallel=True)
def max_travel(position, reference_position, diameter, reference_diameter, count, period, inverse_period):
    """Largest |x - x_ref| + max(0, (d - d_ref)/2) over the droplets [m] (minimum image on periodic axes).

    The list stays valid while this is at most skin/2: two droplets then cannot have closed their gap by more
    than the skin.
    """
    worst = 0.0
    for p in prange(count):
        d2 = 0.0
        for a in range(3):
            delta = _minimum_image(position[p, a] - reference_position[p, a], period[a], inverse_period[a])
            d2 += delta * delta
        worst = max(worst, math.sqrt(d2) + max(0.0, 0.5 * (diameter[p] - reference_diameter[p])))
    return worst


@njit(cache=True, parallel=True)
def wrap_positions(position, count, lower, period):
    """Move droplets back into the box on periodic axes (period [m] > 0 there, 0 on bounded axes)."""
    for p in prange(count):
        for a in range(3):
            if period[a] > 0.0:
                position[p, a] = lower[a] + (position[p, a] - lower[a]) % period[a]


def _grow(array, needed, fill=0):
    """``array`` if it holds ``needed`` entries, else a doubled copy-free replacement (contents not kept)."""
    if array.shape[0] >= needed:
        return array
    size = max(array.shape[0], 1)
    while size < needed:
        size *= 2
    shape = (size,) + array.shape[1:]
    return np.full(shape, fill, dtype=array.dtype)


class NeighbourList:
    """A Verlet list with its binning work arrays, rebuilt in place.

    Attributes: ``start`` (n + 1,) int64 and ``index`` (capacity,) int32 (CSR rows; capacity doubles when a build
    needs more), ``half`` (bool), ``skin`` [m], ``count`` (droplets at the last build), ``builds`` (number of
    builds), ``reference_position`` (cap, 3) [m] and ``reference_diameter`` (cap,) [m] at the last build,
    ``cell_size`` (3,) [m] and ``shape`` (3,) of the last binning, ``longest_row`` (most partners of a droplet),
    ``longest_jump`` (largest |j - i| of an entry: how far apart in memory partners lie, see
    :func:`fulldem.dem.pairs.slab_count`).

    Geometry: ``box_lower`` (3,) [m], ``box_size`` (3,) [m], ``periodic`` (3,) bool.
    """

    def __init__(self, box_lower, box_size, periodic, skin, half=True, cell_diameter=None, index_capacity=1024):
        self.box_lower = np.asarray(box_lower, dtype=float).copy()
        self.box_size = np.asarray(box_size, dtype=float).copy()
        self.periodic = np.asarray(periodic, dtype=bool).copy()
        self.period = np.where(self.periodic, self.box_size, 0.0)
        self.inverse_period = np.where(self.periodic, 1.0 / self.box_size, 0.0)
        if skin <= 0.0:
            raise ValueError(f"neighbours: skin = {skin} m must be positive")
        self.skin = float(skin)
        self.half = bool(half)
        self.cell_diameter = cell_diameter  # None: the 99th percentile of the diameters at each build
        self.start = np.zeros(1, dtype=np.int64)
        self.index = np.zeros(max(int(index_capacity), 1), dtype=np.int32)
        self.count = 0
        self.longest_row = 0
        self.longest_jump = 0
        self.builds = 0
        self.reference_position = np.zeros((0, 3))
        self.reference_diameter = np.zeros(0)
        self.cell_size = np.ones(3)
        self.shape = np.ones(3, dtype=np.int64)
        self.axes = np.array([0, 1, 2], dtype=np.int64)  # cell numbering order, fastest first (see spatial_order)
        self._cell_xyz = np.zeros((0, 3), dtype=np.int64)
        self._cell_id = np.zeros(0, dtype=np.int64)
        self._cell_start = np.zeros(2, dtype=np.int64)
        self._cell_droplets = np.zeros(0, dtype=np.int64)
        self._slot = np.zeros(0, dtype=np.int64)
        self._counts = np.zeros(0, dtype=np.int64)
        self._extra = np.zeros(0, dtype=np.int64)
        self._cursor = np.zeros(0, dtype=np.int64)
        self._is_large = np.zeros(0, dtype=np.bool_)
        self._stride = MIN_ROW_STRIDE
        self._scratch = np.zeros(0, dtype=np.int32)

    # ------------------------------------------------------------------ binning
    def _layout(self, position, diameter, count):
        """Choose the cells: side >= d_cell + skin, exact division of periodic axes, bounding box on bounded axes."""
        if self.cell_diameter is None:
            d_cell = float(np.quantile(diameter[:count], 0.99)) if count else 0.0
        else:
            d_cell = float(self.cell_diameter)
        side = d_cell + self.skin
        low, high = bounding_box(position, count)
        lo = np.where(self.periodic, self.box_lower, low if count else self.box_lower)
        extent = np.where(self.periodic, self.box_size, high - low if count else 0.0)
        budget = MAX_CELLS_PER_DROPLET * count + 1000
        while True:
            shape = np.where(self.periodic, np.maximum(1, np.floor(extent / side)), np.floor(extent / side) + 1)
            shape = np.maximum(shape, 1).astype(np.int64)
            if np.prod(shape.astype(float)) <= budget:
                break
            side *= 1.25
        cell = np.where(self.periodic, extent / shape, side)
        self.grid_lower, self.cell_size, self.shape, self.cell_diameter_used = lo, cell, shape, d_cell
        return d_cell

    def _bin(self, position, count):
        self._cell_xyz = _grow(self._cell_xyz, count)
        self._cell_id = _grow(self._cell_id, count)
        self._cell_droplets = _grow(self._cell_droplets, count)
        self._slot = _grow(self._slot, count)
        ncell = int(np.prod(self.shape))
        self._cell_start = _grow(self._cell_start, ncell + 1)
        cell_start = self._cell_start[: ncell + 1]
        bin_droplets(position, count, self.grid_lower, self.cell_size, self.shape, self.periodic, self.axes,
                     self._cell_xyz, self._cell_id)
        counting_sort(self._cell_id, count, cell_start, self._cell_droplets, self._slot)
        return cell_start

    def spatial_order(self, position, diameter, count) -> np.ndarray:
        """A permutation (count,) that sorts the droplets by cell, for memory locality in the kernels.

        The cells are taken in lexicographic order with the *slowest* axis chosen as the one whose fullest slab of
        cells holds the fewest droplets (a change needs fewer than :data:`AXIS_SWITCH` times the current one's). List
        partners then lie at most about two such slabs apart in memory, which is what the half-list kernels' slabs
        must exceed to run in parallel (:func:`fulldem.dem.pairs.slab_count`). A flat layer of droplets under the roof
        sorted with z slowest puts a whole layer between partners (a third of the droplets in the simple case),
        leaving one slab per phase: one thread. The order is kept (``axes``) for the following builds, whose cells
        are numbered the same way, so a half list's rows hold partners ahead in memory (measured 15 % faster in a
        dense bed than numbering the cells differently from the memory order).
        """
        self._layout(position, diameter, count)
        self._bin(position, count)
        if count == 0:
            return np.zeros(0, dtype=np.int64)
        slabs = fullest_slabs(self._cell_xyz, count, self.shape[self.axes])
        fullest = {int(self.axes[k]): int(slabs[k]) for k in range(3)}
        current = int(self.axes[2])
        slowest = min(fullest, key=fullest.get)
        if fullest[slowest] < AXIS_SWITCH * fullest[current]:
            self.axes = np.array([a for a in range(3) if a != slowest] + [slowest], dtype=np.int64)
            self._bin(position, count)
        return self._cell_droplets[:count].copy()

    # ------------------------------------------------------------------ building
    def build(self, position, diameter, count) -> None:
        """(Re)build the list for the first ``count`` droplets (positions [m] (cap, 3), diameters [m] (cap,))."""
        d_cell = self._layout(position, diameter, count)
        largest = float(diameter[:count].max()) if count else 0.0
        cut = largest + self.skin
        if np.any(self.periodic & (self.box_size < 2.0 * cut)):
            raise ValueError(f"neighbours: periodic box {tuple(self.box_size)} m is shorter than twice the largest "
                             f"cutoff {cut} m; the minimum image would miss pairs")
        cell_start = self._bin(position, count)
        self._is_large = _grow(self._is_large, count)
        is_large = self._is_large
        is_large[:count] = diameter[:count] > d_cell
        large = np.flatnonzero(is_large[:count])
        large_scan = scan_large_half if self.half else scan_large
        self._counts = _grow(self._counts, count)
        self._extra = _grow(self._extra, count)
        self._cursor = _grow(self._cursor, count)
        counts, extra = self._counts, self._extra
        if self.start.shape[0] != count + 1:
            self.start = np.zeros(count + 1, dtype=np.int64)
        start = self.start
        no_index = np.zeros(0, dtype=np.int32)
        args = (self.skin, self.period, self.inverse_period)
        # the scans see the axes in the numbering order (their coordinates, sizes and periodicity permuted alike)
        geometry = (self.shape[self.axes], self.periodic[self.axes], self._cell_xyz, cell_start, self._cell_droplets)
        # one pass into rows of a fixed width (wide enough for the last build's rows, with a margin), then compacted;
        # a cut row (rare: the packing densified) repeats the scan with the width it needed
        while True:
            stride = self._stride
            self._scratch = _grow(self._scratch, count * stride)
            scan_small(position, diameter, count, is_large, *args, *geometry, self._slot, self.half, self._scratch,
                       stride, counts)
            widest = int(counts[:count].max()) if count else 0
            self._stride = max(MIN_ROW_STRIDE, widest + widest // 2)
            if widest <= stride:
                break
        extra[:count] = 0
        if large.size:
            large_scan(position, diameter, large, *args, self.cell_size[self.axes], *geometry, is_large, self.half,
                       no_index, self._cursor, extra)
        start[0] = 0
        np.cumsum(counts[:count] + extra[:count], out=start[1:])
        total = int(start[count])
        if total > self.index.shape[0]:
            self.index = _grow(self.index, total)
        compact_rows(self._scratch, stride, counts, start, count, self.index)
        if large.size:
            cursor = self._cursor
            cursor[:count] = start[:count] + counts[:count]
            extra[:count] = 0
            large_scan(position, diameter, large, *args, self.cell_size[self.axes], *geometry, is_large, self.half,
                       self.index, cursor, extra)
        self.count = count
        self.longest_row = int(np.diff(start).max()) if count else 0
        self.longest_jump = longest_jump(start, self.index, count)
        self.builds += 1
        self.reference_position = _grow(self.reference_position, count)
        self.reference_diameter = _grow(self.reference_diameter, count)
        self.reference_position[:count] = position[:count]
        self.reference_diameter[:count] = diameter[:count]

    def needs_rebuild(self, position, diameter, count) -> bool:
        """True when the droplet count changed or some droplet travelled (or grew) more than skin/2 since the build.
        A check that measured keeps the largest travel (plus growth) in ``last_travel`` [m]."""
        if count != self.count or self.builds == 0:
            return True
        travel = max_travel(position, self.reference_position, diameter, self.reference_diameter, count,
                            self.period, self.inverse_period)
        self.last_travel = travel
        return travel > 0.5 * self.skin

    def state(self) -> dict:
        """The list and its layout as plain arrays and numbers, for a checkpoint: :meth:`restore` of it continues as
        if the list had never been dropped (rows in the same order, the same skin, axis order and reference
        positions), so a resumed run is bit-identical to an uninterrupted one."""
        n = self.count
        return {"start": self.start[: n + 1].copy(), "index": self.index[: int(self.start[n]) if n else 0].copy(),
                "reference_position": self.reference_position[:n].copy(),
                "reference_diameter": self.reference_diameter[:n].copy(), "axes": self.axes.copy(),
                "cell_size": np.asarray(self.cell_size, dtype=float).copy(),
                "shape": np.asarray(self.shape, dtype=np.int64).copy(),
                "scalars": np.array([self.skin, n, self.builds, self.longest_row, self.longest_jump, self._stride],
                                    dtype=float)}

    def restore(self, state: dict) -> None:
        """Take back a list saved by :meth:`state` (for the same droplets, in the same memory order)."""
        skin, n, builds, longest_row, longest_jump, stride = state["scalars"]
        n = int(n)
        self.skin = float(skin)
        self.count, self.builds = n, int(builds)
        self.longest_row, self.longest_jump, self._stride = int(longest_row), int(longest_jump), int(stride)
        self.start = np.asarray(state["start"], dtype=np.int64).copy()
        self.index = _grow(self.index, max(int(self.start[n]) if n else 0, 1))
        self.index[: state["index"].shape[0]] = state["index"]
        self.reference_position = _grow(self.reference_position, n)
        self.reference_diameter = _grow(self.reference_diameter, n)
        self.reference_position[:n] = state["reference_position"]
        self.reference_diameter[:n] = state["reference_diameter"]
        self.axes = np.asarray(state["axes"], dtype=np.int64).copy()
        self.cell_size = np.asarray(state["cell_size"], dtype=float).copy()
        self.shape = np.asarray(state["shape"], dtype=np.int64).copy()

    def invalidate(self) -> None:
        """Force a rebuild at the next check (call after adding, removing or reordering droplets)."""
        self.builds = 0

    def pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """The list as two index arrays (i, j), one entry per stored row element (for tests and diagnostics)."""
        rows = np.repeat(np.arange(self.count), np.diff(self.start))
        return rows, self.index[: self.start[self.count]].astype(np.int64)


def brute_force_pairs(position, diameter, count, skin, box_size, periodic):
    """NumPy twin of the list: every pair i < j with distance < (d_i + d_j)/2 + skin, minimum image on periodic axes.

    Returns (i, j) int64 arrays sorted lexicographically. O(n^2) memory: for tests on small sets.
    """
    pos = np.asarray(position[:count], dtype=float)
    dia = np.asarray(diameter[:count], dtype=float)
    period = np.where(np.asarray(periodic, dtype=bool), np.asarray(box_size, dtype=float), 0.0)
    delta = pos[None, :, :] - pos[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(period > 0.0, period * np.rint(delta / np.where(period > 0.0, period, 1.0)), 0.0)
    delta -= shift
    dist2 = np.einsum("ijk,ijk->ij", delta, delta)
    cut = 0.5 * (dia[:, None] + dia[None, :]) + skin
    i, j = np.nonzero(np.triu(dist2 < cut * cut, k=1))
    return i.astype(np.int64), j.astype(np.int64)


def reorder_store(store, order) -> None:
    """Permute the live droplets of a store so that new p is old ``order[p]``: see
    :meth:`fulldem.droplets.DropletStore.reorder`, the owner of the droplets."""
    store.reorder(order)
