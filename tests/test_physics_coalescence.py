"""Coalescence probability, seed paper Eq. 2, against its formula written independently with NumPy."""

import math

import numpy as np
import pytest

from settler import physics as p


def eq2_reference(d1, d2, u, rho_d, rho_c, sigma, psi, gamma, luo):
    d_i, d_j = min(d1, d2), max(d1, d2)
    xi = d_i / d_j
    we = rho_c * d_i * u**2 / sigma
    denom = (rho_d / rho_c + gamma) ** (0.5 if luo else 1.0)
    return np.exp(-psi * np.sqrt(0.75 * (1 + xi**2) * (1 + xi**3)) / (denom * (1 + xi) ** 3) * np.sqrt(we))


@pytest.mark.parametrize("form", list(p.PROBABILITY_FORMS))
@pytest.mark.parametrize("d1, d2, u", [(500e-6, 500e-6, 1e-3), (350e-6, 2e-3, 5e-2), (1e-3, 40e-3, 0.5),
                                       (600e-6, 400e-6, 3.0)])
def test_probability_matches_formula(form, d1, d2, u):
    code = p.PROBABILITY_FORMS[form]
    got = p.coalescence_probability(d1, d2, u, 5100.0, 3150.0, 0.1, 1.0, 0.5, code)
    assert got == pytest.approx(eq2_reference(d1, d2, u, 5100.0, 3150.0, 0.1, 1.0, 0.5, form == "luo"), rel=1e-13)


def test_probability_symmetric_and_bounded():
    a = p.coalescence_probability(400e-6, 900e-6, 0.02, 5100.0, 3150.0, 0.1)
    b = p.coalescence_probability(900e-6, 400e-6, 0.02, 5100.0, 3150.0, 0.1)
    assert a == b
    assert p.coalescence_probability(400e-6, 900e-6, 0.0, 5100.0, 3150.0, 0.1) == 1.0
    us = np.logspace(-4, 1, 30)
    probs = p.coalescence_probability_v(400e-6, 900e-6, us, 5100.0, 3150.0, 0.1)
    assert np.all(np.diff(probs) < 0) and np.all((probs > 0) & (probs <= 1))


def test_luo_form_exponent_ratio():
    """ln P_luo / ln P_seed = sqrt(rho_d/rho_c + gamma): only the density term differs between the two forms."""
    seed = p.coalescence_probability(500e-6, 700e-6, 0.3, 5100.0, 3150.0, 0.1, 1.0, 0.5, p.FORM_SEED)
    luo = p.coalescence_probability(500e-6, 700e-6, 0.3, 5100.0, 3150.0, 0.1, 1.0, 0.5, p.FORM_LUO)
    assert math.log(luo) / math.log(seed) == pytest.approx(math.sqrt(5100 / 3150 + 0.5), rel=1e-12)


def test_weber_number_and_stokes_scale_probability():
    # physics.md section 3: with sigma ~ 0.1 N/m and Stokes-scale speeds We ~ 1e-5..1e-3 and P_c ~ 0.99
    u = p.stokes_velocity(500e-6, 5100.0, 3150.0, 0.45)
    we = p.weber_number(500e-6, u, 3150.0, 0.1)
    assert we == pytest.approx(3150.0 * 500e-6 * u**2 / 0.1, rel=1e-15)
    assert 1e-6 < we < 1e-3
    assert p.coalescence_probability(500e-6, 500e-6, u, 5100.0, 3150.0, 0.1) > 0.99


def test_merged_diameter_conserves_volume():
    d = p.merged_diameter(0.5e-3, 0.6e-3)
    assert d**3 == pytest.approx(0.5e-3**3 + 0.6e-3**3, rel=1e-14)
    assert p.merged_diameter(1.0, 1.0) == pytest.approx(2 ** (1 / 3), rel=1e-15)
