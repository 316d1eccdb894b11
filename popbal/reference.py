"""Plain-NumPy twins of the compiled kernels (slow, written for reading; the tests require both to agree).

Each twin takes the same inputs as its kernel in :mod:`popbal.kernels` and returns what the kernel writes, built
from the textbook formula rather than the kernel's loops: the cell-average technique from its pair sums, the
collision kernel from broadcasting, the implicit upwind transport as a dense linear solve.
"""

from __future__ import annotations

import numpy as np

from settler.physics import RULE_STEP, coalescence_probability_v

from .kernels import NUMBER


def cell_average_rates(content, pivots, target, beta):
    """d content/dt of one cell by the cell-average technique (Kumar et al. 2006, Eqs. 17-20)."""
    n_q, n_k = content.shape
    number = content[NUMBER]
    j, k = np.nonzero((target >= 0) & (np.arange(n_k)[:, None] <= np.arange(n_k)[None, :]))
    rate = beta[j, k] * number[j] * number[k] * np.where(j == k, 0.5, 1.0)
    cell = target[j, k]
    birth = np.bincount(cell, rate, n_k)
    birth_volume = np.bincount(cell, rate * (pivots[j] + pivots[k]), n_k)
    with np.errstate(invalid="ignore", divide="ignore"):
        per_droplet = np.where(number > 0.0, content / number, 0.0)  # (Q, K) quantity per droplet
    rates = np.zeros_like(content)
    rates[NUMBER] -= np.bincount(j, rate, n_k) + np.bincount(k, rate, n_k)
    births_q = [np.bincount(cell, rate * (per_droplet[q, j] + per_droplet[q, k]), n_k) for q in range(1, n_q)]
    for q in range(1, n_q):
        rates[q] -= np.bincount(j, rate * per_droplet[q, j], n_k) + np.bincount(k, rate * per_droplet[q, k], n_k)
    for i in np.flatnonzero(birth > 0.0):
        vbar = birth_volume[i] / birth[i]
        other = i + 1 if vbar >= pivots[i] else i - 1
        if not 0 <= other < n_k:
            rates[NUMBER, i] += birth_volume[i] / pivots[i]
            for q in range(1, n_q):
                rates[q, i] += births_q[q - 1][i]
            continue
        # number and volume: a + b = 1, a x_i + b x_other = vbar
        a = np.linalg.solve([[1.0, 1.0], [pivots[i], pivots[other]]], [1.0, vbar])[0]
        rates[NUMBER, i] += a * birth[i]
        rates[NUMBER, other] += (1.0 - a) * birth[i]
        share = a * pivots[i] / vbar
        for q in range(1, n_q):
            rates[q, i] += share * births_q[q - 1][i]
            rates[q, other] += (1.0 - share) * births_q[q - 1][i]
    return rates


def collision_kernel(number, pivots, diameters, velocities, densities, shear_rate, density_slag, interfacial_tension,
                     psi, virtual_mass, form, threshold, rule, efficiency, target, negligible=1e-14):
    """beta (K, K) [m^3/s]: differential settling + shear collision frequency x merger fraction (direct Eq. 2)."""
    d_sum = diameters[:, None] + diameters[None, :]
    rho = 0.5 * (densities[:, None] + densities[None, :])
    dv = np.abs(velocities[:, None] - velocities[None, :])
    shear_speed = 0.5 * shear_rate * d_sum

    def merges(speed):
        p = coalescence_probability_v(diameters[:, None], diameters[None, :], speed, rho, density_slag,
                                      interfacial_tension, psi, virtual_mass, form)
        return (p >= threshold).astype(float) if rule == RULE_STEP else p

    beta = 0.25 * np.pi * d_sum**2 * dv * merges(dv) + shear_rate * d_sum**3 / 6.0 * merges(shear_speed)
    present = number * pivots >= negligible
    keep = (target >= 0) & present[:, None] & present[None, :]
    return np.where(keep, efficiency * beta, 0.0)


def transport_zone(content, face_velocity, sink_rate, top_source, dz, dt):
    """Backward-Euler upwind step as a dense linear solve per section; returns (content, bottom_out, sink_out)."""
    n_j, n_q, n_k = content.shape
    new = np.empty_like(content)
    bottom = np.zeros((n_q, n_k))
    sink = np.zeros((n_q, n_k))
    for k in range(n_k):
        u = face_velocity[:, k]
        # (1 + dt u_j/dz + dt s_j) N_j - dt u_{j+1}/dz N_{j+1} = N_j^old (+ dt source at the top)
        matrix = np.diag(1.0 + dt * u / dz + dt * sink_rate) - np.diag(dt * u[1:] / dz, 1)
        for q in range(n_q):
            rhs = content[:, q, k].copy()
            rhs[-1] += dt * top_source[q, k]
            new[:, q, k] = np.linalg.solve(matrix, rhs)
            bottom[q, k] = dt * u[0] * new[0, q, k]
            sink[q, k] = dt * np.sum(sink_rate * new[:, q, k]) * dz
    return new, bottom, sink
