"""Volume and mass of a sphere, written once for NumPy, plain Python and the Numba kernels.

``sphere_volume(d) = pi d^3 / 6`` [m^3] and ``sphere_mass(d, rho) = rho pi d^3 / 6`` [kg], for a diameter d [m] and
a density rho [kg/m^3], scalars or NumPy arrays. Called from Python they are these NumPy expressions; called from a
``@njit`` kernel, Numba compiles the same Python function into the kernel (:func:`numba.extending.overload`,
inlined at Numba's IR level, so the kernel's own fast-math flags apply as they did to the expression written out).

The order of evaluation is part of the definition: (pi / 6) d^3 and ((rho pi) / 6) d^3, as every caller wrote it
before these functions existed, so results did not change in the last bit. A kernel and NumPy may still differ from
each other in the last bit (Numba computes d**3 by multiplication, NumPy by pow), as the expressions written out
did. Expressions that group the factors otherwise (``count * pi / 6 * d^3``, ``rho * (pi / 6) * d^3``, a sum of d^3
times pi/6) keep their own order.
"""

from __future__ import annotations

import math

from numba.extending import overload


def sphere_volume(diameter):
    """Volume pi d^3 / 6 [m^3] of a sphere of diameter ``diameter`` [m] (a number or an array)."""
    return math.pi / 6.0 * diameter**3


def sphere_mass(diameter, density):
    """Mass rho pi d^3 / 6 [kg] of a sphere of diameter ``diameter`` [m] and density ``density`` [kg/m^3]."""
    return density * math.pi / 6.0 * diameter**3


@overload(sphere_volume, inline="always")
def _sphere_volume_kernel(diameter):
    return sphere_volume  # the same Python function, compiled by Numba


@overload(sphere_mass, inline="always")
def _sphere_mass_kernel(diameter, density):
    return sphere_mass
