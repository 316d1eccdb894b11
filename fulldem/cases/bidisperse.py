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
