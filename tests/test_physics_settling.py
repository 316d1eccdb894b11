"""Settling laws against their formulas and the hand values of physics.md section 4."""

import math

import numpy as np
import pytest
from scipy import optimize

from settler import physics as p

G = 9.81  # physics.md's hand values use g = 9.81 m/s^2


def test_stokes_velocity_formula_and_hand_value():
    # physics.md section 3: 500 um matte in slag, 0.59 mm/s; 2 mm: 9.4 mm/s; 10 mm: 0.24 m/s
    assert p.stokes_velocity(500e-6, 5100.0, 3150.0, 0.45, G) == pytest.approx(0.59e-3, rel=5e-3)
    assert p.stokes_velocity(2e-3, 5100.0, 3150.0, 0.45, G) == pytest.approx(9.4e-3, rel=5e-3)
    assert p.stokes_velocity(10e-3, 5100.0, 3150.0, 0.45, G) == pytest.approx(0.24, rel=2e-2)
    d, drho, mu = 0.37e-3, 1234.0, 0.3
    assert p.stokes_velocity(d, 3000.0 + drho, 3000.0, mu, G) == pytest.approx(2 / 9 * drho * G * (d / 2) ** 2 / mu,
                                                                               rel=1e-14)
    # a lighter droplet rises: negative settling velocity
    assert p.stokes_velocity(d, 2000.0, 3000.0, mu) < 0.0


def test_relaxation_time_hand_value():
    # physics.md section 3: tau_p ~ 1.6e-4 s for 500 um matte
    assert p.relaxation_time(500e-6, 5100.0, 0.45) == pytest.approx(1.6e-4, rel=2e-2)


@pytest.mark.parametrize("reynolds, factor", [(0.01, 1.0063), (1.0, 1.150), (10.0, 1.730)])
def test_schiller_naumann_factor_hand_values(reynolds, factor):
    assert p.schiller_naumann_factor(reynolds) == pytest.approx(factor, abs=5e-4)


def test_schiller_naumann_newton_regime_is_continuous_enough():
    # at Re = 1000 the two branches of the standard law meet within 5 %
    low = p.schiller_naumann_factor(1000.0)
    high = p.schiller_naumann_factor(1000.0 * (1 + 1e-12))
    assert high == pytest.approx(low, rel=0.05)


@pytest.mark.parametrize("diameter", [50e-6, 500e-6, 2e-3, 10e-3, 40e-3, 0.2])
def test_schiller_naumann_velocity_balances_forces(diameter):
    """The solved velocity makes drag equal net weight (force balance to round-off), checked with brentq."""
    rho_p, rho_f, mu = 5100.0, 3150.0, 0.45
    v = p.schiller_naumann_velocity(diameter, rho_p, rho_f, mu, G)
    weight = (rho_p - rho_f) * G * math.pi / 6 * diameter**3
    re = rho_f * v * diameter / mu
    drag = 3 * math.pi * mu * diameter * v * p.schiller_naumann_factor(re)
    assert drag == pytest.approx(weight, rel=1e-10)

    def residual(u):
        return 3 * math.pi * mu * diameter * u * p.schiller_naumann_factor(rho_f * u * diameter / mu) - weight

    v_ref = optimize.brentq(residual, 0.0, p.stokes_velocity(diameter, rho_p, rho_f, mu, G), xtol=1e-16, rtol=1e-14)
    assert v == pytest.approx(v_ref, rel=1e-10)


def test_schiller_naumann_velocity_limits():
    # Stokes limit for small droplets; ~10 mm droplet has Re ~ 10 and settles much slower than Stokes says
    v_small = p.schiller_naumann_velocity(50e-6, 5100.0, 3150.0, 0.45, G)
    assert v_small == pytest.approx(p.stokes_velocity(50e-6, 5100.0, 3150.0, 0.45, G), rel=1e-4)
    v = p.schiller_naumann_velocity(10e-3, 5100.0, 3150.0, 0.45, G)
    re = p.reynolds_number(10e-3, v, 3150.0, 0.45)
    assert 5.0 < re < 20.0
    assert v / p.stokes_velocity(10e-3, 5100.0, 3150.0, 0.45, G) == pytest.approx(
        1.0 / p.schiller_naumann_factor(re), rel=1e-10)
    assert p.schiller_naumann_velocity(1e-3, 2000.0, 3150.0, 0.45) < 0.0  # rises


def test_hadamard_rybczynski_factor():
    assert p.hadamard_rybczynski_factor(0.01) == pytest.approx(1.49, abs=5e-3)
    assert p.hadamard_rybczynski_factor(0.0) == pytest.approx(1.5, rel=1e-15)
    assert p.hadamard_rybczynski_factor(1e12) == pytest.approx(1.0, rel=1e-9)


@pytest.mark.parametrize("ratio, factor", [(0.1, 0.792), (0.2, 0.595), (0.3, 0.422), (0.4, 0.279)])
def test_haberman_sayre_hand_values(ratio, factor):
    assert p.haberman_sayre_factor(ratio) == pytest.approx(factor, abs=1e-3)


def test_square_duct_factor_first_order():
    assert p.square_duct_factor(0.0) == 1.0
    assert p.square_duct_factor(0.05) == pytest.approx(1 / (1 + 1.903 * 0.05), rel=1e-15)


@pytest.mark.parametrize("phi, factor", [(0.05, 0.788), (0.1, 0.613), (0.3, 0.190)])
def test_richardson_zaki_hand_values(phi, factor):
    assert p.richardson_zaki_factor(phi) == pytest.approx(factor, abs=1e-3)


def test_richardson_zaki_dilute_limit_is_batchelor_like():
    # physics.md: dilute limit 1 - 6.55 phi (Batchelor 1972); RZ's slope is -4.65: within 30 % of it
    slope = (p.richardson_zaki_factor(1e-6) - 1.0) / 1e-6
    assert slope == pytest.approx(-4.65, rel=1e-4)


def test_di_felice_exponent_range():
    # Di Felice (1994): chi = 3.7 - 0.65 at log10 Re = 1.5, -> 3.7 far from it
    assert p.di_felice_exponent(10**1.5) == pytest.approx(3.05, abs=1e-12)
    assert p.di_felice_exponent(1e-6) == pytest.approx(3.7, abs=1e-6)


def test_slag_viscosity_arrhenius():
    assert p.slag_viscosity(1543.15, 0.45, 1543.15, 250e3) == pytest.approx(0.45, rel=1e-15)
    hot = p.slag_viscosity(1593.15, 0.45, 1543.15, 250e3)
    assert hot < 0.45
    assert math.log(0.45 / hot) == pytest.approx(250e3 / 8.314462618 * (1 / 1543.15 - 1 / 1593.15), rel=1e-12)


TWINS = {
    "stokes_velocity": (p.stokes_velocity, p.stokes_velocity_v, 4),
    "schiller_naumann_velocity": (p.schiller_naumann_velocity, p.schiller_naumann_velocity_v, 4),
    "haberman_sayre_factor": (p.haberman_sayre_factor, p.haberman_sayre_factor_v, 1),
    "richardson_zaki_factor": (p.richardson_zaki_factor, p.richardson_zaki_factor_v, 1),
    "matte_density": (p.matte_density, p.matte_density_v, 1),
}


@pytest.mark.parametrize("name", TWINS)
def test_vectorized_twins_match_scalar_laws(name):
    scalar, twin, nargs = TWINS[name]
    rng = np.random.default_rng(1)
    base = [np.linspace(1e-4, 3e-2, 7), 5100.0, 3150.0, 0.45][:nargs]
    if nargs == 1:
        base = [rng.uniform(0.01, 0.4, 7)]
    out = twin(*base)
    ref = [scalar(*(b[i] if np.ndim(b) else b for b in base)) for i in range(7)]
    np.testing.assert_allclose(out, ref, rtol=1e-15)
