"""Machine tuning, kept apart from the physics: how many threads a DEM advance uses, how thick the neighbour-list
skin is and how often droplets are re-sorted in memory. None of it changes what a run computes beyond round-off
(the timed thread choice splits advances of THREAD_PROBE_EVERY steps or more into segments); all of it changes how
fast it runs.
"""

from __future__ import annotations

import time

import numba
import numpy as np

#: Below this many droplets the DEM kernels run on one thread: a parallel launch costs more than it saves, and on a
#: machine shared with other busy processes a small parallel step waits for a descheduled thread.
PARALLEL_MIN_DROPLETS = 2000

#: Steps between two timings of one thread against all (``ThreadChoice(threads=None)``) inside one long advance
#: (THREAD_PROBE_EVERY steps or more, as the DEM-only benchmark's), and steps per timing.
THREAD_PROBE_EVERY = 500
THREAD_PROBE_STEPS = 10

#: Shorter advances (a coupled run's sub-steps of one fluid step: 71 at the presets' 4 ms) are timed whole, one at
#: all threads and the next at one, this many steps after the last timing: an advance is never split, so the
#: results are those of a fixed thread count bit for bit. (Splitting every fluid step's advance into 10 + 10 + 51
#: steps, as before, cost three free-flight selections a step and 10 sub-steps on one thread: on the simple
#: case's steady state, 18 + 11 ms against 7 ms for those 20 sub-steps.)
THREAD_PROBE_WHOLE_EVERY = 5000

#: Droplets are re-sorted by neighbour cell (memory locality of the DEM and coupling passes) in every fluid step in
#: which some entered or left, and otherwise every this many fluid steps (they move a small fraction of a cell per
#: step); a sort also rebuilds the neighbour list.
SORT_INTERVAL = 50

#: Neighbour-list skin, in mean feed diameters: at least SKIN_MIN, at most SKIN_MAX, otherwise SKIN_TRAVEL times
#: the largest droplet speed times dt, chosen at each re-sort of the droplets. The list must be rebuilt once a
#: droplet has travelled skin/2; a fed run rebuilds it every step anyway (insertions), so a skin that lasts one
#: fluid step (skin/2 = 1.25 v_max dt) saves a second build, while a larger one would only lengthen the rows the
#: contact loop filters. Measured on the simple case at 172 000 droplets (54 mm/s in its channel):
#: 330-340 ms per step with the fixed 0.25 d skin, 270-280 ms with 0.5 d. The cap is 2 d (1 mm for the presets'
#: 0.5 mm feed): free flight needs the fluid step's travel within skin/2, so a cap of 1 d stopped it (and the DEM
#: sub-stepped every droplet) whenever the slag ran faster than 62 mm/s at the 4 ms fluid step (125 mm/s at 2 ms);
#: 2 d keeps it to 125 mm/s at 4 ms (benchmarks/bench_steady.py, simple at 4 ms: 64.0 s per simulated second with
#: 0 % in free flight at 1 d, 48.7 s with 89 % at 2 d; at 2 ms in the slag's spin-up, 103.5 against 75.8 s).
SKIN_MIN = 0.25
SKIN_MAX = 2.0
SKIN_TRAVEL = 2.5


def skin_for(speed, dt, diameter_ref) -> float:
    """Neighbour-list skin [m] for droplets moving at most ``speed`` [m/s] over fluid steps of ``dt`` [s], in units
    of the mean feed diameter ``diameter_ref`` [m] (see :data:`SKIN_TRAVEL`)."""
    return float(np.clip(SKIN_TRAVEL * speed * dt, SKIN_MIN * diameter_ref, SKIN_MAX * diameter_ref))


def compose(order, new):
    """Permutation after two re-sortings: new p is old order[new[p]] (None: no re-sorting)."""
    if new is None:
        return order
    return new if order is None else order[new]


class ThreadChoice:
    """How many threads the DEM kernels of an advance run on.

    One below :data:`PARALLEL_MIN_DROPLETS` droplets; else ``threads`` when given, or when None the faster of one and
    all threads (on a machine shared with other busy processes, threads that wait for each other at every phase can
    be slower than one), timed two ways:

    * an advance shorter than :data:`THREAD_PROBE_EVERY` steps runs whole on one thread count: the first one on all
      (it may compile), then, every :data:`THREAD_PROBE_WHOLE_EVERY` steps, one advance timed on all threads and
      the next on one; the others run on the faster. The results do not depend on the thread count, so these are
      bit for bit those of a fixed one;
    * a longer advance is split, a timing of :data:`THREAD_PROBE_STEPS` steps on each count every
      :data:`THREAD_PROBE_EVERY` steps; the segments change the results at round-off (fused multiply-adds fall
      differently at segment ends).
    """

    def __init__(self, threads=None):
        self.threads = None if threads is None else max(1, int(threads))
        self.timed = None  # the faster thread count of the last timing
        self._timing = {}  # seconds per step of the whole advances timed so far in the current timing
        self._since = 0  # steps run since the last timing of whole advances
        self._calls = 0

    def run(self, count, steps, advance):
        """Run ``advance(k)`` (k steps for ``count`` droplets; returns a droplet permutation or None) for ``steps``
        steps in all, on the chosen threads; returns the composed permutation."""
        threads = numba.get_num_threads()
        if count < PARALLEL_MIN_DROPLETS or threads == 1:
            fixed = 1
        elif self.threads is not None:
            fixed = min(self.threads, threads)
        elif steps < THREAD_PROBE_EVERY:
            return self._run_whole(steps, advance, threads)
        else:
            fixed = None
        order = None
        try:
            if fixed is not None:
                numba.set_num_threads(fixed)
                return advance(steps)
            done = 0
            while done < steps:
                if done % THREAD_PROBE_EVERY == 0 and steps - done >= 4 * THREAD_PROBE_STEPS:
                    timing = {}
                    for candidate in (1, threads):
                        numba.set_num_threads(candidate)
                        start = time.perf_counter()
                        order = compose(order, advance(THREAD_PROBE_STEPS))
                        timing[candidate] = time.perf_counter() - start
                        done += THREAD_PROBE_STEPS
                    self.timed = min(timing, key=timing.get)
                chunk = min(steps - done, THREAD_PROBE_EVERY - done % THREAD_PROBE_EVERY)
                numba.set_num_threads(self.timed)
                order = compose(order, advance(chunk))
                done += chunk
            return order
        finally:
            numba.set_num_threads(threads)

    def _run_whole(self, steps, advance, threads):
        """One advance on one thread count, timed when a timing is due (see the class docstring)."""
        self._calls += 1
        due = self._calls > 1 and (self.timed is None or self._since >= THREAD_PROBE_WHOLE_EVERY)
        candidate = next(c for c in (threads, 1) if c not in self._timing) if due else None
        try:
            numba.set_num_threads(candidate or self.timed or threads)
            start = time.perf_counter()
            order = advance(steps)
            seconds = time.perf_counter() - start
        finally:
            numba.set_num_threads(threads)
        if candidate is None:
            self._since += steps
        else:
            self._timing[candidate] = seconds / steps
            if len(self._timing) == 2:
                self.timed = min(self._timing, key=self._timing.get)
                self._timing, self._since = {}, 0
        return order


class PhaseTimes:
    """Wall seconds spent in each named phase of the fluid steps, summed over the steps since :meth:`reset`.

    The stepper calls :meth:`start` as a step begins and :meth:`lap` as each phase ends, so the phases of a step sum
    to its wall time (less the few microseconds between the step's call and :meth:`start`); a phase's name is what
    ran since the previous lap. The compiled kernels return only when done, so a lap after one times it. Read by
    ``benchmarks/bench_steady.py``; costs two clock reads per phase."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self.steps = 0
        self._last = 0.0

    def start(self):
        self._last = time.perf_counter()
        self.steps += 1

    def lap(self, name):
        now = time.perf_counter()
        self.seconds[name] = self.seconds.get(name, 0.0) + (now - self._last)
        self._last = now

    def reset(self):
        self.seconds, self.steps = {}, 0

    def total(self) -> float:
        """Sum of the phases [s]."""
        return float(sum(self.seconds.values()))
