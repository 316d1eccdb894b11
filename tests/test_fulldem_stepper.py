"""The coupled engine against independent references: single-droplet terminal velocity (Stokes / Schiller-Naumann
with the box's wall correction), exact momentum balance of the two-way coupling, and exact matte accounting."""

import math

import numpy as np
import pytest

# one droplet released in quiescent slag: the set-up the verification report runs too
from fulldem.cases.single_droplet import single_droplet as _single_droplet
from fulldem.droplets import DropletStore
from fulldem.stepper import Simulation
from settler.cases import load_case
from settler.physics import relaxation_time, square_duct_factor, stokes_velocity

#: the direct kernel takes interior weights near walls (fulldem.near_wall = "wall", the default, is the filtered's)
DIRECT_WALLS = {"filtered": [], "direct": ["fulldem.near_wall=interior"]}


@pytest.mark.parametrize("diameter, tolerance, kernel", [(500e-6, 0.02, "filtered"), (2e-3, 0.03, "filtered"),
                                                         (500e-6, 0.02, "direct"), (2e-3, 0.03, "direct")])
def test_terminal_velocity_with_wall_correction(diameter, tolerance, kernel):
    """A droplet released in quiescent slag in the 0.2 m cube reaches the Schiller-Naumann terminal velocity times
    the square-duct wall factor 1/(1 + 1.903 d/L) (Happel & Brenner), within 2 % (500 um) and 3 % (2 mm), with a fluid
    step of ~32 tau_p for 500 um; with either coupling kernel."""
    sim, v = _single_droplet(diameter, (0.2, 0.2, 0.2), 0.01, 5e-3, 1.5, [f"fulldem.kernel={kernel}",
                                                                          *DIRECT_WALLS[kernel]])
    expected = sim.terminal_velocity(diameter) * square_duct_factor(diameter / 0.2)
    assert v == pytest.approx(expected, rel=tolerance)
    if diameter == 500e-6:
        assert sim.dt / relaxation_time(diameter, 5100.0, 0.45) > 30.0  # the fluid step is far above tau_p


def test_terminal_velocity_with_dem_step_ten_relaxation_times():
    """The exponential drag integrator is exact for any step: DEM step = 10 tau_p gives the same terminal velocity."""
    tau = relaxation_time(500e-6, 5100.0, 0.45)
    sim, v = _single_droplet(500e-6, (0.2, 0.2, 0.2), 0.01, 20 * tau, 0.6, [f"fulldem.dem_step={10 * tau}"])
    assert sim.dem_step == pytest.approx(10 * tau, rel=1e-12)
    expected = sim.terminal_velocity(500e-6) * square_duct_factor(500e-6 / 0.2)
    assert v == pytest.approx(expected, rel=0.02)


def test_terminal_velocity_at_reynolds_ten():
    """A 10 mm droplet (Re ~ 10, the size coalesced droplets reach in the deep case) settles at the Schiller-Naumann
    terminal velocity within 5 %: the self-induced-velocity correction with its Oseen factor holds at finite Re.
    Box 0.3 x 0.3 x 0.5 m so that the wall factor (first order 0.94 in Stokes flow, closer to 1 at Re 10) stays
    inside the tolerance."""
    sim, v = _single_droplet(10e-3, (0.3, 0.3, 0.5), 0.01, 5e-3, 0.6)
    v_sn = sim.terminal_velocity(10e-3)
    assert v_sn < 0.7 * stokes_velocity(10e-3, 5100.0, 3150.0, 0.45)  # the Re correction matters here
    assert v == pytest.approx(v_sn, rel=0.05)


def _random_cloud(rng, n, size, d, margin):
    out = []
    while len(out) < n:
        p = rng.uniform(margin, size - margin, 3)
        if all(np.sum((p - q) ** 2) > (1.05 * d) ** 2 for q in out):
            out.append(p)
    return np.array(out)


@pytest.mark.parametrize("kernel", [["fulldem.kernel=filtered"], ["fulldem.kernel=direct", "fulldem.near_wall=interior"],
                                    ["fulldem.kernel=filtered", "fulldem.sigma_diameter=5"]],
                         ids=["filtered", "direct", "filtered_and_direct"])
def test_momentum_balance_in_a_periodic_box(kernel):
    """Fluid + droplets + the impulse owed to the fluid change only by the imposed body forces, to round-off; here
    the mean pressure gradient b balances the droplets' buoyant weight, so the total stays constant while the
    droplets settle and drag the fluid. Also: the reaction the fluid is owed equals minus the drag impulses. For
    both coupling kernels, and for a mixture (sigma_diameter = 5: droplets above 1 mm are wider than a cell and
    take the direct kernel, the others the filtered one)."""
    case = load_case("simple", ["feed.mass_rate=0", "coalescence.enabled=false", "fulldem.cell_size=0.005",
                                "fulldem.fluid_step=0.002", *kernel])
    rng = np.random.default_rng(4)
    size, n, d = 0.05, 150, 1.2e-3
    store = DropletStore(256)
    store.add(_random_cloud(rng, n, size, d, 0.0), rng.uniform(0.8, 1.2, n) * d, 5100.0)
    volume = math.pi / 6 * store.diameter[:n] ** 3
    weight = np.sum((5100.0 - 3150.0) * volume) * 9.80665  # buoyant weight, downward
    body = (0.0, 0.0, weight / size**3)  # b acts upward on the mixture, per unit volume
    sim = Simulation(case, droplets=store, feed=False, box=((size,) * 3, (0.0, 0.0, 0.0)),
                     periodic=(True, True, True), body_force=body)
    wide = sim._wide().size
    mixed = "fulldem.sigma_diameter=5" in kernel
    assert (0 < wide < n) if mixed else (wide == 0)
    sim.step()
    start = sim.momentum()
    scale = np.sum(np.abs(sim.impulse[:n]))
    for _ in range(15):
        sim.step()
        owed = np.array([np.sum(sim.owed_force[a][:size_index(sim, a)]) for a in range(3)])
        np.testing.assert_allclose(owed * sim.dt * sim.grid.cell_volume, -sim.impulse[:n].sum(axis=0),
                                   rtol=0, atol=1e-12 * scale)
    end = sim.momentum()
    assert np.abs(end - start).max() < 1e-10 * scale
    assert np.abs(store.velocity[:n, 2]).mean() > 1e-4  # something did move


def size_index(sim, axis):
    return sim.grid.shape[axis]  # periodic: the last face is the first one again


def test_mass_accounting_with_feed_and_exits():
    """fed = in slag + settled + lost to 1e-12 relative over a fed run with a slag through-flow and an outlet."""
    case = load_case("cubic", ["geometry.height=0.04", "geometry.width=0.04", "geometry.depth=0.04",
                               "geometry.inlet_diameter=0.03", "geometry.outlet_diameter=0.012",
                               "geometry.outlet_height=0.008", "slag.feed_rate=0.02", "feed.mass_rate=1e-3",
                               "feed.mean_diameter=2e-3", "coalescence.size_limit=4e-3", "fulldem.cell_size=0.004",
                               "fulldem.fluid_step=0.004"])
    store = DropletStore(64)
    # a few droplets start at the outlet's mouth and on the floor, so both exits are exercised early
    store.add([[0.037, 0.02, 0.008], [0.036, 0.018, 0.01], [0.02, 0.02, 0.0012]], 2e-3, 5100.0)
    initial = float(np.sum(store.mass()))
    sim = Simulation(case, droplets=store)
    for _ in range(120):
        sim.step()
    c = sim.counters
    fed = initial + c.mass_fed
    balance = fed - sim.mass_in_slag() - c.mass_settled - c.mass_lost
    assert abs(balance) <= 1e-12 * fed
    assert c.fed > 10 and c.settled >= 1 and c.lost >= 1


def test_phase_timers_cover_the_whole_step():
    """Simulation.phase_times names every part of a step: the phases sum to the step's wall time within 5 %
    (what benchmarks/bench_steady.py promises), the fluid's stages included."""
    import time

    case = load_case("cubic", ["geometry.height=0.04", "geometry.width=0.04", "geometry.depth=0.04",
                               "geometry.inlet_diameter=0.03", "feed.mass_rate=1e-3", "feed.mean_diameter=1e-3",
                               "fulldem.cell_size=0.004", "fulldem.fluid_step=0.004"])
    sim = Simulation(case)
    for _ in range(5):  # compilation out of the timed steps
        sim.step()
    sim.phase_times.reset()
    wall = 0.0
    for _ in range(20):
        t0 = time.perf_counter()
        sim.step()
        wall += time.perf_counter() - t0
    phases = sim.phase_times
    assert phases.steps == 20
    assert {"dem", "fluid: pressure", "fluid: momentum", "deposit volume", "interpolate", "sort"} <= set(phases.seconds)
    assert abs(phases.total() - wall) <= 0.05 * wall
