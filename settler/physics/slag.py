"""Slag properties as functions of temperature."""

import math

from numba import njit

from .constants import GAS_CONSTANT


@njit(cache=True)
def slag_viscosity(temperature, viscosity_ref, temperature_ref, activation_energy):
    """Arrhenius slag viscosity mu = mu_ref exp[(E_a/R)(1/T - 1/T_ref)] [Pa s].

    temperature, temperature_ref [K]; viscosity_ref [Pa s] at temperature_ref; activation_energy [J/mol].
    The Arrhenius (Weymann-type) temperature law is the one behind the Riboud model; measured copper-smelting
    slags have E_a of about 160-370 kJ/mol (physics.md section 1).
    """
    return viscosity_ref * math.exp(activation_energy / GAS_CONSTANT * (1.0 / temperature - 1.0 / temperature_ref))
