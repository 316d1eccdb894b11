"""Time per fluid step and pressure-CG iterations of fulldem.fluid on the engine's two grids (prints; not a test).

    python benchmarks/bench_fluid.py [--steps 20]

Grids: the cubic case, 40^3 cells of 5 mm (inlet disk 75 mm radius on the top, outlet disk 7.5 mm radius on x+),
and the deep column, 20 x 20 x 100 cells of 5 mm (inlet 10 mm, outlet 5 mm). Slag rho = 3150 kg/m^3, mu = 0.45 Pa s,
dt = 2e-3 s (the case default). The run starts from a Gaussian downward jet of 0.3 m/s under the inlet (cell
Reynolds number ~10) kept up by a downward force density standing in for the droplet plume's drag reaction, so that
advection works on a real flow. Two void fraction settings: eps = 1 (exact FFT/DCT pressure solve, one CG
iteration per projection) and a smooth eps in [0.7, 1] with a particle flux (PCG, warm-started).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fulldem import boundaries
from fulldem.fluid import solver
from fulldem.fluid import walls as fluid_walls
from fulldem.fluid.grid import Grid


DENSITY = 3150.0
VISCOSITY = 0.45


def plume_force(grid, centre, radius, strength):
    """Downward force density [N/m^3] on z-faces within radius of the vertical axis through centre (x, y)."""
    fz = np.zeros(grid.face_shape(2))
    x, y = grid.cell_centres(0), grid.cell_centres(1)
    inside = (x[:, None] - centre[0]) ** 2 + (y[None, :] - centre[1]) ** 2 < radius**2
    fz[inside, 1:-1] = -strength
    return (np.zeros(grid.face_shape(0)), np.zeros(grid.face_shape(1)), fz)


def plume_state(grid, centre, width, speed):
    """Rest state plus a Gaussian downward jet w = -speed exp(-r^2 / (2 width^2)) on the interior z-faces."""
    state = solver.rest_state(grid)
    x, y = grid.cell_centres(0), grid.cell_centres(1)
    r2 = (x[:, None] - centre[0]) ** 2 + (y[None, :] - centre[1]) ** 2
    state.w[:, :, 1:-1] = -speed * np.exp(-r2 / (2.0 * width**2))[:, :, None]
    return state


def smooth_eps(grid):
    """A smooth void fraction in [0.7, 1] on faces and a matching small particle flux (zero on walls)."""
    eps, flux = [], []
    for axis in range(3):
        coords = [grid.cell_centres(a) if a != axis else grid.face_positions(a) for a in range(3)]
        x, y, z = np.meshgrid(*coords, indexing="ij")
        size = grid.size
        field = np.sin(2 * np.pi * x / size[0]) * np.cos(2 * np.pi * y / size[1]) * np.sin(np.pi * z / size[2])
        eps.append(0.85 + 0.15 * field)
        q = 1e-4 * field
        index = [slice(None)] * 3
        for wall in (0, -1):
            index[axis] = wall
            q[tuple(index)] = 0.0
        flux.append(q)
    return eps, flux


def run(name, grid, boundary, force, initial, steps, variable_eps):
    eps, flux = smooth_eps(grid) if variable_eps else (None, None)
    state = initial
    dt = 2e-3
    for _ in range(3):  # compile and spin up
        state, _ = solver.step(grid, state, boundary, DENSITY, VISCOSITY, dt, eps_faces=eps, particle_flux=flux,
                              force=force)
    iterations = []
    start = time.perf_counter()
    for _ in range(steps):
        state, diagnostics = solver.step(grid, state, boundary, DENSITY, VISCOSITY, dt, eps_faces=eps,
                                        particle_flux=flux, force=force)
        iterations.append(diagnostics.pressure_iterations)
    elapsed = (time.perf_counter() - start) / steps
    label = "eps in [0.7,1]" if variable_eps else "eps = 1       "
    print(f"{name:10s} {str(grid.shape):14s} {label}  {1e3 * elapsed:7.1f} ms/step  "
          f"CG iterations/step {np.mean(iterations):5.1f} (2 projections)  "
          f"cell Re {diagnostics.cell_reynolds:6.1f}  CFL {diagnostics.courant:.3f}  "
          f"max|div| {diagnostics.divergence_residual:.1e} 1/s")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20)
    args = parser.parse_args()

    cubic = Grid.for_box((0.2, 0.2, 0.2), 0.005)
    cubic_boundary = fluid_walls.make_boundary(cubic, inlet=boundaries.InletDisk((0.1, 0.1), 0.075),
                                         outlet=boundaries.OutletDisk("x+", (0.1, 0.03), 0.0075),
                                         inflow_flux=0.022 / DENSITY)
    deep = Grid.for_box((0.1, 0.1, 0.5), 0.005)
    deep_boundary = fluid_walls.make_boundary(deep, inlet=boundaries.InletDisk((0.05, 0.05), 0.01),
                                        outlet=boundaries.OutletDisk("x+", (0.05, 0.03), 0.005),
                                        inflow_flux=0.00038 / DENSITY)
    for variable_eps in (False, True):
        run("cubic", cubic, cubic_boundary, plume_force(cubic, (0.1, 0.1), 0.03, 200.0),
            plume_state(cubic, (0.1, 0.1), 0.02, 0.3), args.steps, variable_eps)
        run("deep", deep, deep_boundary, plume_force(deep, (0.05, 0.05), 0.01, 200.0),
            plume_state(deep, (0.05, 0.05), 0.01, 0.3), args.steps, variable_eps)


if __name__ == "__main__":
    main()
