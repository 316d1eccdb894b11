"""Channeling closure: the collective velocity of the droplet plume under the inlet (two-zone model).

Derivation. A spherical cloud of radius R holding droplets at volume fraction phi falls through the slag as a drop
of suspension whose excess density is phi (rho_p - rho_s) and whose viscosity equals the slag's (viscosity ratio
1). Its Hadamard-Rybczynski velocity is

    U = (2/3) (phi drho g R^2 / mu) (1 + lam)/(2 + 3 lam),  lam = 1  ->  U = (4/15) phi drho g R^2 / mu,

which, with N = phi R^3/a^3 droplets of radius a and U_St = (2/9) drho g a^2 / mu, is U = U_St (6/5) N a / R:
the falling-cloud result of Nitsche & Batchelor (JFM 340, 1997) quoted in physics.md section 4. In shared-law
form U = stokes_velocity(2R, rho_s + phi drho, rho_s, mu) * hadamard_rybczynski_factor(1) (checked in the tests).

A continuous feed Q [m^3/s] of matte into a channel of radius R_c gives, by conservation of the volume flux, a
channel volume fraction phi = Q / (pi R_c^2 u). With the cloud law u = c_ch phi drho g R_c^2 / mu the two close to

    u_c = sqrt(c_ch Q drho g / (pi mu)),

independent of R_c. For the seed paper's simple case (Q = 0.0086/5100 m^3/s, drho = 1950 kg/m^3, mu = 0.45 Pa s)
u_c = 0.078 m/s and the plume Reynolds number rho_s u_c R_c / mu = 41 for R_c = 75 mm (about 80 on the diameter),
inside the 10-1000 range physics.md section 4 expects. The reduced model applies the *local* form
u_c(z) = c_ch g R_c^2 sum_k phi_k (rho_k - rho_s) / mu in every channel cell (popbal.kernels.cell_properties): it
needs no steady state, lets the front of a starting plume advance as a shock, and relaxes to the expression above.

Two-zone model. The slag column is split into a channel under the inlet (radius R_c = channel_radius_factor x the
inlet radius) and the outer zone (the rest of the box cross-section). A fraction f_ch (channel_feed_fraction) of
the matte feed enters the channel, where droplets move at u_c plus their own hindered settling velocity and collide
by differential settling and by the plume's shear, G = shear_coefficient x u_c / R_c; the rest settles
individually (hindered) in the outer zone, colliding by differential settling only. Parameters, all in the case's
[popbal] section and all to be calibrated against the full engine: c_ch (channel_coefficient, default 4/15 from
the cloud solution), f_ch, the radius factor, shear_coefficient and collision_efficiency.

Feed layer (issue 13, from the full engine's reference runs). The full runs do not feed a plume directly: the fed
droplets first collect in a dense layer under the inlet and only then accelerate into the plume. At the end of the
stored runs (data/reference/<case>/snapshots.npz) the top 5 mm hold 28 % of the simple case's droplets, moving
down at 1.8 mm/s, and the droplets reach the plume's speed only 25-30 mm under the top (simple: 45 mm/s; deep:
3.7 mm/s in the top 5 mm, 12 mm/s from 30 mm down); 42-45 % of all droplets are in the top tenth of the height in
both cases, and a good share of the mergers happens there. The old form, which put every fed droplet straight into
the plume at u_c, held half the simple case's droplets and merged almost none. The layer is the top
``feed_layer_thickness`` (delta) of the channel zone, where the same cloud law applies with the layer's own
coefficient and length scale, u_L = c_L phi drho g delta^2 / mu (``feed_layer_coefficient`` c_L): a slab fed at the
volume flux j per unit area holds phi = j / u_L, so u_L = sqrt(c_L j drho g / mu) delta. Both scaled cases feed
the same matte flux per inlet area (0.48 kg/m^2/s), which is why one (delta, c_L) can describe both.

Axis velocity. ``channel_velocity`` in the shared time series is the *slag's* downward velocity on the axis at
mid-height (settler.output). The droplets of the full runs move slower than the slag on the axis (simple: 36 mm/s
on the centreline against 86 mm/s of slag), as droplets spread over a plume whose slag velocity peaks on the axis.
u_c is the velocity of the droplet-laden cloud (what moves the droplets); the reduced model reports the axis
velocity as ``axis_velocity_ratio`` x u_c (plus the downflow), a calibrated ratio (1: the old form).

Not modelled (calibration will tell whether they matter): the return flow of slag in the outer zone and the
exchange of droplets between the zones (the paper's ring flow, which pulls droplets into the channel, and, in the
simple case's lower half, carries them out of the slag jet), the cloud's break-up, and inertia of the plume
(Re > 1).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from settler.physics import STANDARD_GRAVITY

#: Hadamard-Rybczynski coefficient of a cloud with viscosity ratio 1: U = (4/15) phi drho g R^2 / mu.
CLOUD_COEFFICIENT = 4.0 / 15.0


@njit(cache=True)
def cloud_velocity(excess_load, radius, viscosity, coefficient=CLOUD_COEFFICIENT, gravity=STANDARD_GRAVITY):
    """Velocity [m/s] of a cloud of radius R [m] whose excess density is excess_load = sum_k phi_k (rho_k - rho_s)
    [kg/m^3]: c_ch excess_load g R^2 / mu. The one implementation of the closure; the kernels call it per cell."""
    return coefficient * excess_load * gravity * radius * radius / viscosity


def steady_channel_velocity(volume_flux, excess_density, viscosity, coefficient=CLOUD_COEFFICIENT,
                            gravity=STANDARD_GRAVITY):
    """Self-consistent plume velocity u_c = sqrt(c Q drho g / (pi mu)) [m/s] for a matte feed Q [m^3/s]."""
    return math.sqrt(coefficient * volume_flux * excess_density * gravity / (math.pi * viscosity))


def steady_channel_fraction(volume_flux, radius, velocity):
    """Matte volume fraction phi = Q / (pi R^2 u) [-] of a channel of radius [m] carrying Q [m^3/s] at u [m/s]."""
    return volume_flux / (math.pi * radius * radius * velocity) if velocity > 0.0 else 0.0


def plume_reynolds(velocity, radius, density_slag, viscosity):
    """Plume Reynolds number rho_s u_c R_c / mu [-] (on the radius)."""
    return density_slag * velocity * radius / viscosity


def cloud_profile(z, height, channel_radius, channel_coefficient, layer_thickness=None, layer_coefficient=None):
    """Cloud coefficient [-] and length scale [m] of every channel cell, arrays (J,) for cell centres z (J,) [m].

    Below the feed layer: the plume's c_ch and R_c. In the feed layer (cells whose centre lies within
    ``layer_thickness`` [m] of the top ``height`` [m], and at least the top cell when the thickness is > 0): the
    layer's c_L and delta. ``layer_thickness`` None or 0: no layer (the old form).
    """
    z = np.asarray(z, dtype=float)
    coefficient = np.full(z.shape, float(channel_coefficient))
    radius = np.full(z.shape, float(channel_radius))
    if layer_thickness:
        layer = z >= height - layer_thickness
        layer[np.argmax(z)] = True
        coefficient[layer] = layer_coefficient
        radius[layer] = layer_thickness
    return coefficient, radius
