"""The reaction submodel of the seed paper (section 3.3.2): droplets lose FeS as they age, shrink and densify.

Each droplet carries its age [s] and original diameter d0 [m] (at the feed composition X0; its Cu2S mass is
proportional to d0^3 whatever its age). At every fluid step's end-of-step event point (:mod:`fulldem.submodels`),
after coalescence, this submodel advances every droplet's age by dt and sets, through the fit popbal uses
(:mod:`settler.physics.matte`):

* X = X_inf - (X_inf - X0) exp(-age / tau)   (:func:`settler.physics.reaction_fraction`);
* density rho(X) = 1000 (3.9732 + 1.3012 X) kg/m^3 (seed Eq. 4, :func:`settler.physics.matte_density`);
* diameter d0 (V(X)/V(X0))^(1/3): FeS removed, Cu2S kept (Eq. 5, :func:`settler.physics.relative_diameter`).

X0 follows from the fed matte's density (``matte.density``, Eq. 4); X_inf is ``reaction.x_final`` or, with
``reaction.end_state = "equilibrium"``, Cantera's equilibrium grade at the slag's temperature and oxygen pressure
(:attr:`settler.cases.Case.x_final`).

Modes (``reaction.mode``):

* ``"continuous"`` (default): every droplet takes the fit's density and size at every step -- the gradient the paper
  calls its improvement;
* ``"stepped"``: the paper's EDEM materials, densities from rho(X0) to rho(X_inf) in steps of
  ``reaction.density_step`` (4 500 ... 5 200 kg/m^3 in 50 kg/m^3 steps for the deep case). A droplet's density is
  the material nearest to the fit's; when that changes the paper deleted the droplet and created a new one of the
  next material with the same properties: here it changes material in place, counted in
  :attr:`fulldem.stepper.Counters.recreated`. Its size follows the fit continuously, as in the paper.

Mass accounting: the drop in the droplets' mass over the step is booked as ``mass_reacted`` (the FeS removed), so
fed = in slag + settled + lost + reacted holds exactly. Two terms that are not FeS removal enter it too, and are
small: a merged droplet takes the mass-weighted age (conserving mass x age), whose fit composition differs slightly
from the pair's mixed one; and in the stepped mode a change of material changes the mass at a fixed size.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from settler.physics import matte_density, reaction_fraction, relative_diameter

from .base import Submodel


MODES = ("continuous", "stepped")


@njit(cache=True, parallel=True)
def fit_sizes(original_diameter, age, count, x_initial, x_final, time_constant, diameter, density):
    """diameter [m] and density [kg/m^3] of droplets of original diameter d0 [m] and age [s] on the reaction fit
    (written in place; the shared laws of settler.physics.matte, one droplet at a time)."""
    for p in prange(count):
        x = reaction_fraction(age[p], x_initial, x_final, time_constant)
        diameter[p] = original_diameter[p] * relative_diameter(x, x_initial)
        density[p] = matte_density(x)


class Reaction(Submodel):
    """Ages every droplet and sets its density and size from the reaction fit (module docstring)."""

    name = "reaction"

    def __init__(self, case):
        r = case.reaction
        if r.mode not in MODES:
            raise ValueError(f"reaction.mode = {r.mode!r}: allowed: {', '.join(MODES)}")
        self.mode = r.mode
        self.x_initial = case.x_initial
        self.x_final = case.x_final
        self.time_constant = r.time_constant
        low, high = sorted((matte_density(self.x_initial), matte_density(self.x_final)))
        steps = max(int(math.floor((high - low) / r.density_step + 1e-9)), 0)
        #: the stepped mode's material densities [kg/m^3]
        self.materials = low + r.density_step * np.arange(steps + 1)

    def sizes(self, original_diameter, age):
        """(diameter [m], density [kg/m^3]) of droplets of original diameter d0 [m] and age [s] in this mode."""
        original_diameter = np.ascontiguousarray(original_diameter, dtype=float)
        age = np.ascontiguousarray(age, dtype=float)
        n = original_diameter.shape[0]
        diameter, density = np.empty(n), np.empty(n)
        fit_sizes(original_diameter, age, n, self.x_initial, self.x_final, self.time_constant, diameter, density)
        if self.mode == "stepped" and self.materials.size > 1:
            nearest = np.rint((density - self.materials[0]) / (self.materials[1] - self.materials[0]))
            density = self.materials[np.clip(nearest.astype(np.int64), 0, self.materials.size - 1)]
        elif self.mode == "stepped":
            density = np.full(n, self.materials[0])
        return diameter, density

    def at_end(self, sim) -> None:
        s, n = sim.store, sim.store.count
        if n == 0:
            return
        s.age[:n] += sim.dt
        before = float(np.sum(s.density[:n] * s.diameter[:n] ** 3)) * math.pi / 6.0
        old_density = s.density[:n].copy()
        diameter, density = self.sizes(s.original_diameter[:n], s.age[:n])
        s.set_sizes(diameter, density)
        after = float(np.sum(s.density[:n] * s.diameter[:n] ** 3)) * math.pi / 6.0
        sim.counters.mass_reacted += before - after
        if self.mode == "stepped":
            sim.counters.recreated += int(np.count_nonzero(density != old_density))

