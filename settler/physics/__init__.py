"""Shared droplet physics: every droplet law written once, used by both engines.

The laws are scalar ``@njit(cache=True)`` functions of floats (SI units) so that the CFD-DEM kernels
(:mod:`fulldem`) and the population balance (:mod:`popbal`) call literally the same code. For NumPy users each law
also has a broadcasting twin with the suffix ``_v`` (a Numba ufunc built from the same Python source).

Interchangeable models are listed in registries (:mod:`settler.physics.registry`: name -> kernel code, with a
description and a citation per entry): :data:`DRAG_LAWS`, :data:`HINDRANCE`, :data:`PROBABILITY_FORMS`,
:data:`COALESCENCE_RULES`. The case schema takes its allowed values from them and the tests loop over them.

Why a package of its own: ``fulldem`` and ``popbal`` must not import each other (the reduced model has to install and
run without the CFD-DEM engine and vice versa), so the laws they share sit one layer below both, in
``settler.physics``, beside the case files and the command line that both engines also share.
"""

import functools
import inspect

import numba
import numpy as np

from .coalescence import (COALESCENCE_RULES, FORM_LUO, FORM_SEED, PROBABILITY_FORMS, RULE_PROBABILITY, RULE_STEP,
                          coalescence_probability, collision_merges, growth_time, merged_diameter, merger_efficiency,
                          merger_fraction, weber_number)
from .constants import GAS_CONSTANT, MOLAR_MASS_CU, MOLAR_MASS_CU2S, MOLAR_MASS_FES, STANDARD_GRAVITY
from .feed import (FeedSchedule, droplet_rate, mean_droplet_mass, sample_scale_factors, scale_factor_moment,
                   scale_factor_pdf, table_droplet_rate)
from .matte import (composition_from_masses, cu2s_fraction_from_density, cu2s_mass_fraction, density_at_age,
                    diameter_from_masses, matte_density, molar_mass_matte, reacted_mass, reaction_age,
                    reaction_fraction, relative_diameter, relative_diameter_at_age, relative_volume, species_masses)
from .registry import Entry, Registry
from .settling import (DRAG_LAWS, DRAG_SCHILLER_NAUMANN, DRAG_STOKES, HINDRANCE, HINDRANCE_DI_FELICE, HINDRANCE_NONE,
                       di_felice_exponent, drag_factor, haberman_sayre_factor, hadamard_rybczynski_factor,
                       hindrance_factor, relaxation_time, reynolds_number, richardson_zaki_factor,
                       schiller_naumann_factor, schiller_naumann_velocity, square_duct_factor, stokes_velocity,
                       terminal_velocity)
from .slag import slag_viscosity
from .sphere import sphere_mass, sphere_volume


def vectorize(law):
    """Broadcasting NumPy twin of a scalar ``@njit`` law (same source, compiled as a Numba ufunc).

    Arguments broadcast like NumPy's; the law's keyword defaults still apply.
    """
    # No cache=True here: the ufunc shares the law's qualified name and file, so its cache entries would collide
    # with the @njit law's own (a segfault when one is loaded as the other).
    ufunc = numba.vectorize(law.py_func)
    signature = inspect.signature(law.py_func)

    @functools.wraps(law.py_func)
    def twin(*args, **kwargs):
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        return ufunc(*(np.asarray(a, dtype=np.float64) if not isinstance(a, int) else a for a in bound.args))

    twin.ufunc = ufunc
    return twin


stokes_velocity_v = vectorize(stokes_velocity)
relaxation_time_v = vectorize(relaxation_time)
reynolds_number_v = vectorize(reynolds_number)
schiller_naumann_factor_v = vectorize(schiller_naumann_factor)
schiller_naumann_velocity_v = vectorize(schiller_naumann_velocity)
terminal_velocity_v = vectorize(terminal_velocity)
hadamard_rybczynski_factor_v = vectorize(hadamard_rybczynski_factor)
haberman_sayre_factor_v = vectorize(haberman_sayre_factor)
square_duct_factor_v = vectorize(square_duct_factor)
richardson_zaki_factor_v = vectorize(richardson_zaki_factor)
coalescence_probability_v = vectorize(coalescence_probability)
merged_diameter_v = vectorize(merged_diameter)
growth_time_v = vectorize(growth_time)
weber_number_v = vectorize(weber_number)
matte_density_v = vectorize(matte_density)
reaction_fraction_v = vectorize(reaction_fraction)
relative_diameter_v = vectorize(relative_diameter)
density_at_age_v = vectorize(density_at_age)
relative_diameter_at_age_v = vectorize(relative_diameter_at_age)
slag_viscosity_v = vectorize(slag_viscosity)
