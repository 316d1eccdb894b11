"""Coalescence probability of two colliding droplets (seed paper Eq. 2).

P_c = exp(-Psi * sqrt(0.75 (1 + xi^2)(1 + xi^3)) / (D (1 + xi)^3) * sqrt(We)),

after Wang, Wang & Jin, Chem. Eng. Sci. 60 (2005) 6199, who follow Luo (1993). Two forms of D are offered:

* ``"seed"`` (default, :data:`FORM_SEED`): D = rho_d/rho_c + gamma, as typeset in the seed paper -- the model
  being reproduced;
* ``"luo"`` (:data:`FORM_LUO`): D = sqrt(rho_d/rho_c + gamma), Luo's original, as OpenFOAM and Fluent implement it.

Convention for i and j: droplet *i is the smaller one*, so xi = d_i/d_j <= 1 and We = rho_c d_i u_ij^2 / sigma uses
the smaller diameter. The functions order their arguments themselves, so P_c(a, b) = P_c(b, a). The 0.75 sits
*inside* the square root (OpenQBMM puts it outside, an exponent 1.155x too small).

How P_c turns a collision into a merger is the *coalescence rule* (:data:`COALESCENCE_RULES`), applied by
:func:`merger_fraction` (the mean fraction of collisions that merge, for the population balance) and
:func:`collision_merges` (one collision's outcome from a uniform random number, for the DEM); the two agree in
expectation, so both engines merge by the same rule.
"""

import math

from numba import njit

from .registry import Entry, Registry

#: Form code for D = rho_d/rho_c + gamma (seed paper Eq. 2).
FORM_SEED = 0
#: Form code for D = sqrt(rho_d/rho_c + gamma) (Luo 1993).
FORM_LUO = 1
#: Coalescence-probability forms: name (case key coalescence.probability_form) -> code of coalescence_probability.
PROBABILITY_FORMS = Registry(
    "probability form",
    Entry("seed", FORM_SEED, "Eq. 2 as typeset in the seed paper: D = rho_d/rho_c + gamma.",
          "Jylha & Jokilaakso 2023, Heliyon 9, e21570, Eq. 2; after Wang, Wang & Jin 2005, Chem. Eng. Sci. 60, 6199"),
    Entry("luo", FORM_LUO, "Luo's original film-drainage form: D = sqrt(rho_d/rho_c + gamma).",
          "Luo 1993, Dr. ing. thesis, Norwegian Institute of Technology, Trondheim"),
)

#: Rule code: a colliding pair merges iff P_c >= threshold.
RULE_STEP = 0
#: Rule code: a colliding pair merges with probability P_c (threshold ignored).
RULE_PROBABILITY = 1
#: Coalescence rules: how P_c makes a collision a merger; name (case key popbal.coalescence_rule) -> code of
#: merger_fraction / collision_merges. "step" applied to the mean approach speed of a pair in the population balance
#: merges the same pairs as the DEM; "probability" is the film-drainage reading used by Fluent/OpenFOAM population
#: balances.
COALESCENCE_RULES = Registry(
    "coalescence rule",
    Entry("step", RULE_STEP, "A colliding pair merges iff P_c >= coalescence.threshold (the DEM rule).",
          "Jylha & Jokilaakso 2023, Heliyon 9, e21570, section 3.3.1"),
    Entry("probability", RULE_PROBABILITY, "A colliding pair merges with probability P_c.",
          "Luo 1993, Dr. ing. thesis, Norwegian Institute of Technology, Trondheim"),
)


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
def merger_fraction(probability, threshold, rule):
    """Mean fraction of collisions with coalescence probability P_c that merge under ``rule`` [-].

    RULE_STEP: 1 if P_c >= threshold else 0; RULE_PROBABILITY: P_c (threshold unused). The expectation of
    :func:`collision_merges` over a uniform random number.
    """
    if rule == RULE_STEP:
        return 1.0 if probability >= threshold else 0.0
    return probability


@njit(cache=True)
def collision_merges(probability, threshold, rule, uniform):
    """Whether one collision with coalescence probability P_c merges under ``rule``, given uniform in [0, 1).

    RULE_STEP: P_c >= threshold (uniform unused); RULE_PROBABILITY: uniform < P_c.
    """
    if rule == RULE_STEP:
        return probability >= threshold
    return uniform < probability


@njit(cache=True)
def merger_efficiency(diameter_a, diameter_b, approach_speed, density_droplet, density_slag, interfacial_tension,
                      psi, virtual_mass, form, threshold, rule):
    """Fraction of collisions at the given approach speed [m/s] that merge: seed Eq. 2 under ``rule`` [-].

    diameters [m], densities [kg/m^3], interfacial_tension [N/m]; psi, virtual_mass, form as in
    :func:`coalescence_probability`; threshold and rule as in :func:`merger_fraction`.
    """
    p = coalescence_probability(diameter_a, diameter_b, approach_speed, density_droplet, density_slag,
                                interfacial_tension, psi, virtual_mass, form)
    return merger_fraction(p, threshold, rule)


@njit(cache=True)
def merged_diameter(diameter_a, diameter_b):
    """Diameter of the droplet formed from two, conserving volume: (d_a^3 + d_b^3)^(1/3) [m]."""
    return (diameter_a**3 + diameter_b**3) ** (1.0 / 3.0)


@njit(cache=True)
def growth_time(diameter_a, diameter_b, growth_target, growth_rate):
    """The growth time [s] of a marked pair in the delayed coalescence (fulldem.submodels.coalescence): the smaller
    partner's contact diameter grows by growth_rate d_m per second [1/s] until growth_target d_m, d_m the merged
    diameter; popbal's busy partners (popbal.kernels.busy_discount) take the same time."""
    merged = merged_diameter(diameter_a, diameter_b)
    return max(growth_target * merged - min(diameter_a, diameter_b), 0.0) / (growth_rate * merged)
