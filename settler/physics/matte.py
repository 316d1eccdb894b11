"""Matte composition, density, size and the reaction fit X(age) (seed paper Eqs. 4-5, section 3.3.2).

The matte is a Cu2S-FeS melt described by X, the mole fraction of Cu2S. The reaction removes FeS only, so a
droplet keeps its Cu2S mass and loses FeS: it densifies (Eq. 4) and shrinks (Eq. 5). Because the composition path
X(age) is the same for every droplet, the *relative* diameter d(age)/d(0) is the same for every droplet size,
which is how the seed paper applies it.

A droplet is therefore described by its *original diameter* d0 (at the feed composition X0) and its age: the Cu2S
mass is proportional to d0^3 whatever the age, so summing d0^3 on coalescence conserves Cu2S exactly.
"""

import math

from numba import njit

from .constants import MOLAR_MASS_CU2S, MOLAR_MASS_FES
from .sphere import sphere_mass


#: Coefficients of Eq. 4, rho [g/cm^3] = a + b X (Sundstrom et al., J. SAIMM 108 (2008) 431).
DENSITY_INTERCEPT = 3.9732
DENSITY_SLOPE = 1.3012


@njit(cache=True)
def matte_density(x_cu2s):
    """Matte density from the Cu2S mole fraction, Eq. 4: rho = 1000 (3.9732 + 1.3012 X) [kg/m^3]."""
    return 1000.0 * (DENSITY_INTERCEPT + DENSITY_SLOPE * x_cu2s)


@njit(cache=True)
def cu2s_fraction_from_density(density):
    """Inverse of Eq. 4: the Cu2S mole fraction X of a matte of the given density [kg/m^3] -> [-]."""
    return (density / 1000.0 - DENSITY_INTERCEPT) / DENSITY_SLOPE


@njit(cache=True)
def molar_mass_matte(x_cu2s):
    """Mean molar mass of the Cu2S-FeS melt [kg/mol]."""
    return x_cu2s * MOLAR_MASS_CU2S + (1.0 - x_cu2s) * MOLAR_MASS_FES


@njit(cache=True)
def cu2s_mass_fraction(x_cu2s):
    """Mass fraction of Cu2S in the matte [-]."""
    return x_cu2s * MOLAR_MASS_CU2S / molar_mass_matte(x_cu2s)


@njit(cache=True)
def diameter_from_masses(mass_cu2s, mass_fes, density):
    """Droplet diameter from its Cu2S and FeS masses [kg] and density [kg/m^3], Eq. 5 (d = 2r) [m]."""
    return 2.0 * (3.0 * (mass_cu2s + mass_fes) / (4.0 * math.pi * density)) ** (1.0 / 3.0)


@njit(cache=True)
def composition_from_masses(mass_cu2s, mass_fes):
    """Cu2S mole fraction X of a droplet holding the given masses [kg] -> [-]."""
    n_cu2s = mass_cu2s / MOLAR_MASS_CU2S
    n_fes = mass_fes / MOLAR_MASS_FES
    return n_cu2s / (n_cu2s + n_fes)


@njit(cache=True)
def species_masses(diameter, x_cu2s):
    """Cu2S and FeS masses [kg] of a droplet of the given diameter [m] and composition X (tuple)."""
    mass = sphere_mass(diameter, matte_density(x_cu2s))
    w = cu2s_mass_fraction(x_cu2s)
    return w * mass, (1.0 - w) * mass


@njit(cache=True)
def reaction_fraction(age, x_initial, x_final, time_constant):
    """Reaction fit X(age) = X_inf - (X_inf - X0) exp(-age / tau) [-]; age and time_constant [s].

    A first-order approach to the end state X_inf (from the Cantera equilibrium, settler.thermo). The seed paper
    fitted X(age) to Wan et al. (2021) data not available here; tau is therefore a chosen value wherever it is used.
    """
    return x_final - (x_final - x_initial) * math.exp(-age / time_constant)


@njit(cache=True)
def reaction_age(x_cu2s, x_initial, x_final, time_constant):
    """Inverse of :func:`reaction_fraction`: the age [s] at which a droplet fed at X0 reaches X.

    Used on coalescence: the merged droplet gets the age of its merged composition, so Cu2S and FeS are both
    conserved (the seed paper's volume-weighted age conserves Cu2S only).
    """
    return -time_constant * math.log((x_final - x_cu2s) / (x_final - x_initial))


@njit(cache=True)
def relative_volume(x_cu2s, x_initial):
    """V(X)/V(X0) of a droplet that has lost FeS only (Cu2S conserved) going from X0 to X [-]."""
    per_cu2s_now = molar_mass_matte(x_cu2s) / (x_cu2s * matte_density(x_cu2s))
    per_cu2s_then = molar_mass_matte(x_initial) / (x_initial * matte_density(x_initial))
    return per_cu2s_now / per_cu2s_then


@njit(cache=True)
def relative_diameter(x_cu2s, x_initial):
    """d(X)/d(X0) of a droplet that has lost FeS only, the same for every droplet size [-]."""
    return relative_volume(x_cu2s, x_initial) ** (1.0 / 3.0)


@njit(cache=True)
def density_at_age(age, x_initial, x_final, time_constant):
    """Matte density [kg/m^3] of a droplet of the given age [s] (Eq. 4 on the reaction fit)."""
    return matte_density(reaction_fraction(age, x_initial, x_final, time_constant))


@njit(cache=True)
def relative_diameter_at_age(age, x_initial, x_final, time_constant):
    """d(age)/d(0) [-] of a droplet fed at X0 (Eqs. 4-5 on the reaction fit)."""
    return relative_diameter(reaction_fraction(age, x_initial, x_final, time_constant), x_initial)


@njit(cache=True)
def reacted_mass(original_diameter, age, x_initial, x_final, time_constant):
    """FeS mass [kg] a droplet of original diameter d0 [m] has lost by the given age [s]."""
    x = reaction_fraction(age, x_initial, x_final, time_constant)
    m_cu2s, m_fes0 = species_masses(original_diameter, x_initial)
    # FeS left per Cu2S follows from the mole ratio (1 - X)/X.
    m_fes = m_cu2s * (1.0 - x) / x * MOLAR_MASS_FES / MOLAR_MASS_CU2S
    return m_fes0 - m_fes
