"""The coalescence submodel of the seed paper (section 3.3.1): colliding droplets are marked, grow and merge.

Which contacts are evaluated is ``trigger``. With ``"first_contact"`` the DEM kernels record the *first* contact of a
pair -- its overlap is less than its approach speed times the DEM step, so a step earlier the two did not touch --
with its normal approach speed; with ``"every_contact"`` (the seed paper's "during every droplet-droplet contact")
they record every pair in contact whose droplets are both free, with its current normal approach speed max(-v_n, 0)
at the last DEM sub-step it was in contact during the fluid step (0 for a pair at rest or drawing apart: Eq. 2 then
has a Weber number of 0 and P_c = 1, so a resting pair within the size limit merges, as droplets pressed together
under the roof do). Either way the record is per neighbour-list entry (:class:`fulldem.dem.records.Contacts`;
threads never write the same entry). At the fluid step's
end-of-step event point (:mod:`fulldem.submodels`) this submodel, in a fixed order:

1. grows every marked pair's *contact* diameters by ``growth_rate`` x d_m x dt (d_m the merged diameter), up to
   ``growth_target`` x d_m, draws the two together (below), and merges the pairs whose two droplets have both
   reached it and have met
   (:meth:`fulldem.droplets.DropletStore.merge`: volume, mass, momentum, Cu2S and mass x age conserved exactly; the
   merged droplet sits at the centre of mass);
2. reads the step's recorded contacts, keeps those where P_c >= ``threshold`` (seed Eq. 2,
   :func:`settler.physics.coalescence_probability`, with the Weber number of the approach speed; the same step rule
   popbal applies, :func:`settler.physics.collision_merges`) and the merged droplet would not exceed ``size_limit``,
   and, in order of the pair's idents, marks each pair whose droplets are both free (``mode = "delayed"``): they no
   longer push each other, every other droplet still touches both. With ``mode = "instantaneous"`` (the paper's
   previous model) they are merged at once instead, which lets a merged droplet appear deep inside its neighbours
   -- the "explosions" of section 4.1.

Grown sizes are for contacts only: the store keeps them in ``contact_diameter``; volume, mass, buoyancy, drag, the
coupling's deposits and the matte accounting use ``diameter`` (two partners grown to 95 % of the merged diameter
would otherwise hold 1.71 times the true volume).

Counts: merges (:attr:`fulldem.stepper.Counters.merges`), droplets formed by a merge (flag
:data:`fulldem.droplets.MERGED`) and a table of merges by the size pair (:data:`SIZE_BINS`), which the time series and
``merges_by_size.csv`` report; what limits the rate: pairs marked and pairs refused by the size limit
(:attr:`fulldem.stepper.Counters.marks`, ``refused_size``, per row in the time series), and, from
:meth:`Coalescence.columns`, the marked pairs waiting past their growth time plus one fluid step and the longest time
a pair has been marked.

Differences from the paper, and why. With ``trigger = "first_contact"`` the approach speed is the normal component
of the relative velocity at first contact, and a pair is evaluated once (EDEM evaluated the model at every contact
time step with its current relative velocity, which ``"every_contact"`` does at every fluid step). The growth happens at the fluid step's event
point in steps of ``growth_rate`` x d_m x dt (EDEM grew every DEM step); the case key sets its speed. And marked
partners are drawn together along their line of centres as they grow, keeping their centre of mass, at a fixed
speed (below) with which partners that met at contact distance meet at the centre of mass when both are grown; the
paper does not say how the pair's centres move. Without it, partners that met at contact distance in a dense
cluster stay there (nothing pulls them together), and the merged droplet, placed at their centre of mass, fills the
groove between the two spheres where neighbours sit: measured on the demo case, a merged droplet then overlapped a
neighbour by 27 % of its diameter and the run stopped at 4.7 s. Drawing them together moves those neighbours out
gradually, through the contacts, while the pair grows.

The draw has a fixed speed: each step closes at most (d_i + d_j)/2 x g / (``growth_target`` x d_m - d_small) [m], g =
``growth_rate`` x d_m x dt the step's growth [m], so that partners marked at contact distance reach each other exactly
as the smaller one reaches its target; and a pair merges only once its partners have met (the step's draw closed what
was left), waiting at its grown size if its neighbours pushed it apart. Partners do not push each other, so in a
jammed cluster the other droplets' contacts can hold them apart or wedge between them; a draw by a fixed *fraction* of
what is left (this module's first version) then sped up as the growth neared its end and the merge put both at the
centre of mass, however far apart: measured on a collapsing fcc cluster of 256 droplets of 1 mm, every droplet paired
at once, partners held 1.4 mm apart were drawn 0.7 mm closer in the growth's last step and the largest overlap reached
25 % of a diameter (the instantaneous merge: 45 %); with the fixed speed it stays at 3 % over 100 steps, the pairs
merging over steps 43-180 instead of all at step 40 (108 droplets, the dense-cluster test of
tests/test_fulldem_coalescence.py: 13 % before, 3.3 % after, 44 % instantaneous). What is left is the merge's own
step: the merged droplet's contact diameter jumps from ``growth_target`` x d_m to d_m, which presses a neighbour by up
to (1 - growth_target) d_m / 2 more (5 % of a 1.3 mm droplet next to a merge of 2.6 mm, at 0.95).

The draw also follows the partners' differential settling: each step it takes back what their drift velocities (the
step's fluid velocity at each droplet plus its buoyant weight and pressure force over its drag coefficient, what it
settles at with contacts aside) carried them apart along their line of centres over the fluid step. Without it a
marked pair whose partners settle at different speeds hardly ever merged: the partners no longer push each other,
the faster one falls on through the slower, and the fixed-speed draw is slower than their relative speed, so the
pair waited, marked and unable to merge with anything, for the rest of the run (1.5 and 0.5 mm droplets settling
5.5 mm/s apart: 0 merges in 3 s where the instantaneous merge made 286 and the ballistic kernel predicts 310; with
the drift taken back: 235 at the first-contact trigger, 247 at every contact, most of the rest still growing, each
pair for the 0.31 s the small partner needs to grow at growth_rate 2). Only
the drift is followed, not the partners' whole relative motion: in a jammed cluster their neighbours' contacts push
them apart, and pulling against those pushes would press the partners into the neighbours (the dense-cluster test's
overlap bound).
"""

from __future__ import annotations

import numpy as np

from settler.physics import RULE_STEP, coalescence_probability, collision_merges, growth_time_v, merged_diameter_v
from settler.physics.coalescence import PROBABILITY_FORMS

from ..droplets import COALESCING
from .base import Submodel


#: Bins of the merges-by-size table: droplet diameters [m], edges doubling the volume per bin (d ratio 2^(1/3))
#: from 10 um to 0.1 m (41 edges), plus a bin below and one above.
SIZE_BINS = 10e-6 * 2.0 ** (np.arange(41) / 3.0)
MODES = ("delayed", "instantaneous")


def marked_pairs(store):
    """The marked pairs of a store as index arrays (first, second), first < second, in index order."""
    n = store.count
    marked = np.flatnonzero((store.flags[:n] & COALESCING) != 0)
    first = marked[store.partner[marked] > marked]
    return first, store.partner[first]


def size_bin(diameter):
    """Index of the merges-by-size bin of each diameter [m]: 0 below SIZE_BINS[0], len(SIZE_BINS) above the last."""
    return np.searchsorted(SIZE_BINS, np.asarray(diameter, dtype=float), side="right")


def empty_size_table():
    """A zero merges-by-size table: (bins, bins) counts, smaller droplet first."""
    return np.zeros((SIZE_BINS.size + 1, SIZE_BINS.size + 1), dtype=np.int64)


def size_table_frame(table):
    """The non-zero cells of a merges-by-size table as rows (smaller bin's edges, larger bin's edges [m], merges)."""
    import pandas as pd

    edges = np.concatenate([[0.0], SIZE_BINS, [np.inf]])
    i, j = np.nonzero(np.asarray(table))
    return pd.DataFrame({"small_low": edges[i], "small_high": edges[i + 1], "large_low": edges[j],
                         "large_high": edges[j + 1], "merges": np.asarray(table)[i, j]})


class Coalescence(Submodel):
    """Marks colliding pairs, grows them and merges them at the end-of-step event point (module docstring)."""

    name = "coalescence"

    def __init__(self, case):
        c = case.coalescence
        if c.mode not in MODES:
            raise ValueError(f"coalescence.mode = {c.mode!r}: allowed: {', '.join(MODES)}")
        self.mode = c.mode
        self.size_limit = c.size_limit
        self.threshold = c.threshold
        self.growth_target = c.growth_target
        self.growth_rate = c.growth_rate
        self.psi = c.psi
        self.virtual_mass = c.virtual_mass
        self.form = PROBABILITY_FORMS[c.probability_form]
        self.slag_density = case.slag.density
        self.interfacial_tension = case.matte.interfacial_tension

    def at_end(self, sim) -> None:
        if self.mode == "delayed":
            self.grow_and_merge(sim)
        self.mark(sim)

    def columns(self, sim) -> dict:
        """What limits the merge rate now, for the time series: ``pairs_waiting``, marked pairs past their growth
        time plus one fluid step (grown, but not yet met: held apart by neighbours), and ``longest_marked`` [s], the
        longest any marked pair has been marked (0 without marked pairs; NaN for pairs marked before a resume from a
        checkpoint that did not time its marks)."""
        s = sim.store
        first, second = marked_pairs(s)
        if first.size == 0:
            return {"pairs_waiting": 0, "longest_marked": 0.0}
        growth_time = growth_time_v(s.diameter[first], s.diameter[second], self.growth_target, self.growth_rate)
        marked_for = sim.time - s.marked_time[first]
        return {"pairs_waiting": int((marked_for > growth_time + sim.dt).sum()),
                "longest_marked": float(np.max(marked_for))}

    # -- marked pairs
    def grow_and_merge(self, sim) -> None:
        """Grow every marked pair's contact diameters by one fluid step, draw the partners together at the pair's
        fixed speed (module docstring) and merge the pairs that are grown and have met."""
        s = sim.store
        first, second = marked_pairs(s)
        if first.size == 0:
            return
        # the step's drift velocities, while their rows are still the store's droplets
        drifting = sim.drift_velocity if sim.drift_version == s.version else None
        d_first, d_second = s.diameter[first], s.diameter[second]
        merged = merged_diameter_v(d_first, d_second)
        target = self.growth_target * merged
        step = self.growth_rate * sim.dt * merged
        grown_first = np.minimum(s.contact_diameter[first] + step, np.maximum(target, d_first))
        grown_second = np.minimum(s.contact_diameter[second] + step, np.maximum(target, d_second))
        s.set_contact_diameters(np.concatenate([first, second]), np.concatenate([grown_first, grown_second]))
        # draw the partners together along their line of centres, keeping their centre of mass, by at most the
        # closing [m] that brings partners from contact distance to one point over the smaller one's growth
        delta = s.position[second] - s.position[first]
        period = sim.dem.neighbours.period
        delta -= period * np.rint(delta * sim.dem.neighbours.inverse_period)
        separation = np.sqrt(np.einsum("ij,ij->i", delta, delta))
        span = np.maximum(target - np.minimum(d_first, d_second), step)
        closing = 0.5 * (d_first + d_second) * step / span
        # ... plus what their drift velocities (fluid velocity + buoyant weight and pressure force over drag: what
        # each settles at, contacts aside) carried them apart along their line of centres over the fluid step, so
        # that partners settling at different speeds meet as partners at rest do (module docstring)
        if drifting is not None:
            unit = delta / np.maximum(separation, 1e-300)[:, None]
            apart = np.einsum("ij,ij->i", drifting[second] - drifting[first], unit) * sim.dt
            closing = closing + np.maximum(apart, 0.0)
        close = np.minimum(closing / np.maximum(separation, 1e-300), 1.0)  # the fraction of the separation closed
        mass_first = s.density[first] * d_first**3
        mass_second = s.density[second] * d_second**3
        share = (close / (mass_first + mass_second))[:, None] * delta
        s.displace(np.concatenate([first, second]),
                   np.concatenate([share * mass_second[:, None], -share * mass_first[:, None]]))
        done = (grown_first >= target) & (grown_second >= target) & (close >= 1.0)
        if done.any():
            self._merge(sim, first[done], second[done])

    def _merge(self, sim, first, second) -> None:
        sim.merge(first, second)  # counted there, by size too

    # -- new pairs
    def candidates(self, sim):
        """This step's recorded contacts (first or every, ``trigger``) that would coalesce, as disjoint index pairs
        (first, second) of free droplets, in the order of the pairs' idents."""
        s, n = sim.store, sim.store.count
        a, b, speed = sim.dem.take_first_contacts()
        if a.size == 0 or n == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        # idents -> current indices (a droplet merged or gone since is dropped); one pass over the store, sorting
        # only the few droplets involved
        where = np.flatnonzero(np.isin(s.ident[:n], np.concatenate([a, b])))
        order = np.argsort(s.ident[where], kind="stable")
        known, index = s.ident[where][order], where[order]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        if known.size == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        pos_lo = np.minimum(np.searchsorted(known, lo), known.size - 1)
        pos_hi = np.minimum(np.searchsorted(known, hi), known.size - 1)
        alive = (known[pos_lo] == lo) & (known[pos_hi] == hi)
        i, j, lo, hi, speed = index[pos_lo][alive], index[pos_hi][alive], lo[alive], hi[alive], speed[alive]
        # one record per pair (the first read), in the order of (lower ident, higher ident)
        pair_order = np.lexsort((hi, lo))
        i, j, lo, hi, speed = i[pair_order], j[pair_order], lo[pair_order], hi[pair_order], speed[pair_order]
        first_of_pair = np.ones(lo.size, dtype=bool)
        first_of_pair[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
        i, j, speed = i[first_of_pair], j[first_of_pair], speed[first_of_pair]
        # the size limit, then seed Eq. 2 under the step rule at the pair's mean density
        d_i, d_j = s.diameter[i], s.diameter[j]
        free = ((s.flags[i] | s.flags[j]) & COALESCING) == 0
        keep = merged_diameter_v(d_i, d_j) <= self.size_limit
        sim.counters.refused_size += int((free & ~keep).sum())
        keep &= free
        volume_i, volume_j = d_i**3, d_j**3
        density = (s.density[i] * volume_i + s.density[j] * volume_j) / (volume_i + volume_j)
        for k in np.flatnonzero(keep):
            p = coalescence_probability(d_i[k], d_j[k], speed[k], density[k], self.slag_density,
                                        self.interfacial_tension, self.psi, self.virtual_mass, self.form)
            keep[k] = collision_merges(p, self.threshold, RULE_STEP, 0.0)
        # disjoint pairs, greedily in that order
        taken = np.zeros(n, dtype=bool)
        first, second = [], []
        for k in np.flatnonzero(keep):
            if not taken[i[k]] and not taken[j[k]]:
                taken[i[k]] = taken[j[k]] = True
                first.append(i[k])
                second.append(j[k])
        return np.array(first, dtype=np.int64), np.array(second, dtype=np.int64)

    def mark(self, sim) -> None:
        """Mark (delayed) or merge (instantaneous) the step's coalescing first contacts."""
        first, second = self.candidates(sim)
        if first.size == 0:
            return
        if self.mode == "instantaneous":
            self._merge(sim, first, second)
        else:
            sim.store.mark_pairs(first, second, sim.time)
            sim.counters.marks += int(first.size)
