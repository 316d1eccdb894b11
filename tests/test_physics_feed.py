"""The feed sampler's statistics and the insertion schedule's mass rate."""

import math

import numpy as np
import pytest
from scipy import integrate, stats

from settler import physics as p


def test_scale_factor_statistics():
    rng = np.random.default_rng(7)
    n = 400_000
    s = p.sample_scale_factors(rng, n, 0.1, 0.7, 1.3)
    assert s.min() >= 0.7 and s.max() <= 1.3
    # truncation at +-3 sigma: the mean stays 1 by symmetry, the std is 0.1 x 0.9865 (truncated normal)
    a, b = -3.0, 3.0
    std_exact = 0.1 * math.sqrt(1 + (a * stats.norm.pdf(a) - b * stats.norm.pdf(b)) / (stats.norm.cdf(b) - stats.norm.cdf(a)))
    assert s.mean() == pytest.approx(1.0, abs=4 * 0.1 / math.sqrt(n))
    assert s.std() == pytest.approx(std_exact, rel=4 / math.sqrt(2 * n))
    # mass-weighted moment agrees with quadrature of the density
    e3 = integrate.quad(lambda x: x**3 * p.scale_factor_pdf(x), 0.7, 1.3)[0]
    assert p.scale_factor_moment(3) == pytest.approx(e3, rel=1e-10)
    assert np.mean(s**3) == pytest.approx(e3, rel=5e-3)


def test_droplet_rate_of_paper_cases():
    # physics.md section 2: a 500 um droplet weighs 3.34e-7 kg at 5100 kg/m^3, so 0.0086 kg/s is ~25 800 droplets/s
    mass = 5100.0 * math.pi / 6 * 500e-6**3
    assert mass == pytest.approx(3.34e-7, rel=2e-3)
    nominal = p.droplet_rate(0.0086, 500e-6, 5100.0, std=0.0)
    assert nominal == pytest.approx(25_800, rel=5e-3)
    # the distribution's E[s^3] > 1 lowers the count by its mass-weighted factor
    assert p.droplet_rate(0.0086, 500e-6, 5100.0) == pytest.approx(nominal / p.scale_factor_moment(3), rel=1e-14)


def test_schedule_mass_rate_within_one_percent_over_a_long_run():
    rate = 0.0086
    sched = p.FeedSchedule(rate, 500e-6, 5100.0, seed=3)
    dt = 2e-3
    diameters = [sched.advance(k * dt) for k in range(1, 2501)]  # 5 s, ~125 000 droplets
    d = np.concatenate(diameters)
    mass = np.sum(5100.0 * math.pi / 6 * d**3)
    assert mass == pytest.approx(sched.fed_mass, rel=1e-12)
    t = 2500 * dt
    assert mass / t == pytest.approx(rate, rel=1e-2)
    # the bound behind "exact on average": never more than half the largest droplet off the target
    largest = 5100.0 * math.pi / 6 * (1.3 * 500e-6) ** 3
    assert abs(mass - rate * t) <= 0.5 * largest
    assert d.min() >= 0.35e-3 and d.max() <= 0.65e-3


def test_schedule_independent_of_step_size():
    a = p.FeedSchedule(1e-4, 500e-6, 4500.0, seed=11)
    b = p.FeedSchedule(1e-4, 500e-6, 4500.0, seed=11)
    da = a.advance(3.0)
    db = np.concatenate([b.advance(t) for t in np.linspace(0.01, 3.0, 300)])
    np.testing.assert_array_equal(da, db)


def test_schedule_refuses_going_back_in_time():
    s = p.FeedSchedule(1e-4, 500e-6, 4500.0, seed=1)
    s.advance(1.0)
    with pytest.raises(ValueError, match="before"):
        s.advance(0.5)


def test_table_droplet_rate_by_hand():
    # two classes: 1 kg/s, 30 % by mass at 1 mm and 70 % at 0.1 mm, density 5000 kg/m^3
    m1 = 5000.0 * math.pi / 6 * 1e-3**3
    m2 = 5000.0 * math.pi / 6 * 1e-4**3
    assert p.table_droplet_rate(1.0, [1e-3, 1e-4], [0.3, 0.7], 5000.0) == pytest.approx(0.3 / m1 + 0.7 / m2,
                                                                                      rel=1e-14)
