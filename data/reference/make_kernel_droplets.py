"""Writes kernel_droplets.csv, the initial droplets of the reference set's kernel run (design.toml, run 'kernel').

6 000 droplets of 0.5 mm and 6 000 of 1.0 mm [chosen: a 2:1 size ratio whose Stokes velocities differ by 1.9 mm/s
in the demo's slag, so that gravitational collisions between the two sizes dominate], on a random subset of a
3.5 mm lattice filling x, y in [5, 95] mm and z in [10, 90] mm of the demo's 100 mm box, jittered by up to 0.5 mm
(no two droplets touch), sizes shuffled: a volume fraction of 0.54 % in the filled region. Seed 20261203 [chosen].

    python data/reference/make_kernel_droplets.py      # rewrites data/reference/kernel_droplets.csv
"""

from pathlib import Path

import numpy as np

SEED = 20261203
SPACING = 3.5e-3
JITTER = 0.5e-3
COUNT = 6000  # of each size
DIAMETERS = (0.5e-3, 1.0e-3)


def droplets() -> np.ndarray:
    """(x, y, z, diameter) rows [m]."""
    rng = np.random.default_rng(SEED)
    xs = np.arange(5e-3 + 0.5 * SPACING, 95e-3, SPACING)
    zs = np.arange(10e-3 + 0.5 * SPACING, 90e-3, SPACING)
    gx, gy, gz = np.meshgrid(xs, xs, zs, indexing="ij")
    sites = np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()])
    chosen = sites[rng.choice(len(sites), 2 * COUNT, replace=False)]
    chosen += rng.uniform(-JITTER, JITTER, chosen.shape)
    diameter = rng.permutation(np.repeat(DIAMETERS, COUNT))
    return np.column_stack([chosen, diameter])


if __name__ == "__main__":
    path = Path(__file__).with_name("kernel_droplets.csv")
    rows = droplets()
    lines = ["x,y,z,diameter"] + [",".join(f"{v:.7g}" for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    print(f"{path}: {len(rows)} droplets")
