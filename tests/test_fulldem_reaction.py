"""The reaction submodel (seed paper section 3.3.2) against the fit's closed forms and the matte accounting.

References: settler.physics.reacted_mass (the FeS a droplet of original size d0 has lost by a given age, written
from the species masses, not from the density and size the engine sets); Eq. 4 and 5 at the fit's composition;
fed = in slag + settled + lost + reacted, exactly; Cantera's equilibrium grade as the end state.
"""

import math

import numpy as np
import pytest

from fulldem.droplets import DropletStore
from fulldem.stepper import Simulation
from settler.cases import load_case
from settler.physics import matte_density, reacted_mass, reaction_fraction, relative_diameter

DEEP_SMALL = ["feed.mass_rate=0", "geometry.height=0.04", "geometry.width=0.04", "geometry.depth=0.04",
              "geometry.inlet_diameter=0.01", "geometry.outlet_diameter=0.0", "slag.feed_rate=0", "fulldem.cell_size=0.005",
              "fulldem.fluid_step=0.002", "reaction.time_constant=0.2"]


def _droplets(extra=(), ages=(0.0, 0.1, 0.5), d0=0.6e-3):
    case = load_case("deep", [*DEEP_SMALL, *extra])
    store = DropletStore(16)
    n = len(ages)
    store.add([[0.01 + 0.01 * k, 0.02, 0.03] for k in range(n)], d0, case.matte.density, age=list(ages))
    return case, Simulation(case, droplets=store, feed=False)


def test_continuous_reaction_follows_the_fit_and_books_the_fes_removed():
    """After 50 steps each droplet has the fit's density (Eq. 4) and size (Eq. 5) at its age, its original diameter
    (its Cu2S) is unchanged, and mass_reacted equals the FeS that settler.physics.reacted_mass says the droplets lost
    since the start (the first step sets the fed sizes: the start is the state after it)."""
    case, sim = _droplets()
    s = sim.store
    sim.step()
    age0 = s.age[:3].copy()
    mass0 = float(np.sum(s.mass()))
    booked0 = sim.counters.mass_reacted
    for _ in range(50):
        sim.step()
    x0, xf, tau = case.x_initial, case.x_final, case.reaction.time_constant
    for p in range(3):
        assert s.age[p] == pytest.approx(age0[p] + 50 * sim.dt, rel=1e-12)
        x = reaction_fraction(s.age[p], x0, xf, tau)
        assert s.density[p] == pytest.approx(matte_density(x), rel=1e-14)
        assert s.diameter[p] == pytest.approx(0.6e-3 * relative_diameter(x, x0), rel=1e-14)
        assert s.original_diameter[p] == 0.6e-3
    lost = sum(reacted_mass(0.6e-3, s.age[p], x0, xf, tau) - reacted_mass(0.6e-3, age0[p], x0, xf, tau)
               for p in range(3))
    assert lost > 0.0
    assert sim.counters.mass_reacted - booked0 == pytest.approx(lost, rel=1e-9)
    assert mass0 - float(np.sum(s.mass())) == pytest.approx(lost, rel=1e-9)
    assert s.density[2] > s.density[0] and s.diameter[2] < s.diameter[0]  # older: denser and smaller


def test_stepped_reaction_uses_the_papers_materials():
    """Densities are the materials 4500, 4550, ... 5200 kg/m^3 (deep case: rho(X0) = 4500, rho(X_inf) = 5200),
    the one nearest the fit's; crossing a boundary counts as a re-creation; sizes follow the fit continuously."""
    case, sim = _droplets(["reaction.mode=stepped"], ages=(0.0, 0.05, 0.3))
    s = sim.store
    seen = set()
    for _ in range(60):
        sim.step()
        seen.update(np.round(s.density[:3], 6).tolist())
    materials = 4500.0 + 50.0 * np.arange(15)
    assert all(np.isclose(materials, d).any() for d in seen) and len(seen) >= 4
    x = np.array([reaction_fraction(a, case.x_initial, case.x_final, case.reaction.time_constant) for a in s.age[:3]])
    np.testing.assert_allclose(np.abs(s.density[:3] - 1000.0 * (3.9732 + 1.3012 * x)), 0.0, atol=25.0 + 1e-9)
    np.testing.assert_allclose(s.diameter[:3], 0.6e-3 * np.array([relative_diameter(v, case.x_initial) for v in x]),
                               rtol=1e-14)
    assert sim.counters.recreated >= 3


def test_mass_accounting_with_feed_exits_coalescence_and_reaction():
    """fed = in slag + settled + lost + reacted to 1e-12 of the fed mass, in a fed, reacting, coalescing run with
    a slag through-flow and a side outlet."""
    case = load_case("deep", ["geometry.height=0.06", "geometry.width=0.04", "geometry.depth=0.04",
                              "geometry.inlet_diameter=0.03", "geometry.outlet_diameter=0.012",
                              "geometry.outlet_height=0.008", "slag.feed_rate=0.02", "feed.mass_rate=1e-3",
                              "feed.mean_diameter=1.5e-3", "fulldem.cell_size=0.004", "fulldem.fluid_step=0.004",
                              "reaction.time_constant=0.1"])
    store = DropletStore(64)
    store.add([[0.037, 0.02, 0.008], [0.036, 0.018, 0.01], [0.02, 0.02, 0.0012]], 1.5e-3, case.matte.density)
    initial = float(np.sum(store.mass()))
    sim = Simulation(case, droplets=store)
    for _ in range(150):
        sim.step()
    c = sim.counters
    fed = initial + c.mass_fed
    balance = fed - sim.mass_in_slag() - c.mass_settled - c.mass_lost - c.mass_reacted
    assert abs(balance) <= 1e-12 * fed
    assert c.fed > 10 and c.settled >= 1 and c.lost >= 1 and c.mass_reacted > 0.0


def test_equilibrium_end_state_follows_the_slag_temperature():
    """With end_state = 'equilibrium' an old droplet (age 40 tau) has the density of Cantera's equilibrium grade
    at the slag's temperature and oxygen pressure, which differs between 1500 K and 1600 K."""
    from settler.thermo import equilibrium_grade

    grades = []
    for temperature in (1500.0, 1600.0):
        case, sim = _droplets(["reaction.end_state=equilibrium", f"slag.temperature={temperature}"], ages=(8.0,))
        sim.step()
        r = case.reaction
        grade = equilibrium_grade(temperature, r.oxygen_pressure, p_so2=r.so2_pressure, a_feo=r.feo_activity)
        assert sim.store.density[0] == pytest.approx(matte_density(grade), rel=1e-12)
        grades.append(grade)
    assert abs(grades[0] - grades[1]) > 1e-3
    assert math.isfinite(grades[0])
