"""Derived numbers of a case: the dimensionless groups and rates everyone asks for before a run.

One function, :func:`derived_numbers`, computes them for ``settler info`` and for the engines' start-up logs, so a
number is never computed two ways.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from .cases import Case
from .physics import (FORM_LUO, FORM_SEED, coalescence_probability, droplet_rate, hadamard_rybczynski_factor,
                      mean_droplet_mass, relaxation_time, relative_diameter, reynolds_number,
                      schiller_naumann_velocity, scale_factor_moment, stokes_velocity,
                              table_droplet_rate, weber_number)
from .physics import matte_density as matte_density_law

#: Richardson-Zaki exponent n (Richardson & Zaki 1954) used for the hindered estimate.
RICHARDSON_ZAKI_EXPONENT = 4.65

#: The seed paper's time steps [s] (section 3.2/3.3: CFD 5e-5 s, DEM 2e-5 s), quoted for tau_p/dt.
PAPER_CFD_STEP = 5e-5
PAPER_DEM_STEP = 2e-5


@dataclass(frozen=True)
class Quantity:
    """A derived number with its unit and how it was obtained."""

    name: str
    value: float
    unit: str
    note: str = ""


def settling_velocity(case: Case, diameter, density=None):
    """Terminal settling velocity of a single droplet in the case's slag with the case's drag law [m/s]."""
    rho = case.matte.density if density is None else density
    mu = case.slag_viscosity
    if case.drag.law == "stokes":
        v = stokes_velocity(diameter, rho, case.slag.density, mu)
    else:
        v = schiller_naumann_velocity(diameter, rho, case.slag.density, mu)
    if case.drag.fluid_drop:
        v *= hadamard_rybczynski_factor(case.matte.viscosity / mu)
    return v


@dataclass(frozen=True)
class FeedSummary:
    """The feed distribution reduced to the numbers the derived quantities need (SI)."""

    rate: float  # droplets per second [1/s]
    mean_mass: float  # [kg]
    mean_mass_note: str
    mean_diameter: float  # d_mean (normal) or mass-weighted mean diameter (table) [m]
    smallest: float  # [m]
    largest: float  # [m]
    slowness_factor: float  # sum_k w_k (d_mean / d_k)^2 over mass fractions w_k [-]


def feed_summary(case: Case) -> FeedSummary:
    """Rate, mean mass and size range of the case's feed, for either feed distribution."""
    f, rho_p = case.feed, case.matte.density
    if getattr(f, "distribution", "normal") == "table":
        d = np.asarray(f.table_diameters, dtype=float)
        w = np.asarray(f.table_mass_fractions, dtype=float)
        rate = float(table_droplet_rate(f.mass_rate, d, w, rho_p))
        d_mean = float(np.sum(w * d))
        mean_mass = f.mass_rate / rate if rate > 0 else float(np.sum(w * rho_p * math.pi / 6.0 * d**3))
        return FeedSummary(rate, mean_mass, "matte rate / droplets per second (table)", d_mean, float(d.min()),
                           float(d.max()), float(np.sum(w * (d_mean / d) ** 2)))
    dist = (f.scale_std, f.scale_min, f.scale_max)
    return FeedSummary(droplet_rate(f.mass_rate, f.mean_diameter, rho_p, *dist),
                       mean_droplet_mass(f.mean_diameter, rho_p, *dist), "rho pi/6 d_mean^3 E[s^3]",
                       f.mean_diameter, f.mean_diameter * f.scale_min, f.mean_diameter * f.scale_max,
                       scale_factor_moment(1, *dist) / scale_factor_moment(3, *dist))


def derived_numbers(case: Case) -> dict[str, list[Quantity]]:
    """Derived numbers of a case, grouped by topic (dict of lists of :class:`Quantity`)."""
    f, s, m, g = case.feed, case.slag, case.matte, case.geometry
    mu = case.slag_viscosity
    rho_p = m.density
    dist = (f.scale_std, f.scale_min, f.scale_max)
    groups: dict[str, list[Quantity]] = {}

    groups["slag"] = [
        Quantity("viscosity at run temperature", mu, "Pa s", f"Arrhenius at T = {s.temperature:.2f} K"),
        Quantity("slag throughput residence time",
                 s.density * g.height * g.width * g.depth / s.feed_rate if s.feed_rate > 0 else math.inf, "s",
                 "box slag mass / slag feed rate"),
    ]

    summary = feed_summary(case)
    nominal = f.mass_rate / (rho_p * math.pi / 6.0 * summary.mean_diameter**3)
    groups["feed"] = [
        Quantity("droplets fed per second", summary.rate, "1/s",
                 "matte rate / mean droplet mass over the feed distribution"),
        Quantity("droplets fed per second at d_mean", nominal, "1/s",
                 f"matte rate / mass of a d_mean = {summary.mean_diameter * 1e6:.4g} um droplet"),
        Quantity("mean fed droplet mass", summary.mean_mass, "kg", summary.mean_mass_note),
        Quantity("matte volume feed", f.mass_rate / rho_p, "m^3/s", ""),
    ]

    sizes = {"smallest fed": summary.smallest, "mean fed": summary.mean_diameter, "largest fed": summary.largest}
    if case.coalescence.enabled:
        sizes["size limit"] = case.coalescence.size_limit
    settling = []
    for label, d in sizes.items():
        v_st = stokes_velocity(d, rho_p, s.density, mu)
        v = settling_velocity(case, d)
        tau = relaxation_time(d, rho_p, mu)
        settling += [
            Quantity(f"Stokes velocity, {label} ({d * 1e3:.3g} mm)", v_st, "m/s", "Eq. 1"),
            Quantity(f"terminal velocity, {label}", v, "m/s", f"{case.drag.law} drag"),
            Quantity(f"Re_p, {label}", reynolds_number(d, v, s.density, mu), "-", "at terminal velocity"),
            Quantity(f"tau_p, {label}", tau, "s", f"tau_p / paper DEM step = {tau / PAPER_DEM_STEP:.3g}"),
        ]
    groups["settling"] = settling

    # Dilute plume under the inlet: each size class k carries its volume flux Q_k at its own velocity v_k, so
    # phi = sum Q_k / (A v_k) = Q / (A v(d_mean)) * sum_k w_k (d_mean / d_k)^2 in the Stokes regime.
    area = math.pi * 0.25 * g.inlet_diameter**2
    v_mean = stokes_velocity(summary.mean_diameter, rho_p, s.density, mu)
    q = f.mass_rate / rho_p
    phi_dilute = q / (area * v_mean) * summary.slowness_factor
    n = RICHARDSON_ZAKI_EXPONENT
    phi_peak = 1.0 / (1.0 + n)
    flux_peak = phi_peak * (1.0 - phi_peak) ** n
    if phi_dilute <= 0.0:
        phi_hindered, note = 0.0, "no matte feed"
    elif phi_dilute < flux_peak:
        phi_hindered = optimize.brentq(lambda p: p * (1.0 - p) ** n - phi_dilute, 0.0, phi_peak)
        note = "phi (1 - phi)^4.65 = dilute estimate"
    else:
        phi_hindered = math.nan
        note = (f"no steady hindered state: the feed exceeds the largest hindered flux {flux_peak:.3f}; "
                "collective (plume) settling must carry it")
    radius = 0.5 * g.inlet_diameter
    groups["cluster under the inlet"] = [
        Quantity("volume fraction, dilute estimate", phi_dilute, "-", "Q / (A_inlet v_St) over the feed distribution"),
        Quantity("volume fraction, hindered (Richardson-Zaki)", phi_hindered, "-", note),
        Quantity("collective-settling number (6/5) phi (R/a)^2", 1.2 * phi_dilute * (radius / (0.5 * summary.mean_diameter)) ** 2,
                 "-", "> 1: the cloud falls as a plume (Nitsche & Batchelor 1997)"),
    ]

    sigma = m.interfacial_tension
    c = case.coalescence
    form = FORM_LUO if c.probability_form == "luo" else FORM_SEED
    d_small, d_mean, d_large = sizes["smallest fed"], sizes["mean fed"], sizes["largest fed"]
    pairs = [
        ("smallest on largest fed, differential settling", d_small, d_large,
         abs(settling_velocity(case, d_large) - settling_velocity(case, d_small))),
        ("two mean droplets, approach at v_St", d_mean, d_mean, settling_velocity(case, d_mean)),
    ]
    if c.enabled:
        pairs.append(("size-limit droplet on a mean droplet", d_mean, c.size_limit,
                      abs(settling_velocity(case, c.size_limit) - settling_velocity(case, d_mean))))
    coal = []
    for label, da, db, u in pairs:
        we = weber_number(min(da, db), u, s.density, sigma)
        p = coalescence_probability(da, db, u, rho_p, s.density, sigma, c.psi, c.virtual_mass, form)
        coal.append(Quantity(f"P_c, {label}", p, "-", f"u = {u:.3g} m/s, We = {we:.3g}, {c.probability_form} form"))
    groups["coalescence"] = coal

    if case.reaction.enabled:
        x0, xf = case.x_initial, case.x_final
        groups["reaction"] = [
            Quantity("feed Cu2S mole fraction X0", x0, "-", "Eq. 4 inverted at matte.density"),
            Quantity("end-state Cu2S mole fraction X_inf", xf, "-", f"end_state = {case.reaction.end_state}"),
            Quantity("end-state density", matte_density_law(xf), "kg/m^3", "Eq. 4"),
            Quantity("end-state relative diameter", relative_diameter(xf, x0), "-", "Cu2S kept, FeS removed (Eq. 5)"),
            Quantity("time constant", case.reaction.time_constant, "s", "chosen unless sourced"),
        ]
        from .thermo import equilibrium_grade, mass_fraction_cu

        r = case.reaction
        x_eq = float(equilibrium_grade(s.temperature, r.oxygen_pressure, p_so2=r.so2_pressure, a_feo=r.feo_activity))
        groups["reaction"] += [
            Quantity("Cantera equilibrium X_inf at run T, pO2", x_eq, "-",
                     f"ideal mixing (qualitative); pO2 = {r.oxygen_pressure:g} Pa, pSO2 = {r.so2_pressure:g} Pa, "
                     f"a_FeO = {r.feo_activity:g}"),
            Quantity("matte grade at X_inf", 100.0 * float(mass_fraction_cu(xf)), "wt% Cu", ""),
        ]
    return groups


def format_numbers(groups: dict[str, list[Quantity]]) -> str:
    """Plain-text table of :func:`derived_numbers`."""
    lines = []
    for group, items in groups.items():
        lines.append(f"{group}:")
        for q in items:
            value = f"{q.value:.4g}" if isinstance(q.value, float) else str(q.value)
            lines.append(f"  {q.name:<52s} {value:>12s} {q.unit:<7s} {q.note}")
    return "\n".join(lines)


def as_records(groups: dict[str, list[Quantity]]) -> list[dict]:
    """Flat list of dicts (group, name, value, unit, note), e.g. for JSON or pandas."""
    return [{"group": g, "name": q.name, "value": float(np.float64(q.value)), "unit": q.unit, "note": q.note}
            for g, items in groups.items() for q in items]
