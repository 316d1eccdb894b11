"""Set-ups of the collective-settling verification cases, shared by tests/test_fulldem_verification.py,
analysis/verification.py (one row per check, measured against its reference) and the verification report
(reports/verification.py, `settler report verification`, which also draws a cloud turning into a torus).

* Hindered settling: an initially uniform random suspension of monodisperse droplets fills the lower part of a box,
  periodic in x and y, walls in z (closed top and bottom, so the mixture's volume flux is zero); the height with
  5 % of the droplets above it (the top interface) descends at the Richardson-Zaki velocity U_St (1 - phi)^4.65
  (Richardson & Zaki 1954), U_St the single-droplet Schiller-Naumann terminal velocity.
* Homogeneous suspension: the same in a fully periodic box, settling speed in the frame of zero volume flux.

All lengths in m, times in s, velocities in m/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from settler.cases import load_case
from settler.physics import STANDARD_GRAVITY, richardson_zaki_factor, sphere_volume

from ..droplets import DropletStore
from ..fluid.solver import total_momentum
from ..stepper import Simulation


NITSCHE_BATCHELOR = 1.2  # 6/5: a drop of suspension, viscosity ratio 1 (Hadamard-Rybczynski)


def point_like_overrides(diameter, cell, fluid_step, extra=()):
    """Case overrides for monodisperse point-like droplets: no feed, no coalescence, the contact stiffness set for
    ``diameter`` (the feed's mean diameter is the stiffness reference), and contacts softened to max_overlap 0.1
    with 8 steps per contact: contacts are rare in these dilute suspensions and only need to keep droplets apart,
    and the DEM then needs a few sub-steps per fluid step instead of ~150."""
    return ["feed.mass_rate=0", "coalescence.enabled=false", f"feed.mean_diameter={diameter}",
            "feed.scale_min=0.99", "feed.scale_max=1.01", "fulldem.max_overlap=0.1", "fulldem.contact_steps=8",
            f"fulldem.cell_size={cell}", f"fulldem.fluid_step={fluid_step}", *extra]


def separate(points, diameter, draw, gap, tries=1000, period=None):
    """Redraw (with ``draw(k)``) the later member of every pair closer than ``gap * diameter`` until none is;
    ``period``: box edge lengths [m] of a periodic box (distances by minimum image)."""
    for _ in range(tries):
        pairs = cKDTree(points, boxsize=period).query_pairs(gap * diameter, output_type="ndarray")
        if len(pairs) == 0:
            return points
        bad = np.unique(pairs[:, 1])
        points[bad] = draw(len(bad))
    raise RuntimeError("separate: could not place the droplets without overlap")


def random_suspension(rng, count, lower, upper, diameter, gap=1.02):
    """``count`` non-overlapping centres uniform in the box [lower, upper] [m], each droplet inside it."""
    lo = np.asarray(lower, float) + 0.5 * gap * diameter
    hi = np.asarray(upper, float) - 0.5 * gap * diameter
    return separate(rng.uniform(lo, hi, (count, 3)), diameter, lambda k: rng.uniform(lo, hi, (k, 3)), gap)


def random_periodic_suspension(rng, count, size, diameter, gap=1.02):
    """``count`` centres uniform in the periodic box [0, size), no two closer than ``gap * diameter`` [m]."""
    size = np.asarray(size, float)
    return separate(rng.uniform(0.0, 1.0, (count, 3)) * size, diameter,
                    lambda k: rng.uniform(0.0, 1.0, (k, 3)) * size, gap, period=size)


def random_ball(rng, count, centre, radius, diameter, gap=1.05):
    """``count`` non-overlapping centres uniform in the ball of ``radius`` [m] (droplets inside it) about ``centre``."""
    inner = radius - 0.5 * diameter

    def draw(k):
        out = np.empty((0, 3))
        while len(out) < k:
            p = rng.uniform(-inner, inner, (2 * k, 3))
            out = np.concatenate([out, p[np.einsum("ij,ij->i", p, p) <= inner**2]])
        return out[:k]

    return np.asarray(centre, float) + separate(draw(count), diameter, draw, gap)


def hindered_suspension(phi, *, diameter=2e-3, cell=6e-3, width=0.036, height=0.072, fill=0.066, fluid_step=0.01,
                        seed=1, extra=()):
    """A uniform random suspension at volume fraction ``phi`` of droplets of ``diameter`` [m] (matte 5100 in slag
    3150 kg/m^3, 0.45 Pa s) filling the box from the floor to ``fill`` [m]; box width x width x height [m], periodic
    in x and y, walls in z; droplets touching the floor are removed as settled. Returns the Simulation."""
    case = load_case("simple", point_like_overrides(diameter, cell, fluid_step, extra))
    count = int(round(phi * width * width * fill / sphere_volume(diameter)))
    positions = random_suspension(np.random.default_rng(seed), count, (0.0, 0.0, 0.0), (width, width, fill),
                                  diameter)
    store = DropletStore(count)
    store.add(positions, diameter, case.matte.density)
    return Simulation(case, droplets=store, feed=False, box=((width, width, height), (0.0, 0.0, 0.0)),
                      periodic=(True, True, False))


def homogeneous_suspension(phi, *, diameter=2e-3, cell=6e-3, size=0.048, fluid_step=0.01, seed=1, extra=()):
    """The same droplets filling a fully periodic cube of side ``size`` [m] at volume fraction ``phi``; a uniform
    upward body force (the mean pressure gradient) carries their total buoyant weight. Returns the Simulation."""
    case = load_case("simple", point_like_overrides(diameter, cell, fluid_step, extra))
    count = int(round(phi * size**3 / sphere_volume(diameter)))
    positions = random_periodic_suspension(np.random.default_rng(seed), count, (size,) * 3, diameter)
    store = DropletStore(count)
    store.add(positions, diameter, case.matte.density)
    volume = count * math.pi / 6.0 * diameter**3
    weight = volume * (case.matte.density - case.slag.density) * STANDARD_GRAVITY
    return Simulation(case, droplets=store, feed=False, box=((size,) * 3, (0.0, 0.0, 0.0)), periodic=(True,) * 3,
                      body_force=(0.0, 0.0, weight / size**3))


def batch_settling_speed(sim):
    """Settling speed [m/s] of the droplets in the frame of zero mixture volume flux (a batch settler's frame):
    (1 - phi) (u_f - v), u_f the fluid's interstitial mean velocity, v the droplets' mean velocity (z, downward +).
    In a periodic box the frame moves: the drag reaction is owed one step, so the total momentum (zero) includes
    that impulse in transit and fluid and droplets drift upward together; only their difference is physical."""
    store, n = sim.store, sim.store.count
    droplet_volume = float(np.sum(sphere_volume(store.diameter[:n])))
    box_volume = float(np.prod(sim.grid.size))
    fluid_momentum = total_momentum(sim.grid, sim.fluid, sim.density, sim.momentum_eps)[2]
    fluid_velocity = fluid_momentum / (sim.density * (box_volume - droplet_volume))
    return (1.0 - droplet_volume / box_volume) * (fluid_velocity - float(store.velocity[:n, 2].mean()))


@dataclass
class FrontRecord:
    """Time series of a settling suspension: ``front`` [m] is the height with ``quantile`` of the initial droplets
    above it (settled droplets count as below everything); ``bulk`` [m/s] the mean settling speed of droplets more
    than 2.5 kernel widths from the front and the floor (nan when there are none)."""

    times: np.ndarray
    front: np.ndarray
    bulk: np.ndarray
    count: int
    quantile: float


def run_hindered(sim, t_end, quantile=0.05):
    """Step ``sim`` to ``t_end`` [s], recording the front and the bulk speed after every step."""
    store = sim.store
    initial = store.count
    above = int(round(quantile * initial))
    reach = 2.5 * max(sim.case.fulldem.sigma_cells * sim.grid.spacing,
                      sim.case.fulldem.sigma_diameter * float(store.diameter[0]))
    times, front, bulk = [], [], []
    while sim.time < t_end - 1e-9:
        sim.step()
        n = store.count
        z = store.position[:n, 2]
        top = float(np.partition(z, n - above - 1)[n - above - 1]) if n > above else math.nan
        inside = (z > sim.lower[2] + reach) & (z < top - reach)
        times.append(sim.time)
        front.append(top)
        bulk.append(-float(store.velocity[:n, 2][inside].mean()) if inside.any() else math.nan)
    return FrontRecord(np.array(times), np.array(front), np.array(bulk), initial, quantile)


def front_speed(record, t_start):
    """Descent speed of the front [m/s]: least-squares slope over times >= t_start."""
    keep = record.times >= t_start - 1e-9
    return -float(np.polyfit(record.times[keep], record.front[keep], 1)[0])


def settling_speed(times, heights, t_start, t_end=math.inf):
    """Least-squares descent speed [m/s] over t_start <= t <= t_end."""
    keep = (times >= t_start - 1e-9) & (times <= t_end + 1e-9)
    return -float(np.polyfit(times[keep], heights[keep], 1)[0])


def check_hindered(phi, t_end, t_start=1.0, **setup):
    sim = hindered_suspension(phi, **setup)
    record = run_hindered(sim, t_end)
    u_stokes = sim.terminal_velocity(float(sim.store.diameter[0]))
    u_rz = u_stokes * richardson_zaki_factor(phi)
    speed = front_speed(record, t_start)
    n = sim.store.count
    # every droplet is in the slag or counted settled (none lost through the periodic sides; positions are wrapped
    # at the start of each DEM step, so within a step's travel of the box); the front stayed in the suspension
    d = float(sim.store.diameter[0])
    assert n + sim.counters.settled == record.count
    assert np.all((sim.store.position[:n, :2] >= -d) & (sim.store.position[:n, :2] <= sim.grid.size[:2] + d))
    assert record.front[-1] > 0.3 * record.front[0]
    droplet_re = sim.density * u_rz * float(sim.store.diameter[0]) / sim.viscosity
    return speed / u_rz, record, sim, droplet_re


def check_homogeneous(phi, t_start=0.5, t_end=1.5, **setup):
    """Run :func:`homogeneous_suspension` to ``t_end`` [s]; returns (the Simulation, the Richardson-Zaki velocity
    [m/s], the batch settling speeds [m/s] of :func:`batch_settling_speed` after every step past ``t_start``)."""
    sim = homogeneous_suspension(phi, **setup)
    u_rz = sim.terminal_velocity(float(sim.store.diameter[0])) * richardson_zaki_factor(phi)
    speeds = []
    while sim.time < t_end - 1e-9:
        sim.step()
        if sim.time > t_start:
            speeds.append(batch_settling_speed(sim))
    return sim, u_rz, np.array(speeds)
