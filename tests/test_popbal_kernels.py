"""popbal kernels: Numba kernels against their NumPy twins, invariants, closures and the shared-physics plumbing."""

import math

import numpy as np
import pytest

import popbal
from popbal import closures, reference
from popbal.grid import make_grid, split_to_pivots, volume_of
from popbal.kernels import (AGE, FES_REMOVED, NUMBER, QUANTITIES, RULE_PROBABILITY, RULE_STEP, cell_average_rates,
                            collision_kernel, composition_age, merger_speed_limit, react_zone, transport_zone)
from settler.cases import CaseError, load_case
from settler.derived import settling_velocity
from settler.physics import (FORM_LUO, FORM_SEED, coalescence_probability, density_at_age, droplet_rate,
                             hadamard_rybczynski_factor, reacted_mass, relative_diameter_at_age, stokes_velocity)


def _cell(rng, grid, quantities=QUANTITIES):
    content = np.zeros((quantities, grid.size))
    content[NUMBER] = rng.uniform(0.0, 1e6, grid.size) * (rng.random(grid.size) < 0.8)
    for q in range(1, quantities):
        content[q] = content[NUMBER] * grid.pivots * rng.uniform(0.0, 5.0, grid.size)
    return content


@pytest.fixture
def grid():
    return make_grid(volume_of(200e-6), volume_of(1.5e-3), 2)


def test_grid_pivots_midpoints_and_size_limit(grid):
    assert grid.pivots[-1] == pytest.approx(volume_of(1.5e-3), rel=1e-14)
    assert grid.pivots[0] <= volume_of(200e-6)
    assert np.allclose(0.5 * (grid.edges[:-1] + grid.edges[1:]), grid.pivots, rtol=1e-14)
    assert np.allclose(grid.pivots[1:] / grid.pivots[:-1], 2**0.5, rtol=1e-12)
    sums = grid.pivots[:, None] + grid.pivots[None, :]
    ok = grid.target >= 0
    assert np.all(sums[~ok] > grid.volume_limit) and np.all(sums[ok] <= grid.volume_limit * (1 + 1e-12))
    assert np.all(grid.edges[grid.target[ok]] <= sums[ok]) and np.all(sums[ok] < grid.edges[grid.target[ok] + 1])


def test_cell_average_kernel_matches_numpy_twin_and_conserves(grid):
    rng = np.random.default_rng(1)
    beta = rng.uniform(0.0, 1e-9, (grid.size, grid.size))
    beta = beta + beta.T
    births = np.zeros((QUANTITIES + 1, grid.size))
    rates = np.zeros((QUANTITIES, grid.size))
    for _ in range(5):
        content = _cell(rng, grid)
        cell_average_rates(content, grid.pivots, grid.target, beta, births, rates)
        twin = reference.cell_average_rates(content, grid.pivots, grid.target, beta)
        assert np.allclose(rates, twin, rtol=1e-12, atol=1e-12 * np.abs(twin).max())
        # volume and the carried quantities are invariants of every merger
        scale = np.abs(rates[NUMBER] * grid.pivots).max()
        assert abs(rates[NUMBER] @ grid.pivots) < 1e-13 * scale
        for q in (AGE, FES_REMOVED):
            assert abs(rates[q].sum()) < 1e-13 * np.abs(rates[q]).max()
        # no merger beyond the size limit: the top section only gains
        assert rates[NUMBER, -1] >= 0.0


def test_collision_kernel_matches_numpy_twin(grid):
    rng = np.random.default_rng(2)
    number = rng.uniform(0.0, 1e7, grid.size)
    number[3] = 0.0
    d = grid.diameters * rng.uniform(0.9, 1.0, grid.size)
    v = rng.uniform(1e-4, 1e-2, grid.size)
    rho = rng.uniform(4500.0, 5200.0, grid.size)
    beta = np.zeros((grid.size, grid.size))
    for rule, form, shear in [(RULE_STEP, FORM_SEED, 1.3), (RULE_PROBABILITY, FORM_LUO, 0.0),
                              (RULE_PROBABILITY, FORM_SEED, 50.0)]:
        args = (3150.0, 0.01, 1.0, 0.5, form, 0.5, rule, 0.7)
        collision_kernel(number, grid.pivots, d, v, rho, shear, *args, np.empty((0, 0)), grid.target, beta)
        twin = reference.collision_kernel(number, grid.pivots, d, v, rho, shear, *args, grid.target)
        assert np.allclose(beta, twin, rtol=1e-12, atol=0.0)
        assert np.all(beta[3] == 0.0) and np.all(beta[grid.target < 0] == 0.0)


def test_speed_limit_table_reproduces_the_step_rule(grid):
    sigma, rho_d, rho_s = 1e-3, 5100.0, 3150.0  # a low tension so that the threshold is reached at 0.1-1 m/s
    limit = np.array([[merger_speed_limit(a, b, rho_d, rho_s, sigma, 1.0, 0.5, FORM_SEED, 0.5)
                       for b in grid.diameters] for a in grid.diameters])
    p = coalescence_probability(grid.diameters[0], grid.diameters[-1], limit[0, -1], rho_d, rho_s, sigma)
    assert p == pytest.approx(0.5, rel=1e-9)
    rng = np.random.default_rng(3)
    number = np.full(grid.size, 1e6)
    d, rho = grid.diameters, np.full(grid.size, rho_d)
    beta_table, beta_direct = np.zeros((2, grid.size, grid.size))
    for _ in range(3):
        v = rng.uniform(0.0, 2.0 * limit.max(), grid.size)
        shear = rng.uniform(0.0, 2000.0)
        args = (rho_s, sigma, 1.0, 0.5, FORM_SEED, 0.5, RULE_STEP, 1.0)
        collision_kernel(number, grid.pivots, d, v, rho, shear, *args, limit, grid.target, beta_table)
        collision_kernel(number, grid.pivots, d, v, rho, shear, *args, np.empty((0, 0)), grid.target, beta_direct)
        assert np.array_equal(beta_table, beta_direct)


def test_transport_kernel_matches_numpy_twin_and_conserves():
    rng = np.random.default_rng(4)
    cells, sections, dz, dt = 12, 4, 0.01, 0.7
    content = rng.uniform(0.0, 1.0, (cells, QUANTITIES, sections))
    velocity = rng.uniform(0.0, 0.05, (cells, sections))
    sink = np.where(np.arange(cells) == 3, 0.2, 0.0)
    source = rng.uniform(0.0, 1.0, (QUANTITIES, sections))
    new = content.copy()
    bottom, lost = np.zeros((2, QUANTITIES, sections))
    transport_zone(new, velocity, sink, source, dz, dt, bottom, lost)
    twin, twin_bottom, twin_lost = reference.transport_zone(content, velocity, sink, source, dz, dt)
    assert np.allclose(new, twin, rtol=1e-12) and np.allclose(bottom, twin_bottom, rtol=1e-12)
    assert np.allclose(lost, twin_lost, rtol=1e-12)
    before = content.sum(axis=0) * dz + dt * source * dz
    after = new.sum(axis=0) * dz + bottom + lost
    assert np.allclose(before, after, rtol=1e-13)
    assert np.all(new >= 0.0)


def test_reaction_follows_the_shared_fit_and_books_the_fes():
    case = load_case("deep")
    x0, xf, tau = case.x_initial, case.x_final, case.reaction.time_constant
    d0 = 500e-6
    for age in (0.0, 7.0, 60.0, 300.0):
        removed = reacted_mass(d0, age, x0, xf, tau)
        assert composition_age(removed, d0, x0, xf, tau) == pytest.approx(age, abs=1e-9 * tau)
        # Eq. 4-5 consistency: mass = density x volume of the shrunk droplet
        mass = density_at_age(age, x0, xf, tau) * volume_of(d0 * relative_diameter_at_age(age, x0, xf, tau))
        assert mass == pytest.approx(case.matte.density * volume_of(d0) - removed, rel=1e-12)
    grid = make_grid(volume_of(d0), volume_of(d0), 1)
    content = np.zeros((1, QUANTITIES, 1))
    content[0, NUMBER, 0] = 10.0
    total = 0.0
    for _ in range(40):
        total += react_zone(content, grid.pivots, grid.diameters, True, x0, xf, tau, 3.0)
    assert content[0, FES_REMOVED, 0] == pytest.approx(10.0 * reacted_mass(d0, 120.0, x0, xf, tau), rel=1e-9)
    assert total == pytest.approx(content[0, FES_REMOVED, 0], rel=1e-12)
    assert content[0, AGE, 0] == pytest.approx(10.0 * grid.pivots[0] * 120.0, rel=1e-12)


def test_velocity_table_is_the_shared_settling_velocity():
    for name, extra in [("deep", {"drag.fluid_drop": True}), ("simple", {"drag.law": "stokes"})]:
        model = popbal.setup(name, extra)
        case = model.case
        k = model.grid.size // 2
        d0 = model.grid.diameters[k]
        if model.reacting:
            x0, xf, tau = model.x_initial, model.x_final, model.time_constant
            for m in (0, 7, 33):
                age = m * model.age_step
                expected = settling_velocity(case, d0 * relative_diameter_at_age(age, x0, xf, tau),
                                             density_at_age(age, x0, xf, tau))
                assert model.velocity_table[k, m] == pytest.approx(expected, rel=1e-14)
        else:
            assert model.velocity_table.shape[1] == 1
            assert model.velocity_table[k, 0] == pytest.approx(settling_velocity(case, d0), rel=1e-14)


def test_feed_discretisation_delivers_the_mass_rate_and_droplet_rate():
    for name in ("simple", "furnace"):
        model = popbal.setup(name)
        f = model.case.feed
        mass = (model.feed_number_rate * model.grid.pivots).sum() * model.feed_density
        assert mass == pytest.approx(f.mass_rate, rel=1e-12)
        if f.distribution == "normal":
            shared = droplet_rate(f.mass_rate, f.mean_diameter, model.feed_density, f.scale_std, f.scale_min,
                                  f.scale_max)
            assert model.feed_number_rate.sum() == pytest.approx(shared, rel=1e-9)
        else:
            d = np.asarray(f.table_diameters)
            expected = f.mass_rate * np.asarray(f.table_mass_fractions) / (model.feed_density * volume_of(d))
            assert model.feed_number_rate.sum() == pytest.approx(expected.sum(), rel=1e-12)
    pivots = np.array([1.0, 2.0, 4.0])
    split = split_to_pivots([1.5, 3.0, 4.0], [2.0, 1.0, 1.0], pivots)
    assert split.sum() == pytest.approx(4.0) and split @ pivots == pytest.approx(1.5 * 2 + 3.0 + 4.0)


def test_cloud_coefficient_is_hadamard_rybczynski_and_the_falling_cloud():
    phi, drho, radius, mu, a = 0.05, 1950.0, 0.02, 0.45, 250e-6
    u = closures.cloud_velocity(phi * drho, radius, mu)
    # a drop of suspension with viscosity ratio 1, from the shared laws
    shared = stokes_velocity(2 * radius, 3150.0 + phi * drho, 3150.0, mu) * hadamard_rybczynski_factor(1.0)
    assert u == pytest.approx(shared, rel=1e-12)
    # U_St (6/5) N a / R (Nitsche & Batchelor 1997), N = phi (R/a)^3
    n = phi * (radius / a) ** 3
    assert u == pytest.approx(stokes_velocity(2 * a, 5100.0, 3150.0, mu) * 1.2 * n * a / radius, rel=1e-12)
    # the self-consistent plume velocity of the simple case (the issue: ~0.08 m/s, plume Re ~80 on the diameter)
    case = load_case("simple")
    q = case.feed.mass_rate / case.matte.density
    u_c = closures.steady_channel_velocity(q, case.matte.density - case.slag.density, case.slag_viscosity)
    assert u_c == pytest.approx(0.078, abs=1e-3)
    assert 10 < 2 * closures.plume_reynolds(u_c, 0.075, case.slag.density, case.slag_viscosity) < 1000
    phi_c = closures.steady_channel_fraction(q, 0.075, u_c)
    assert closures.cloud_velocity(phi_c * 1950.0, 0.075, case.slag_viscosity) == pytest.approx(u_c, rel=1e-12)


def test_model_channel_reaches_the_steady_plume_velocity():
    model = popbal.setup("simple", {"case.calibration": "none", "coalescence.enabled": False, "popbal.end_time": 10.0,
                                    "popbal.output_interval": 10.0})
    result = popbal.run(model)
    expected = popbal.steady_channel_velocity(model.case.feed.mass_rate / model.feed_density,
                                              model.feed_density - model.case.slag.density, model.viscosity)
    # droplets move at u_c plus their own (hindered) velocity, so the plume itself is slightly below the formula
    centre = result.timeseries.centreline_settling_velocity.iloc[-1]
    assert 0.98 * expected < centre < 1.02 * expected


def test_bad_popbal_inputs_are_refused_clearly():
    with pytest.raises(CaseError, match="popbal.channel_radius_factor = 3.0.*smaller than the box"):
        popbal.setup("simple", popbal__channel_radius_form="inlet", popbal__channel_radius_factor=3.0)
    with pytest.raises(CaseError, match="popbal.channel_feed_fraction = 0.5: allowed 0 when"):
        popbal.setup("simple", popbal__channel_radius_factor=0.0, popbal__channel_feed_fraction=0.5)
    with pytest.raises(CaseError, match="slag_flow = 'horizontal': needs slag.feed_rate > 0"):
        popbal.setup("simple", popbal__slag_flow="horizontal")
    with pytest.raises(CaseError, match="feed.table_mass_fractions.*one entry per"):
        popbal.setup("furnace", feed__table_mass_fractions=[0.5, 0.5])
    with pytest.raises(CaseError, match="feed.table_mass_fractions.*sum to 1"):
        popbal.setup("furnace", feed__table_mass_fractions=[0.1] * 7)
    with pytest.raises(CaseError, match="feed.distribution = 'table': 'table' needs"):
        popbal.setup("simple", feed__distribution="table")
    with pytest.raises(CaseError, match="coalescence.size_limit.*max\\(feed.table_diameters\\)"):
        popbal.setup("furnace", coalescence__size_limit=0.4e-3)
    with pytest.raises(CaseError, match="popbal.coalescence_rule = 'maybe': allowed: one of 'step', 'probability'"):
        popbal.setup("simple", popbal__coalescence_rule="maybe")
    with pytest.raises(ValueError, match="end_time = -1"):
        popbal.run("simple", end_time=-1.0)
    assert math.isfinite(popbal.setup("simple").grid.volume_limit)
