"""Smoluchowski coagulation without transport: analytic solutions and the 0-D sectional solver that is checked
against them (physics.md section 5).

Exponential initial condition n0(v) = (N0/v0) exp(-v/v0); dimensionless time tau and moments M_k / (N0 v0^k):

* constant kernel beta0 (Scott 1968, J. Atmos. Sci. 25, 54): tau = beta0 N0 t, M0 = 2/(2 + tau),
  M2 = 2 + tau (dM2/dt = beta0 M1^2);
* sum kernel beta1 (u + v) (Golovin 1963; Scott 1968): tau = beta1 N0 v0 t, M0 = exp(-tau), M2 = 2 exp(2 tau);
* product kernel beta2 u v (McLeod 1962; Scott 1968): tau = beta2 N0 v0^2 t, M0 = 1 - tau/2, M2 = 2/(1 - 2 tau),
  gelation at tau = 1/2.

The registry :data:`KERNELS` maps each name to its kernel matrix on the pivots and its moments; tests loop over it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import special

from .grid import SectionGrid, exponential_sections, make_grid
from .kernels import integrate_cell


@dataclass(frozen=True)
class AnalyticKernel:
    """A kernel with a closed-form solution from the exponential initial condition (N0 = v0 = coefficient = 1)."""

    matrix: Callable[[np.ndarray], np.ndarray]  # pivots (K,) -> beta (K, K)
    zeroth_moment: Callable[[float], float]  # tau -> M0 / N0
    second_moment: Callable[[float], float]  # tau -> M2 / (N0 v0^2)
    density: Callable[[np.ndarray, float], np.ndarray] | None  # (v / v0, tau) -> n v0 / N0
    aggregation_95: float  # tau at which 95 % of the droplets have merged (M0 = 0.05 N0), or the limit
    source: str


def _constant_density(x, tau):
    return 4.0 / (tau + 2.0) ** 2 * np.exp(-2.0 * x / (tau + 2.0))


def _sum_density(x, tau):
    t = 1.0 - np.exp(-tau)
    if t == 0.0:
        return np.exp(-x)
    # I1(z) e^-z is special.i1e, so the large exponentials cancel analytically
    z = 2.0 * x * np.sqrt(t)
    return (1.0 - t) / (x * np.sqrt(t)) * np.exp(-(1.0 + t) * x + z) * special.i1e(z)


KERNELS: dict[str, AnalyticKernel] = {
    "constant": AnalyticKernel(
        lambda x: np.ones((x.size, x.size)), lambda tau: 2.0 / (2.0 + tau), lambda tau: 2.0 + tau,
        _constant_density, 38.0, "Scott 1968, J. Atmos. Sci. 25, 54"),
    "sum": AnalyticKernel(
        lambda x: x[:, None] + x[None, :], lambda tau: np.exp(-tau), lambda tau: 2.0 * np.exp(2.0 * tau),
        _sum_density, float(np.log(20.0)), "Golovin 1963; Scott 1968"),
    "product": AnalyticKernel(
        lambda x: x[:, None] * x[None, :], lambda tau: 1.0 - 0.5 * tau, lambda tau: 2.0 / (1.0 - 2.0 * tau),
        None, 0.4, "McLeod 1962; Scott 1968 (the issue stops at tau = 0.4, before gelation at 0.5)"),
}


@dataclass(frozen=True)
class SectionalSolution:
    """Sectional moments at the requested times (dimensionless: N0 = v0 = 1)."""

    grid: SectionGrid
    taus: np.ndarray  # (T,)
    number: np.ndarray  # (T, K) sectional number densities
    steps: int

    def moment(self, order: int) -> np.ndarray:
        return self.number @ self.grid.pivots**order


def solve(kernel: str, sections_per_doubling: int, taus, volume_min: float = 2.0**-13,
          volume_top: float = 2.0**15, max_rate_step: float = 2.5, max_step: float = 0.01) -> SectionalSolution:
    """Cell-average sectional solution of a registered kernel from the exponential initial condition.

    Pivots from below volume_min to volume_top (units of v0) with ratio 2^(1/sections_per_doubling); mergers beyond
    the top pivot are excluded, so the grid must reach far past the distribution's tail (the defaults hold the
    registered cases to 95 % aggregation with a M2 tail below 1e-8). Returns moments at ``taus``.
    """
    entry = KERNELS[kernel]
    grid = make_grid(volume_min, volume_top, sections_per_doubling)
    beta = np.ascontiguousarray(entry.matrix(grid.pivots))
    content = np.zeros((1, grid.size))  # number only: nothing else is carried in 0-D
    content[0] = exponential_sections(grid, 1.0, 1.0)
    taus = np.asarray(taus, dtype=float)
    out = np.empty((taus.size, grid.size))
    now, steps = 0.0, 0
    for n, tau in enumerate(taus):
        if tau > now:
            steps += integrate_cell(content, grid.pivots, grid.target, grid.loss_weight, beta, tau - now,
                                    max_rate_step, max_step)
            now = tau
        out[n] = content[0]
    return SectionalSolution(grid, taus, out, steps)
