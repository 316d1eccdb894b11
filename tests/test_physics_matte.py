"""Matte density (Eq. 4), size from masses (Eq. 5) and the reaction's mass bookkeeping."""

import math

import numpy as np
import pytest

from settler import physics as p


@pytest.mark.parametrize("x, rho", [(0.405, 4500.0), (0.943, 5200.0)])
def test_density_hand_values(x, rho):
    # physics.md section 1: X range 0.405-0.943 for 4500-5200 kg/m^3 (3 significant digits in X)
    assert p.matte_density(x) == pytest.approx(rho, abs=1.0)
    assert p.cu2s_fraction_from_density(rho) == pytest.approx(x, abs=5e-4)


def test_density_inverse_roundtrip():
    xs = np.linspace(0.0, 1.0, 11)
    assert np.allclose([p.cu2s_fraction_from_density(p.matte_density(x)) for x in xs], xs, rtol=0, atol=1e-14)


def test_diameter_from_masses_is_eq5():
    m_cu2s, m_fes, rho = 2.0e-7, 1.3e-7, 4800.0
    r = (3 * (m_cu2s + m_fes) / (4 * math.pi * rho)) ** (1 / 3)
    assert p.diameter_from_masses(m_cu2s, m_fes, rho) == pytest.approx(2 * r, rel=1e-15)


def test_species_masses_roundtrip():
    d, x = 0.55e-3, 0.63
    m_cu2s, m_fes = p.species_masses(d, x)
    assert p.composition_from_masses(m_cu2s, m_fes) == pytest.approx(x, rel=1e-14)
    assert p.diameter_from_masses(m_cu2s, m_fes, p.matte_density(x)) == pytest.approx(d, rel=1e-14)


@pytest.mark.parametrize("d0", [0.35e-3, 0.5e-3, 2e-3, 40e-3])
@pytest.mark.parametrize("age", [0.0, 5.0, 60.0, 600.0])
def test_reaction_conserves_cu2s_and_removes_only_fes(d0, age):
    """A droplet of any size keeps its Cu2S mass to round-off; what it loses is FeS, counted by reacted_mass."""
    x0, xf, tau = 0.405, 0.943, 60.0
    m_cu2s0, m_fes0 = p.species_masses(d0, x0)
    x = p.reaction_fraction(age, x0, xf, tau)
    d = d0 * p.relative_diameter_at_age(age, x0, xf, tau)
    m_cu2s, m_fes = p.species_masses(d, x)
    assert m_cu2s == pytest.approx(m_cu2s0, rel=1e-13)
    assert m_fes0 - m_fes == pytest.approx(p.reacted_mass(d0, age, x0, xf, tau), rel=1e-9, abs=1e-13 * m_fes0)
    assert p.density_at_age(age, x0, xf, tau) == pytest.approx(p.matte_density(x), rel=1e-15)
    if age > 0:
        assert d < d0 and x > x0


def test_relative_size_and_velocity_hand_values():
    # physics.md section 3: X 0.6 -> 0.8 gives d x 0.924 and Stokes velocity x 0.99
    ratio = p.relative_diameter(0.8, 0.6)
    assert ratio == pytest.approx(0.924, abs=1e-3)
    v_ratio = ratio**2 * (p.matte_density(0.8) - 3150.0) / (p.matte_density(0.6) - 3150.0)
    assert v_ratio == pytest.approx(0.99, abs=5e-3)


def test_reaction_fit_and_its_inverse():
    x0, xf, tau = 0.405, 0.943, 60.0
    assert p.reaction_fraction(0.0, x0, xf, tau) == x0
    assert p.reaction_fraction(1e6, x0, xf, tau) == pytest.approx(xf, rel=1e-15)
    for age in (0.1, 10.0, 100.0):
        x = p.reaction_fraction(age, x0, xf, tau)
        assert p.reaction_age(x, x0, xf, tau) == pytest.approx(age, rel=1e-10)


def test_merging_by_composition_conserves_both_species():
    """Two droplets of different ages merged: the merged droplet's age from reaction_age keeps Cu2S and FeS."""
    x0, xf, tau = 0.405, 0.943, 60.0
    d0a, d0b, age_a, age_b = 0.5e-3, 0.9e-3, 3.0, 50.0
    masses = []
    for d0, age in ((d0a, age_a), (d0b, age_b)):
        d = d0 * p.relative_diameter_at_age(age, x0, xf, tau)
        masses.append(p.species_masses(d, p.reaction_fraction(age, x0, xf, tau)))
    m_cu2s = masses[0][0] + masses[1][0]
    m_fes = masses[0][1] + masses[1][1]
    x_merged = p.composition_from_masses(m_cu2s, m_fes)
    age = p.reaction_age(x_merged, x0, xf, tau)
    d0 = p.merged_diameter(d0a, d0b)  # Cu2S is proportional to d0^3
    d = d0 * p.relative_diameter_at_age(age, x0, xf, tau)
    got = p.species_masses(d, p.reaction_fraction(age, x0, xf, tau))
    assert got[0] == pytest.approx(m_cu2s, rel=1e-12)
    assert got[1] == pytest.approx(m_fes, rel=1e-9)
