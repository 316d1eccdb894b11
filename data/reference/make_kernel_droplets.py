"""Writes the initial droplets of the reference set's kernel runs (design.toml, runs 'kernel' and 'kernel_ratio4').

kernel_droplets.csv: 6 000 droplets of 0.5 mm and 6 000 of 1.0 mm [chosen: a 2:1 size ratio whose Stokes
velocities differ by 1.9 mm/s in the demo's slag, so that gravitational collisions between the two sizes dominate],
on a random subset of a 3.5 mm lattice filling x, y in [5, 95] mm and z in [10, 90] mm of the demo's 100 mm box,
jittered by up to 0.5 mm (no two droplets touch), sizes shuffled: a volume fraction of 0.54 % in the filled region.
Seed 20261203 [chosen].

kernel_ratio4_droplets.csv: 6 000 of 0.35 mm and 1 500 of 1.4 mm [chosen: a 4:1 size ratio, both below the demo's
1.5 mm size limit and so is a merged pair (1.41 mm), Stokes velocities 0.29 and 4.6 mm/s; whether the collision
efficiency measured at 2:1 holds at 4:1 decides how popbal's sectional kernel grows large droplets], on the same
lattice and jitter with seed 20261204 [chosen]: a volume fraction of 0.35 % in the filled region.

    python data/reference/make_kernel_droplets.py      # rewrites both files in data/reference/
"""

from pathlib import Path

import numpy as np

SEED = 20261203
SPACING = 3.5e-3
JITTER = 0.5e-3
COUNT = 6000  # of each size
DIAMETERS = (0.5e-3, 1.0e-3)
#: file -> (seed, {diameter [m]: count})
RUNS = {"kernel_droplets.csv": (SEED, {DIAMETERS[0]: COUNT, DIAMETERS[1]: COUNT}),
        "kernel_ratio4_droplets.csv": (20261204, {0.35e-3: 6000, 1.4e-3: 1500})}


def droplets(seed: int = SEED, counts: dict | None = None) -> np.ndarray:
    """(x, y, z, diameter) rows [m]: ``counts`` {diameter: number} on random lattice sites (module docstring)."""
    counts = counts or dict.fromkeys(DIAMETERS, COUNT)
    rng = np.random.default_rng(seed)
    xs = np.arange(5e-3 + 0.5 * SPACING, 95e-3, SPACING)
    zs = np.arange(10e-3 + 0.5 * SPACING, 90e-3, SPACING)
    gx, gy, gz = np.meshgrid(xs, xs, zs, indexing="ij")
    sites = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    total = sum(counts.values())
    chosen = sites[rng.choice(len(sites), total, replace=False)]
    chosen += rng.uniform(-JITTER, JITTER, chosen.shape)
    diameter = rng.permutation(np.concatenate([np.full(n, d) for d, n in counts.items()]))
    return np.column_stack([chosen, diameter])


if __name__ == "__main__":
    for name, (seed, counts) in RUNS.items():
        path = Path(__file__).with_name(name)
        rows = droplets(seed, counts)
        lines = ["x,y,z,diameter"] + [",".join(f"{v:.7g}" for v in row) for row in rows]
        path.write_text("\n".join(lines) + "\n")
        print(f"{path}: {len(rows)} droplets")
