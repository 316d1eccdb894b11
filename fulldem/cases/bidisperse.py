"""A dilute bidisperse suspension settling in a closed box: large droplets falling through small ones, the regime of
the channel where droplets meet because they settle at different speeds. Shared by the coalescence tests
(tests/test_fulldem_coalescence.py) and the study of merges against the ballistic kernel
(benchmarks/study_coalescence_kernel.py). Lengths in m.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from settler.cases import load_case

from ..droplets import DropletStore
from ..stepper import Simulation


def bidisperse_suspension(n_large, n_small, box, *, large_bottom, large_diameter=1.5e-3, small_diameter=0.5e-3,
                          margin=2e-3, seed=7, extra=()):
    """A Simulation of the simple case's slag in a closed ``box`` (3,) [m] without feed: ``n_large`` droplets of
    ``large_diameter`` placed at random above ``large_bottom`` [m], ``n_small`` of ``small_diameter`` spread from
    5 mm above the floor to the top, ``margin`` [m] from the walls, none overlapping (gaps of 5 %); every contact
    may merge (coalescence.threshold = 0, size limit 5 mm) unless ``extra`` overrides say otherwise. Returns (the
    Simulation, the region the small droplets fill as (lower, upper) (3,) [m])."""
    case = load_case("simple", ["feed.mass_rate=0", "fulldem.cell_size=0.005", "fulldem.fluid_step=0.002",
                                "coalescence.threshold=0", "coalescence.size_limit=5e-3", *extra])
    rng = np.random.default_rng(seed)
    lower, upper = np.array([margin, margin, 0.005]), np.array(box) - margin
    large = []
    for p in rng.uniform([margin, margin, large_bottom], upper, size=(10 * n_large, 3)):
        if not large or np.min(np.linalg.norm(np.array(large) - p, axis=1)) > 1.05 * large_diameter:
            large.append(p)
        if len(large) == n_large:
            break
    small = rng.uniform(lower, upper, size=(3 * n_small, 3))
    near_large = cKDTree(large)
    small = small[[not near_large.query_ball_point(p, 1.05 * (large_diameter + small_diameter) / 2) for p in small]]
    crowded = {j for _, j in cKDTree(small).query_pairs(1.05 * small_diameter)}
    small = np.array([p for k, p in enumerate(small) if k not in crowded])[:n_small]
    store = DropletStore(2 * (len(large) + len(small)))
    store.add(np.vstack([large, small]),
              np.r_[np.full(len(large), large_diameter), np.full(len(small), small_diameter)], 5100.0)
    return Simulation(case, droplets=store, feed=False, box=(tuple(box), (0.0, 0.0, 0.0))), (lower, upper)


def growth_time(case, large_diameter=1.5e-3, small_diameter=0.5e-3) -> float:
    """How long [s] the delayed merge of a ``large_diameter`` and a ``small_diameter`` droplet [m] takes from its mark:
    the smaller partner's contact diameter grows to growth_target x d_m at growth_rate x d_m per second (d_m the
    merged diameter), rounded up to whole fluid steps (:mod:`fulldem.submodels.coalescence`)."""
    c, dt = case.coalescence, case.fulldem.fluid_step
    merged = (large_diameter**3 + small_diameter**3) ** (1.0 / 3.0)
    return dt * np.ceil((c.growth_target * merged - small_diameter) / (c.growth_rate * dt * merged) - 1e-9)


def settle_against_ballistic_kernel(sim, region, end_time, *, large_diameter=1.5e-3, small_diameter=0.5e-3):
    """Run ``sim`` (from :func:`bidisperse_suspension`) to ``end_time`` [s], integrating the ballistic
    differential-settling kernel as it goes: each fluid step adds pi (a_l + a_s)^2 |dU| n_s N_l dt to the expected
    number of large-small contacts, with the mean radii a [m] and counts N of the droplets in the two merges-by-size
    bins at that step, n_s the small droplets over ``region``'s volume [1/m^3] (the region they fill, as (lower,
    upper) (3,) [m]) and dU [m/s] the difference of the two bins' mean vertical velocities, taken two ways:

    * ``slip``: of the droplets' velocities relative to the slag they feel (the interpolated slag velocity of the
      step), the relative velocity of two droplets in the same slag. Where the large droplets stir the slag (a
      cloud sinking, its return flow), both sizes are carried alike, and only this difference brings them together;
    * ``absolute``: of the droplets' velocities, which counts that stirring as approach speed.

    Returns a dict of arrays over the fluid steps, each value at a step's end: ``time`` [s], ``merged`` (the
    large-small merges counted by merges_by_size so far), ``expected`` and ``expected_absolute`` (the kernel's
    integral so far with the two dU); and ``waiting`` (the most pairs marked past their growth time at any step)
    and ``longest`` (the longest a pair was marked [s]). A delayed merge completes its growth time
    (:func:`growth_time`) after the contact: compare its merges at t with the contacts expected at t minus that."""
    from ..submodels.coalescence import size_bin

    lower, upper = region
    volume = float(np.prod(np.asarray(upper) - np.asarray(lower)))
    coalescence = next(m for m in sim.submodels if m.name == "coalescence")
    bin_l, bin_s = int(size_bin(large_diameter)), int(size_bin(small_diameter))
    pair = (min(bin_l, bin_s), max(bin_l, bin_s))

    def bins_of(s):
        bins = size_bin(s.diameter[: s.count])
        return bins == bin_l, bins == bin_s

    rows, expected, expected_absolute, waiting, longest, slip = [], 0.0, 0.0, 0, 0.0, None
    while sim.time < end_time - 1e-12:
        s, n = sim.store, sim.store.count
        is_l, is_s = bins_of(s)
        if is_l.any() and is_s.any():
            w = s.velocity[:n, 2]
            absolute = abs(w[is_l].mean() - w[is_s].mean())
            a = 0.5 * (s.diameter[:n][is_l].mean() + s.diameter[:n][is_s].mean())
            rate = np.pi * a**2 * is_s.sum() / volume * is_l.sum() * sim.dt
            expected += rate * (absolute if slip is None else slip)
            expected_absolute += rate * absolute
        sim.step()
        s, n = sim.store, sim.store.count
        if sim.drift_version == s.version:  # the slag velocities felt are rows of these droplets (else: keep the last)
            is_l, is_s = bins_of(s)
            if is_l.any() and is_s.any():
                relative = s.velocity[:n, 2] - sim.fluid_velocity[:n, 2]
                slip = abs(relative[is_l].mean() - relative[is_s].mean())
        columns = coalescence.columns(sim)
        waiting, longest = max(waiting, columns["pairs_waiting"]), max(longest, columns["longest_marked"])
        rows.append((sim.time, sim.counters.merges_by_size[pair], expected, expected_absolute))
    time, merged, expected, expected_absolute = (np.array(c) for c in zip(*rows))
    return {"time": time, "merged": merged.astype(np.int64), "expected": expected,
            "expected_absolute": expected_absolute, "waiting": waiting, "longest": longest}


def at_time(result, key, t):
    """``result[key]`` (from :func:`settle_against_ballistic_kernel`) at the last step ending by ``t`` [s] (0 before
    the first)."""
    k = np.searchsorted(result["time"], t + 1e-9, side="right")
    return result[key][k - 1] if k else 0
