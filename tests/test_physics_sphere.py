"""The volume and mass of a sphere (settler.physics.sphere): against 4/3 pi r^3, and the same bits from Python,
NumPy and a Numba kernel."""

import math

import numpy as np
from numba import njit

from settler.physics import sphere_mass, sphere_volume


def test_sphere_volume_and_mass_against_four_thirds_pi_r_cubed():
    for d in (1e-6, 5e-4, 2e-3, 0.04):
        r = d / 2.0
        assert math.isclose(sphere_volume(d), 4.0 / 3.0 * math.pi * r**3, rel_tol=1e-15)
        assert math.isclose(sphere_mass(d, 5200.0), 5200.0 * 4.0 / 3.0 * math.pi * r**3, rel_tol=1e-15)


@njit
def _in_a_kernel(diameter, density, out):
    for p in range(diameter.shape[0]):
        out[0, p] = sphere_volume(diameter[p])
        out[1, p] = math.pi / 6.0 * diameter[p] ** 3
        out[2, p] = sphere_mass(diameter[p], density[p])
        out[3, p] = density[p] * math.pi / 6.0 * diameter[p] ** 3


def test_each_form_gives_the_bits_of_the_expression_it_replaced():
    """Callers rely on it: the functions replaced expressions written out in kernels and in NumPy code, and the
    engines' results did not change. (A kernel and NumPy may differ in the last bit: Numba computes d**3 by
    multiplication, NumPy by pow.)"""
    rng = np.random.default_rng(3)
    d = rng.uniform(1e-4, 3e-3, 200)
    rho = rng.uniform(4500.0, 5300.0, 200)
    out = np.empty((4, 200))
    _in_a_kernel(d, rho, out)
    assert np.array_equal(out[0], out[1]) and np.array_equal(out[2], out[3])
    assert np.array_equal(sphere_volume(d), math.pi / 6.0 * d**3)
    assert np.array_equal(sphere_mass(d, rho), rho * math.pi / 6.0 * d**3)
    assert all(sphere_volume(float(x)) == math.pi / 6.0 * float(x) ** 3 for x in d)
