"""Coalescence probability of two colliding droplets (seed paper Eq. 2).

P_c = exp(-Psi * sqrt(0.75 (1 + xi^2)(1 + xi^3)) / (D (1 + xi)^3) * sqrt(We)),

after Wang, Wang & Jin, Chem. Eng. Sci. 60 (2005) 6199, who follow Luo (1993). Two forms of D are offered:

* ``"seed"`` (default, :data:`FORM_SEED`): D = rho_d/rho_c + gamma, as typeset in the seed paper -- the model
  being reproduced;
* ``"luo"`` (:data:`FORM_LUO`): D = sqrt(rho_d/rho_c + gamma), Luo's original, as OpenFOAM and Fluent implement it.

Convention for i and j: droplet *i is the smaller one*, so xi = d_i/d_j <= 1 and We = rho_c d_i u_ij^2 / sigma uses
the smaller diameter. The functions order their arguments themselves, so P_c(a, b) = P_c(b, a). The 0.75 sits
*inside* the square root (OpenQBMM puts it outside, an exponent 1.155x too small).
"""

import math

from numba import njit

#: Form code for D = rho_d/rho_c + gamma (seed paper Eq. 2).
FORM_SEED = 0
#: Form code for D = sqrt(rho_d/rho_c + gamma) (Luo 1993).
FORM_LUO = 1
#: Registry of the coalescence-probability forms: name -> code passed to the kernels.
PROBABILITY_FORMS = {"seed": FORM_SEED, "luo": FORM_LUO}


@njit(cache=True)
def weber_number(diameter_small, relative_speed, density_continuous, interfacial_tension):
    """Collision Weber number We = rho_c d_i u_ij^2 / sigma [-] with d_i the smaller diameter [m].

    relative_speed [m/s] is the approach speed at contact; density_continuous [kg/m^3]; sigma [N/m].
    """
    return density_continuous * diameter_small * relative_speed * relative_speed / interfacial_tension


@njit(cache=True)
def coalescence_probability(diameter_a, diameter_b, relative_speed, density_droplet, density_continuous,
                            interfacial_tension, psi=1.0, virtual_mass=0.5, form=FORM_SEED):
    """Coalescence probability P_c of two droplets, seed paper Eq. 2 [-].

    diameters [m] (either order), relative_speed [m/s], densities [kg/m^3], interfacial_tension [N/m],
    psi: the order-of-unity constant Psi, virtual_mass: gamma (0.5 for spheres), form: FORM_SEED or FORM_LUO.
    """
    d_i = min(diameter_a, diameter_b)
    d_j = max(diameter_a, diameter_b)
    xi = d_i / d_j
    ratio = density_droplet / density_continuous + virtual_mass
    if form == FORM_LUO:
        ratio = math.sqrt(ratio)
    one_xi = 1.0 + xi
    shape = math.sqrt(0.75 * (1.0 + xi * xi) * (1.0 + xi * xi * xi)) / (ratio * one_xi * one_xi * one_xi)
    we = weber_number(d_i, relative_speed, density_continuous, interfacial_tension)
    return math.exp(-psi * shape * math.sqrt(we))


@njit(cache=True)
def merged_diameter(diameter_a, diameter_b):
    """Diameter of the droplet formed from two, conserving volume: (d_a^3 + d_b^3)^(1/3) [m]."""
    return (diameter_a**3 + diameter_b**3) ** (1.0 / 3.0)
