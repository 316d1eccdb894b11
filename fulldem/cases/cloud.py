"""Set-ups of the collective-settling verification cases, shared by tests/test_fulldem_verification.py,
analysis/verification.py (one row per check, measured against its reference) and the verification report
(reports/verification.py, `settler report verification`, which also draws a cloud turning into a torus).

* Falling cloud: N droplets of radius a in a ball of radius R fall at U_St (1 + 1.2 N a / R) (Nitsche & Batchelor,
  JFM 340 (1997)) in unbounded Stokes flow. The box here is periodic, and its images slow the cloud at first order by
  Hasimoto's (1959) lattice term 2.837 N a U_St / L (the cloud's far field is the Stokeslet of its total weight), so
  the reference is U_St (1 + 1.2 N a/R - 2.837 N a/L).

All lengths in m, times in s, velocities in m/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from settler.cases import load_case
from settler.physics import STANDARD_GRAVITY, stokes_velocity

from ..coupling.mobility import HASIMOTO
from ..droplets import DropletStore
from ..stepper import Simulation
from .suspensions import NITSCHE_BATCHELOR, point_like_overrides, random_ball, settling_speed


def cloud_overrides(diameter, cell, fluid_step, slag_density, density_excess, viscosity, extra=()):
    return point_like_overrides(diameter, cell, fluid_step,
                                [f"matte.density={slag_density + density_excess}",
                                 f"slag.viscosity_reference={viscosity}", *extra])


@dataclass
class Cloud:
    """A falling-cloud set-up: ``count`` droplets of ``diameter`` [m] in a ball of ``radius`` [m] in a periodic cube
    of side ``box`` [m]; ``stokes`` is the single-droplet terminal velocity [m/s]."""

    sim: Simulation
    count: int
    diameter: float
    radius: float
    box: float
    stokes: float

    @property
    def n_a_over_r(self):
        return self.count * 0.5 * self.diameter / self.radius

    def nitsche_batchelor(self):
        """Unbounded Stokes-flow cloud velocity U_St (1 + 1.2 N a/R) [m/s]."""
        return self.stokes * (1.0 + NITSCHE_BATCHELOR * self.n_a_over_r)

    def reference(self):
        """The same in the periodic box: minus Hasimoto's first-order image term 2.837 N a U_St / L [m/s]."""
        return self.nitsche_batchelor() - self.stokes * HASIMOTO * self.count * 0.5 * self.diameter / self.box

    def reynolds(self, velocity):
        """Cloud Reynolds number rho U 2R / mu [-]."""
        return self.sim.density * velocity * 2.0 * self.radius / self.sim.viscosity


def falling_cloud(n_a_over_r, *, cells_per_radius=4, box_radii=8, cell=5e-3, diameter=1.5e-3, reynolds=0.3,
                  viscosity=0.45, fluid_step=None, seed=7, extra=()):
    """A cloud with N a/R ~ ``n_a_over_r`` at rest in a periodic cube of side ``box_radii`` R, R =
    ``cells_per_radius`` cells. The density excess is chosen so that the Nitsche-Batchelor cloud Reynolds number is
    ``reynolds``; a uniform upward body force carries the droplets' total buoyant weight (the mean pressure gradient
    of a periodic box), so the mixture has no net force. fluid_step default: 0.7 of the viscous limit h^2 / (6 nu)."""
    radius = cells_per_radius * cell
    box = box_radii * radius
    count = int(round(n_a_over_r * radius / (0.5 * diameter)))
    slag_density = load_case("simple").slag.density  # the property set's [kg/m^3]
    u_cloud = reynolds * viscosity / (slag_density * 2.0 * radius)
    u_stokes = u_cloud / (1.0 + NITSCHE_BATCHELOR * count * 0.5 * diameter / radius)
    density_excess = u_stokes / stokes_velocity(diameter, 1.0, 0.0, viscosity)  # Stokes, solved for it
    if fluid_step is None:
        fluid_step = 0.7 * cell**2 / (6.0 * viscosity / slag_density)
    case = load_case("simple", cloud_overrides(diameter, cell, fluid_step, slag_density, density_excess, viscosity,
                                               extra))
    positions = random_ball(np.random.default_rng(seed), count, (0.5 * box,) * 3, radius, diameter)
    store = DropletStore(count)
    store.add(positions, diameter, case.matte.density)
    weight = count * math.pi / 6.0 * diameter**3 * (case.matte.density - case.slag.density) * STANDARD_GRAVITY
    sim = Simulation(case, droplets=store, feed=False, box=((box,) * 3, (0.0, 0.0, 0.0)), periodic=(True,) * 3,
                     body_force=(0.0, 0.0, weight / box**3))
    return Cloud(sim, count, diameter, radius, box, sim.terminal_velocity(diameter))


class Unwrapper:
    """Positions [m] of a periodic run followed across the box's faces, droplets matched by ``ident``."""

    def __init__(self, sim):
        self.sim = sim
        self.previous = self._current()
        self.position = self.previous.copy()

    def _current(self):
        s = self.sim.store
        order = np.argsort(s.ident[: s.count])
        return s.position[: s.count][order].copy()

    def update(self):
        now = self._current()
        size = self.sim.grid.size
        jump = now - self.previous
        jump -= size * np.round(jump / size)
        self.position += jump
        self.previous = now
        return self.position


def run_cloud(cloud, t_end, every=1):
    """Step to ``t_end`` [s]; returns times [s] and the unwrapped centroid heights [m] every ``every`` steps."""
    sim = cloud.sim
    follow = Unwrapper(sim)
    times, centroid = [0.0], [follow.position[:, 2].mean()]
    while sim.time < t_end - 1e-9:
        sim.step()
        positions = follow.update()
        if sim.steps % every == 0:
            times.append(sim.time)
            centroid.append(positions[:, 2].mean())
    return np.array(times), np.array(centroid), follow


def check_cloud(n_a_over_r, start_viscous_times=5.0, end_viscous_times=8.0, **setup):
    """Measure the centroid velocity between ``start`` and ``end`` viscous times R^2/nu after release (the periodic
    box's slowest mode relaxes on L^2 / (4 pi^2 nu) = 1.6 R^2/nu for L = 8 R)."""
    cloud = falling_cloud(n_a_over_r, **setup)
    viscous_time = cloud.radius**2 * cloud.sim.density / cloud.sim.viscosity
    initial = gyration_radius(cloud.sim.store.position[: cloud.count])
    times, heights, follow = run_cloud(cloud, end_viscous_times * viscous_time)
    speed = settling_speed(times, heights, start_viscous_times * viscous_time)
    fallen = (heights[0] - heights[-1]) / cloud.radius
    return cloud, speed, fallen, gyration_radius(follow.position) / initial


def gyration_radius(positions):
    """Root-mean-square distance of the droplets from their centroid [m]."""
    return float(np.sqrt(((positions - positions.mean(axis=0)) ** 2).sum(axis=1).mean()))
