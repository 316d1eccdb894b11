"""The correction for a droplet's own disturbance of the grid flow (self-mobility).

**Self-induced velocity.** A droplet that pushes on the grid with force F sees, at its own position, a disturbance
u_self = M_self F it created itself, along the force the *fluid* receives, -F_drag; using the disturbed velocity
would make droplets not much smaller than sigma settle too fast (the error grows like d/sigma). Following the idea
of Balachandar, Liu & Lakhote (2019, J. Comput. Phys. 376, 160) and Horwitz & Mani (2016, J. Comput. Phys. 318,
85), the undisturbed velocity is estimated as u_interp + M_self F_drag. With the linear drag
F_drag = beta (u_undisturbed - v) this is the same as using u_interp with the increased coefficient
beta / (1 - beta M_self), which keeps the exact exponential drag integrator. beta M_self = d f / (2 sqrt(pi) sigma)
at low Re is at most about 0.6 with sigma >= d/2; it is capped at :data:`SELF_CORRECTION_CAP`.
M_self is the Gaussian-regularised Stokeslet's self-mobility 1/(6 pi^(3/2) mu sigma) (Maxey & Patel 2001), times
a *discrete* factor computed once per sigma/h by solving the grid's own periodic Stokes problem with FFTs
(:func:`discrete_mobility_factor`), times an Oseen factor of the slip Reynolds number rho |u - v| sigma / mu
(:func:`oseen_factor`), which accounts for inertia sweeping the disturbance downstream.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from scipy import fft as sfft
from scipy import integrate

from .smoothing import DEFAULT_CUT, deposit, interpolate


#: Hasimoto (1959) coefficient of the periodic-array correction of a Stokeslet's mobility, 1 - 2.837 a / L.
HASIMOTO = 2.837297
#: Upper bound applied to beta M_self in the self-induced-velocity correction (the correction diverges at 1).
SELF_CORRECTION_CAP = 0.9


def _stokes_transfer(n, h, mu):
    """FFT symbol of the periodic MAC Stokes solve for the z-velocity from a z-force (no mean flow)."""
    k = 2.0 * np.pi * sfft.fftfreq(n, d=h)
    g2 = (2.0 * np.sin(k * h / 2.0) / h) ** 2
    gx2, gy2, gz2 = np.meshgrid(g2, g2, g2, indexing="ij")
    gsum = gx2 + gy2 + gz2
    gsum[0, 0, 0] = 1.0
    transfer = (1.0 - gz2 / gsum) / (mu * gsum)
    transfer[0, 0, 0] = 0.0  # no mean flow: the periodic box's uniform counter-force
    return transfer


@njit(cache=True)
def gaussian_self_mobility(smoothing_width, viscosity):
    """Self-mobility of a Gaussian-regularised Stokeslet averaged with the same Gaussian, 1/(6 pi^1.5 mu sigma)
    [m/(N s)] (Maxey & Patel 2001: a Gaussian of width sigma = a / sqrt(pi) reproduces Stokes drag on radius a)."""
    return 1.0 / (6.0 * math.pi**1.5 * viscosity * smoothing_width)


def _oseen_inner(s, re):
    """int_-1^1 (1 - c^2) s^2 / (s^2 + Re^2 c^2) dc = 2a[(1 + a^2) arctan(1/a) - a], a = s/Re (closed form)."""
    if re == 0.0:
        return 4.0 / 3.0
    a = s / re
    if a > 1e3:  # series in 1/a avoids cancellation: 4/3 - 4/(15 a^2) + ...
        return 4.0 / 3.0 - 4.0 / (15.0 * a * a)
    return 2.0 * a * ((1.0 + a * a) * math.atan(1.0 / a) - a)


def _oseen_integral(re):
    return integrate.quad(lambda s: math.exp(-s * s) * _oseen_inner(s, re), 0.0, 9.0, epsabs=1e-13,
                          epsrel=1e-11, limit=400)[0]


@functools.lru_cache(maxsize=1)
def oseen_table():
    """Table (log10 Re_sigma, factor) of the Oseen factor, computed once by quadrature."""
    logs = np.linspace(-3.0, 4.0, 57)
    stokes = _oseen_integral(0.0)
    factors = np.array([_oseen_integral(10.0**x) / stokes for x in logs])
    return logs, factors


def oseen_factor(re_width):
    """u_self(Re)/u_self(0) for a Gaussian-regularised Oseenlet along the slip direction [-].

    u_self(Re) / u_self(0) = I(Re) / I(0), I(Re) = int_0^inf ds int_-1^1 dc exp(-s^2)(1 - c^2) s^2/(s^2 + Re^2 c^2),
    Re = rho |u - v| sigma / mu: the Fourier-space Oseen tensor averaged over the Gaussian (derived in the module
    docstring's references' manner). 1 at Re = 0, falling like 1/Re for large Re.
    """
    logs, factors = oseen_table()
    x = np.log10(np.maximum(np.asarray(re_width, dtype=float), 10.0 ** logs[0]))
    inside = np.interp(np.minimum(x, logs[-1]), logs, factors)
    return np.where(x > logs[-1], factors[-1] * 10.0 ** (logs[-1] - x), inside)


@functools.lru_cache(maxsize=64)
def discrete_mobility_factor(sigma_cells_ratio: float, cut: float = DEFAULT_CUT, n: int = 48, samples: int = 4):
    """Self-mobility of a droplet on the MAC grid divided by the continuous Gaussian value (dimensionless).

    A unit z-force is spread on the z-faces of a periodic n^3 grid with the coupling kernel (sigma = ratio * h), the
    discrete Stokes problem mu L u - grad p + f = 0, div u = 0 is solved exactly with FFTs (MAC symbols
    g_a = 2 sin(k_a h / 2) / h), u_z is interpolated back with the same weights, Hasimoto's periodic-image term is
    added back, and the result is averaged over ``samples`` sub-cell positions. Viscosity and h cancel out.
    """
    h, mu = 1.0, 1.0
    shape = (n, n, n)
    periodic = np.array([True, True, True])
    lower = np.zeros(3)
    transfer = _stokes_transfer(n, h, mu)
    rng = np.random.default_rng(12345)
    smoothing_width = sigma_cells_ratio * h
    values = []
    for _ in range(samples):
        pos = np.array([[n / 2 + rng.uniform(0, 1), n / 2 + rng.uniform(0, 1), n / 2 + rng.uniform(0, 1)]])
        diam = np.array([0.0])
        force = np.zeros(shape)
        scratch = np.zeros((1, *shape))
        deposit(pos, diam, np.array([1.0]), 1, 2, force, h, lower, np.array(shape), periodic, sigma_cells_ratio,
                0.0, cut, scratch)
        uz = np.real(sfft.ifftn(sfft.fftn(force / h**3) * transfer))
        out = np.zeros(1)
        interpolate(pos, diam, 1, 2, uz, out, h, lower, np.array(shape), periodic, sigma_cells_ratio, 0.0, cut)
        values.append(out[0])
    periodic_mobility = float(np.mean(values))
    unbounded = periodic_mobility + HASIMOTO / (6.0 * math.pi * mu * n * h)
    return unbounded / gaussian_self_mobility(smoothing_width, mu)


@njit(cache=True)
def corrected_drag_coefficient(beta, smoothing_width, viscosity, discrete_factor, oseen):
    """beta / (1 - beta M_self): the drag coefficient to use with the interpolated (disturbed) fluid velocity [kg/s].

    M_self = discrete_factor * oseen / (6 pi^1.5 mu sigma) is the droplet's own self-mobility on the grid.
    """
    m_self = discrete_factor * oseen * gaussian_self_mobility(smoothing_width, viscosity)
    return beta / (1.0 - min(beta * m_self, SELF_CORRECTION_CAP))
