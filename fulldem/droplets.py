"""Droplet state as a struct of arrays with capacity that grows by doubling: the one owner of the droplets.

All arrays have the store's capacity as first dimension; entries ``[0:count]`` are the live droplets, kept
contiguous (removal compacts, preserving order). Kernels receive the arrays and ``count``, never the store.

Ownership. Only the store's methods add (:meth:`DropletStore.add`), remove (:meth:`~DropletStore.remove`), reorder
(:meth:`~DropletStore.reorder`), grow (:meth:`~DropletStore.reserve`) or restore (:meth:`~DropletStore.restore`)
droplets; each keeps coalescence partners pointing at the right droplets and increments :attr:`DropletStore.version`.
Whoever holds per-droplet work arrays or a neighbour list (the DEM stepper, the coupling) compares the version it
last saw with the store's instead of keeping a flag of its own. Checkpoints (:meth:`~DropletStore.state`,
:meth:`~DropletStore.restore`) carry every field of :data:`FIELDS`: a field added there is stored, moved, permuted
and checkpointed with no other edit.

Arrays and units:

* ``position`` (cap, 3) [m] centre; ``velocity`` (cap, 3) [m/s];
* ``diameter`` (cap,) [m] current diameter; ``density`` (cap,) [kg/m^3];
* ``contact_diameter`` (cap,) [m] the diameter the contacts see: ``diameter``, except for a droplet marked for
  coalescence, which grows it toward its target (fulldem.submodels.coalescence). Grown sizes are for contacts only: volume,
  mass, buoyancy, drag and the coupling use ``diameter``;
* ``original_diameter`` (cap,) [m] diameter at the feed composition (Cu2S mass is proportional to its cube);
* ``age`` (cap,) [s] time since feeding (reaction submodel);
* ``flags`` (cap,) int32 bit flags (:data:`COALESCING`, ...); ``partner`` (cap,) int64 index of the coalescence
  partner or -1; ``ident`` (cap,) int64 unique droplet number (never reused within a run);
* ``marked_time`` (cap,) [s] simulated time at which the droplet was marked for coalescence (read only while it is
  marked; NaN where a checkpoint from before the field did not say).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from settler.physics import merged_diameter_v, sphere_mass, sphere_volume


#: Flag bit: the droplet is marked for coalescence with ``partner`` (they no longer repel each other).
COALESCING = 1
#: Flag bit: the droplet was formed by a merge (the seed paper's Fig. 15 counts coalesced and never-coalesced ones).
MERGED = 2

FIELDS = {
    "position": (3, np.float64),
    "velocity": (3, np.float64),
    "diameter": (None, np.float64),
    "density": (None, np.float64),
    "contact_diameter": (None, np.float64),
    "original_diameter": (None, np.float64),
    "age": (None, np.float64),
    "flags": (None, np.int32),
    "partner": (None, np.int64),
    "ident": (None, np.int64),
    "marked_time": (None, np.float64),
}


class DropletStore:
    """Growable struct-of-arrays store of droplets (see module docstring for the arrays and units)."""

    def __init__(self, capacity: int = 1024):
        self.count = 0
        self.next_ident = 0
        self.version = 0  # incremented by every change of the droplet set, order or capacity
        self.size_version = 0  # incremented by every change in place of sizes, densities or positions at an event
        # point (set_sizes, set_contact_diameters, displace): the DEM then checks its list and masses
        self.capacity = max(int(capacity), 1)
        for name, (width, dtype) in FIELDS.items():
            shape = (self.capacity,) if width is None else (self.capacity, width)
            setattr(self, name, np.zeros(shape, dtype=dtype))
        self.partner[:] = -1

    def arrays(self) -> dict[str, np.ndarray]:
        """Views of the live part of every array."""
        return {name: getattr(self, name)[: self.count] for name in FIELDS}

    def reserve(self, capacity: int) -> None:
        """Ensure room for ``capacity`` droplets, doubling the arrays as often as needed."""
        if capacity <= self.capacity:
            return
        new = self.capacity
        while new < capacity:
            new *= 2
        for name, (width, dtype) in FIELDS.items():
            old = getattr(self, name)
            shape = (new,) if width is None else (new, width)
            grown = np.zeros(shape, dtype=dtype)
            grown[: self.count] = old[: self.count]
            if name == "partner":
                grown[self.count:] = -1
            setattr(self, name, grown)
        self.capacity = new
        self.version += 1

    def add(self, position, diameter, density, velocity=None, original_diameter=None, age=None, **fields) -> slice:
        """Append droplets; returns the slice of their indices. Arrays broadcast to (n, 3) / (n,).

        Fields of :data:`FIELDS` not given (as arguments or keywords) start at 0, ``partner`` at -1 and ``ident``
        numbers the droplets on from the last one; ``original_diameter`` defaults to ``diameter``."""
        unknown = [name for name in fields if name not in FIELDS or name == "ident"]
        if unknown:
            raise KeyError(f"droplets: add() got unknown or reserved field(s) {unknown}")
        position = np.atleast_2d(np.asarray(position, dtype=float))
        n = position.shape[0]
        start = self.count
        self.reserve(start + n)
        sl = slice(start, start + n)
        values = {"position": position, "diameter": diameter, "density": density, "partner": -1,
                  "original_diameter": diameter if original_diameter is None else original_diameter,
                  "contact_diameter": diameter,
                  **({} if velocity is None else {"velocity": velocity}), **({} if age is None else {"age": age}),
                  **fields, "ident": np.arange(self.next_ident, self.next_ident + n)}
        for name in FIELDS:
            getattr(self, name)[sl] = values.get(name, 0)
        self.next_ident += n
        self.count += n
        self.version += 1
        return sl

    def remove(self, mask: np.ndarray) -> None:
        """Remove the live droplets where ``mask`` (length count) is true, keeping the others' order.

        Coalescence partners are re-pointed to the droplets' new indices (a partner that is removed leaves -1).
        """
        keep = ~np.asarray(mask, dtype=bool)
        if keep.all():
            return
        count = self.count
        for name in FIELDS:  # compacted in place, in order, by a compiled loop (a NumPy mask copies each field twice)
            arr = getattr(self, name)
            (_compact_1d if arr.ndim == 1 else _compact_2d)(arr, keep, count)
        n = _remap_partners(self.partner, self.flags, self.contact_diameter, self.diameter, keep, count)
        self.partner[n:count] = -1
        self.count = n
        self.version += 1

    def merge(self, first, second, lower=None, period=None) -> np.ndarray:
        """Replace each pair (``first[k]``, ``second[k]``) of live droplets by one droplet; returns the merged
        droplets' indices after the store is compacted.

        The merged droplet conserves each pair's volume, mass (so its density is the mass over the volume), momentum
        (it sits at the centre of mass, at the centre-of-mass velocity), Cu2S (its original volume is the sum of the
        original volumes) and mass x age (its age is the mass-weighted age); it takes the lower index's slot and a
        new ident, its contact diameter is its diameter, it is flagged :data:`MERGED` and has no partner (droplets
        partnered with either one lose their partner and their grown size). Pairs must be disjoint. Other fields of
        :data:`FIELDS` take the lower index's value. In a periodic box (``period`` (3,) [m], 0 on bounded axes, and
        the box's ``lower`` corner (3,) [m]) the centre of mass is taken over the pair's nearest images and wrapped
        back into the box.
        """
        i = np.asarray(first, dtype=np.int64).ravel()
        j = np.asarray(second, dtype=np.int64).ravel()
        both = np.concatenate([i, j])
        if i.shape != j.shape or (both.size and (both.min() < 0 or both.max() >= self.count)) \
                or np.unique(both).size != both.size:
            raise ValueError("droplets: merge() takes pairs of distinct live droplets, each in at most one pair")
        if i.size == 0:
            return i
        keep, gone = np.minimum(i, j), np.maximum(i, j)
        volume_k, volume_g = self.diameter[keep] ** 3, self.diameter[gone] ** 3  # x pi/6, which cancels
        mass_k, mass_g = self.density[keep] * volume_k, self.density[gone] * volume_g
        mass, volume = mass_k + mass_g, volume_k + volume_g
        wk, wg = (mass_k / mass)[:, None], (mass_g / mass)[:, None]
        other = self.position[gone]
        period = np.zeros(3) if period is None else np.asarray(period, dtype=float)
        periodic = period > 0.0
        safe = np.where(periodic, period, 1.0)
        if periodic.any():  # the nearest image of the second droplet
            delta = other - self.position[keep]
            other = self.position[keep] + np.where(periodic, delta - period * np.rint(delta / safe), delta)
        self.position[keep] = wk * self.position[keep] + wg * other
        if periodic.any():
            lower = np.asarray(lower, dtype=float)
            wrapped = lower + np.mod(self.position[keep] - lower, safe)
            self.position[keep] = np.where(periodic, wrapped, self.position[keep])
        self.velocity[keep] = wk * self.velocity[keep] + wg * self.velocity[gone]
        self.age[keep] = wk[:, 0] * self.age[keep] + wg[:, 0] * self.age[gone]
        self.original_diameter[keep] = merged_diameter_v(self.original_diameter[keep], self.original_diameter[gone])
        self.diameter[keep] = merged_diameter_v(self.diameter[keep], self.diameter[gone])
        volume = self.diameter[keep] ** 3  # the merged droplet's own volume (x pi/6), so density x volume = mass
        self.density[keep] = mass / volume
        n = self.count
        partnered = np.isin(self.partner[:n], both)
        self.partner[:n][partnered] = -1
        self.flags[:n][partnered] &= ~np.int32(COALESCING)
        self.contact_diameter[:n][partnered] = self.diameter[:n][partnered]
        self.contact_diameter[keep] = self.diameter[keep]
        self.partner[keep], self.flags[keep] = -1, MERGED
        self.ident[keep] = np.arange(self.next_ident, self.next_ident + keep.size)
        self.next_ident += keep.size
        mask = np.zeros(n, dtype=bool)
        mask[gone] = True
        self.remove(mask)
        return keep - np.searchsorted(np.sort(gone), keep)

    def mark_pairs(self, first, second, time=np.nan) -> None:
        """Mark each pair (``first[k]``, ``second[k]``) of free live droplets for coalescence at simulated ``time``
        [s]: flag :data:`COALESCING` and point each at the other (mutual partners exert no contact force on each
        other)."""
        i = np.asarray(first, dtype=np.int64).ravel()
        j = np.asarray(second, dtype=np.int64).ravel()
        both = np.concatenate([i, j])
        if i.shape != j.shape or np.unique(both).size != both.size \
                or (both.size and ((self.flags[both] & COALESCING) != 0).any()):
            raise ValueError("droplets: mark_pairs() takes disjoint pairs of droplets not yet marked")
        self.flags[both] |= COALESCING
        self.partner[i], self.partner[j] = j, i
        self.marked_time[both] = time

    def set_contact_diameters(self, index, contact_diameter) -> None:
        """Set the contact diameters [m] of the given droplets (a marked pair's growth; at least their diameters)."""
        index = np.asarray(index, dtype=np.int64)
        self.contact_diameter[index] = np.maximum(contact_diameter, self.diameter[index])
        self.size_version += 1

    def displace(self, index, displacement) -> None:
        """Move the given droplets by ``displacement`` (k, 3) [m] at an event point (a marked pair drawn together)."""
        index = np.asarray(index, dtype=np.int64)
        self.position[index] += displacement
        self.size_version += 1

    def set_sizes(self, diameter, density) -> None:
        """Set every live droplet's diameter [m] and density [kg/m^3] in place (the reaction); contact diameters
        follow: equal to the diameter, or a marked droplet's grown size if larger."""
        n = self.count
        self.diameter[:n] = diameter
        self.density[:n] = density
        marked = (self.flags[:n] & COALESCING) != 0
        self.contact_diameter[:n] = np.where(marked, np.maximum(self.contact_diameter[:n], self.diameter[:n]),
                                             self.diameter[:n])
        self.size_version += 1

    def reorder(self, order) -> None:
        """Permute the live droplets so that new p is old ``order[p]`` (a permutation of range(count)).

        Every field moves with its droplet; coalescence partners are re-pointed to the new indices. Per-droplet arrays
        held elsewhere must be permuted with the same ``order`` (``array[:n] = array[order]``).
        """

        n = self.count
        order = np.asarray(order, dtype=np.int64)
        if order.shape != (n,):
            raise ValueError(f"droplets: order has shape {order.shape}, expected ({n},)")
        new_index = np.empty(n, dtype=np.int64)
        new_index[order] = np.arange(n)
        for name in FIELDS:
            permute_rows(getattr(self, name), order)
        partner = self.partner[:n]
        has = partner >= 0
        partner[has] = new_index[partner[has]]
        self.version += 1

    def state(self) -> dict[str, np.ndarray | int]:
        """Plain data for checkpoints: the live arrays plus counters."""
        out = {k: v.copy() for k, v in self.arrays().items()}
        out["next_ident"] = self.next_ident
        return out

    def restore(self, state: dict) -> None:
        """Take the droplets of :meth:`state` in place of the current ones (every field of :data:`FIELDS`; a field
        missing from ``state`` raises KeyError naming it)."""
        if "contact_diameter" not in state and "diameter" in state:  # a checkpoint from before grown sizes existed
            state = {**state, "contact_diameter": state["diameter"]}
        if "marked_time" not in state and "diameter" in state:  # a checkpoint from before marks were timed
            state = {**state, "marked_time": np.full(len(state["diameter"]), np.nan)}
        missing = [name for name in FIELDS if name not in state]
        if missing:
            raise KeyError(f"droplet state has no field(s) {missing}")
        n = len(state["diameter"])
        self.reserve(max(2 * n, 1024))
        for name in FIELDS:
            getattr(self, name)[:n] = state[name]
        self.partner[n:] = -1
        self.count = n
        self.next_ident = int(state["next_ident"])
        self.version += 1

    @classmethod
    def from_state(cls, state: dict) -> "DropletStore":
        """A new store holding the droplets of :meth:`state`."""
        store = cls(max(2 * len(state["diameter"]), 1024))
        store.restore(state)
        return store

    def volume(self) -> np.ndarray:
        """Volumes of the live droplets [m^3]."""
        return sphere_volume(self.diameter[: self.count])

    def mass(self) -> np.ndarray:
        """Masses of the live droplets [kg]."""
        return self.density[: self.count] * self.volume()


@njit(cache=True)
def _compact_1d(array, keep, count):
    """array[:n] = array[:count][keep], in place (each row moves down or stays, so the order is kept)."""
    write = 0
    for p in range(count):
        if keep[p]:
            array[write] = array[p]
            write += 1


@njit(cache=True)
def _compact_2d(array, keep, count):
    """The rows of a 2-D array: array[:n] = array[:count][keep], in place."""
    write = 0
    for p in range(count):
        if keep[p]:
            for a in range(array.shape[1]):
                array[write, a] = array[p, a]
            write += 1


@njit(cache=True)
def _remap_partners(partner, flags, contact_diameter, diameter, keep, count):
    """After the fields were compacted (partner[:n] still holding old indices): point each partner to its new index,
    -1 where the partner was removed; a droplet marked COALESCING without a partner loses the mark and its grown
    size. Returns n, the droplets kept."""
    new_index = np.empty(count, dtype=np.int64)
    n = 0
    for p in range(count):
        if keep[p]:
            new_index[p] = n
            n += 1
        else:
            new_index[p] = -1
    for p in range(n):
        q = partner[p]
        partner[p] = new_index[q] if q >= 0 else -1
        if partner[p] < 0 and (flags[p] & COALESCING) != 0:
            flags[p] &= ~np.int32(COALESCING)
            contact_diameter[p] = diameter[p]
    return n


@njit(cache=True, parallel=True)
def _gather_1d(source, order, out):
    for p in prange(order.shape[0]):
        out[p] = source[order[p]]


@njit(cache=True, parallel=True)
def _gather_2d(source, order, out):
    for p in prange(order.shape[0]):
        q = order[p]
        for a in range(source.shape[1]):
            out[p, a] = source[q, a]


def permute_rows(array, order) -> None:
    """``array[:n] = array[order]`` for n = len(order), gathered in parallel (1-D or 2-D arrays)."""
    n = order.shape[0]
    work = np.empty((n,) + array.shape[1:], dtype=array.dtype)
    (_gather_1d if array.ndim == 1 else _gather_2d)(array, order, work)
    array[:n] = work


@njit(cache=True)
def total_momentum(velocity, diameter, density, count):
    """Total momentum of droplets [kg m/s] (3,)."""
    out = np.zeros(3)
    for p in range(count):
        m = sphere_mass(diameter[p], density[p])
        for a in range(3):
            out[a] += m * velocity[p, a]
    return out
