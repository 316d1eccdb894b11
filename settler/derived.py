"""Derived numbers of a case: the dimensionless groups and rates everyone asks for before a run.

One function, :func:`derived_numbers`, computes them for ``settler info`` and for the engines' start-up logs, so a
number is never computed two ways.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .cases import Case
from .physics import (DRAG_LAWS, PROBABILITY_FORMS, coalescence_probability, droplet_rate, mean_droplet_mass,
                      relaxation_time, relative_diameter, reynolds_number, scale_factor_moment, sphere_mass,
                      stokes_velocity, table_droplet_rate, terminal_velocity, terminal_velocity_v, weber_number)
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
    """Terminal settling velocity of a single droplet in the case's slag with the case's drag law [m/s].

    The case-level form of :func:`settler.physics.terminal_velocity`, the one dispatch on ``drag.law`` and
    ``drag.fluid_drop`` that both engines use (popbal's velocity table, fulldem's ``Simulation.terminal_velocity``).
    diameter [m] and density [kg/m^3, default the fed matte's]: floats, or arrays that broadcast.
    """
    rho = case.matte.density if density is None else density
    mu = case.slag_viscosity
    law = DRAG_LAWS[case.drag.law]
    ratio = case.matte.viscosity / mu if case.drag.fluid_drop else 0.0
    if np.ndim(diameter) or np.ndim(rho):
        return terminal_velocity_v(diameter, rho, case.slag.density, mu, law, ratio)
    return terminal_velocity(diameter, rho, case.slag.density, mu, law, ratio)


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


def _ieee(record):
    """The record with its floats as NumPy float64s.

    Their arithmetic overflows to inf and divides by zero to inf or nan (under ``np.errstate(all="ignore")``) where
    Python floats raise, so a valid but absurd case (a 1e-300 m droplet, a 1e308 Pa s slag) still gets its numbers
    and its plausibility warnings instead of a ZeroDivisionError or OverflowError.
    """
    return dataclasses.replace(record, **{k: np.float64(v) for k, v in vars(record).items() if type(v) is float})


def feed_summary(case: Case) -> FeedSummary:
    """Rate, mean mass and size range of the case's feed, for either feed distribution."""
    with np.errstate(all="ignore"):
        return _feed_summary(_ieee(case.feed), np.float64(case.matte.density))


def _feed_summary(f, rho_p) -> FeedSummary:
    if getattr(f, "distribution", "normal") == "table":
        d = np.asarray(f.table_diameters, dtype=float)
        w = np.asarray(f.table_mass_fractions, dtype=float)
        rate = float(table_droplet_rate(f.mass_rate, d, w, rho_p))
        d_mean = np.sum(w * d)
        mean_mass = f.mass_rate / rate if rate > 0 else np.sum(w * rho_p * math.pi / 6.0 * d**3)
        return FeedSummary(rate, mean_mass, "matte rate / droplets per second (table)", d_mean, d.min(), d.max(),
                           np.sum(w * (d_mean / d) ** 2))
    dist = (f.scale_std, f.scale_min, f.scale_max)
    return FeedSummary(droplet_rate(f.mass_rate, f.mean_diameter, rho_p, *dist),
                       mean_droplet_mass(f.mean_diameter, rho_p, *dist), "rho pi/6 d_mean^3 E[s^3]",
                       f.mean_diameter, f.mean_diameter * f.scale_min, f.mean_diameter * f.scale_max,
                       scale_factor_moment(1, *dist) / scale_factor_moment(3, *dist))


def derived_numbers(case: Case) -> dict[str, list[Quantity]]:
    """Derived numbers of a case, grouped by topic (dict of lists of :class:`Quantity`).

    Values far outside the laws' ranges give inf or nan where the arithmetic overflows, never an exception.
    """
    with np.errstate(all="ignore"):
        return _derived_numbers(case)


def _derived_numbers(case: Case) -> dict[str, list[Quantity]]:
    f, s, m, g = _ieee(case.feed), _ieee(case.slag), _ieee(case.matte), _ieee(case.geometry)
    mu = np.float64(case.slag_viscosity)
    rho_p = m.density
    groups: dict[str, list[Quantity]] = {}

    groups["slag"] = [
        Quantity("viscosity at run temperature", mu, "Pa s", f"Arrhenius at T = {s.temperature:.2f} K"),
        Quantity("slag throughput residence time",
                 s.density * g.height * g.width * g.depth / s.feed_rate if s.feed_rate > 0 else math.inf, "s",
                 "box slag mass / slag feed rate"),
    ]

    summary = feed_summary(case)
    nominal = f.mass_rate / sphere_mass(summary.mean_diameter, rho_p)
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
    area = case.inlet_area  # the disk's pi d^2 / 4, a slot's length x width
    v_mean = stokes_velocity(summary.mean_diameter, rho_p, s.density, mu)
    q = f.mass_rate / rho_p
    phi_dilute = q / (area * v_mean) * summary.slowness_factor
    n = RICHARDSON_ZAKI_EXPONENT
    phi_peak = 1.0 / (1.0 + n)
    flux_peak = phi_peak * (1.0 - phi_peak) ** n
    if phi_dilute <= 0.0:
        phi_hindered, note = 0.0, "no matte feed"
    elif phi_dilute < flux_peak:
        from scipy import optimize  # imported here: scipy.optimize would slow every `settler` command's start

        phi_hindered = optimize.brentq(lambda p: p * (1.0 - p) ** n - phi_dilute, 0.0, phi_peak)
        note = "phi (1 - phi)^4.65 = dilute estimate"
    else:
        phi_hindered = math.nan
        note = (f"no steady hindered state: the feed exceeds the largest hindered flux {flux_peak:.3f}; "
                "collective (plume) settling must carry it")
    radius = 0.5 * g.inlet_diameter  # a slot: half its width, the cloud's narrower half-extent
    groups["cluster under the inlet"] = [
        Quantity("volume fraction, dilute estimate", phi_dilute, "-", "Q / (A_inlet v_St) over the feed distribution"),
        Quantity("volume fraction, hindered (Richardson-Zaki)", phi_hindered, "-", note),
        Quantity("collective-settling number (6/5) phi (R/a)^2", 1.2 * phi_dilute * (radius / (0.5 * summary.mean_diameter)) ** 2,
                 "-", "> 1: the cloud falls as a plume (Nitsche & Batchelor 1997)"),
    ]

    sigma = m.interfacial_tension
    c = case.coalescence
    form = PROBABILITY_FORMS[c.probability_form]
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
    """Plain-text table of :func:`derived_numbers`, every line a TOML comment (``# ...``).

    ``settler info CASE > my.toml`` prints the resolved case followed by this table, so the table must not break the
    TOML: the output loads as the case again.
    """
    lines = []
    for group, items in groups.items():
        lines.append(f"# {group}:")
        for q in items:
            value = f"{q.value:.4g}" if isinstance(q.value, float) else str(q.value)
            lines.append(f"#   {q.name:<52s} {value:>12s} {q.unit:<7s} {q.note}".rstrip())
    return "\n".join(lines)


def as_records(groups: dict[str, list[Quantity]]) -> list[dict]:
    """Flat list of dicts (group, name, value, unit, note), e.g. for JSON or pandas."""
    return [{"group": g, "name": q.name, "value": float(np.float64(q.value)), "unit": q.unit, "note": q.note}
            for g, items in groups.items() for q in items]


# ------------------------------------------------------------------------------------------------- plausibility
@dataclass(frozen=True)
class PlausibleRange:
    """Range of one quantity that the laws of settler.physics were made for, and why."""

    low: float
    high: float
    unit: str
    reason: str


#: What the laws were made for. The schema (settler.cases.SCHEMA) only refuses values no law can take (signs, zeros);
#: a value outside these ranges is accepted but warned about by :func:`plausibility_warnings`, because the laws and
#: the fitted constants behind them were not made for it. The ranges are deliberately wide: a warning means "far
#: outside", not "unusual".
PLAUSIBLE_RANGES: dict[str, PlausibleRange] = {
    "slag viscosity": PlausibleRange(
        0.01, 10.0, "Pa s",
        "copper-smelting slags measure about 0.05-1 Pa s at 1220-1320 C; the Arrhenius law with E_a of 160-370 "
        "kJ/mol is fitted there"),
    "slag density": PlausibleRange(
        2500.0, 4500.0, "kg/m^3", "molten iron-silicate (fayalite) slags are about 2800-3800 kg/m^3"),
    "matte density": PlausibleRange(
        3500.0, 6000.0, "kg/m^3", "Cu2S-FeS mattes lie between 3973 (FeS) and 5274 kg/m^3 (Cu2S) by Eq. 4"),
    "slag temperature": PlausibleRange(
        1400.0, 1700.0, "K", "flash-smelting settlers run at about 1490-1600 K; the slag viscosity law and the "
        "thermodynamic data are used near there"),
    "oxygen pressure": PlausibleRange(
        1e-9, 101325.0, "Pa", "the grades of data/thermo/README.md's equilibrium need log10(p_O2/atm) of about -8.8 to "
        "-7.9 (1e-4 to 1e-3 Pa) at 1493-1543 K; a partial pressure cannot exceed the settler's total pressure, about "
        "one atmosphere"),
    "SO2 pressure": PlausibleRange(
        1.0, 101325.0, "Pa", "the default 2e4 Pa is an SO2-rich furnace atmosphere (chosen, data/thermo/README.md); a "
        "partial pressure cannot exceed the settler's total pressure, about one atmosphere"),
    "interfacial tension": PlausibleRange(
        0.01, 1.0, "N/m", "measured matte-slag interfacial tensions are about 0.05-0.6 N/m"),
    "mean fed diameter": PlausibleRange(
        1e-6, 50e-3, "m", "the seed paper's droplets are 0.35-0.65 mm; below 1 um Brownian motion, above 50 mm "
        "droplet break-up, neither of which the laws include"),
    "Re_p schiller_naumann": PlausibleRange(
        0.0, 800.0, "-", "the Schiller-Naumann drag correlation is fitted for Re_p < 800"),
    "Re_p stokes": PlausibleRange(
        0.0, 1.0, "-", "Stokes drag holds for creeping flow, Re_p < 1"),
}


def _outside(value: float, r: PlausibleRange) -> bool:
    return not (r.low <= value <= r.high)  # NaN counts as outside


def _range_text(r: PlausibleRange) -> str:
    unit = "" if r.unit == "-" else " " + r.unit
    where = f"above {r.high:g}{unit}, the limit" if r.low <= 0.0 else f"outside {r.low:g} to {r.high:g}{unit}, the range"
    return f"{where} the laws were made for ({r.reason})"


def plausibility_warnings(case: Case) -> list[str]:
    """Warnings, one line each, for values of a validated case far outside what the laws were made for.

    Each names the key(s), the value and the range of :data:`PLAUSIBLE_RANGES`. An empty list: nothing to warn
    about. The case is not refused: a study may leave the ranges on purpose.
    """
    warnings = []
    s, m = case.slag, case.matte
    mu = case.slag_viscosity

    r = PLAUSIBLE_RANGES["slag viscosity"]
    if _outside(mu, r):
        if s.activation_energy == 0.0 or s.temperature == s.reference_temperature:
            how = f"slag.viscosity_reference = {s.viscosity_reference:g} Pa s"
        else:
            how = (f"slag.viscosity_reference = {s.viscosity_reference:g} Pa s at slag.reference_temperature = "
                   f"{s.reference_temperature:g} K with slag.activation_energy = {s.activation_energy:g} J/mol gives "
                   f"{mu:.3g} Pa s at slag.temperature = {s.temperature:g} K")
        warnings.append(f"slag viscosity: {how}: {_range_text(r)}")

    for key, value, name in (("slag.density", s.density, "slag density"),
                             ("matte.density", m.density, "matte density"),
                             ("slag.temperature", s.temperature, "slag temperature"),
                             ("matte.interfacial_tension", m.interfacial_tension, "interfacial tension")):
        r = PLAUSIBLE_RANGES[name]
        if _outside(value, r):
            warnings.append(f"{key} = {value:g} {r.unit}: {_range_text(r)}")

    r_ = case.reaction
    if r_.enabled and r_.end_state == "equilibrium":  # (the pressures are read only there)
        for key, value, name in (("reaction.oxygen_pressure", r_.oxygen_pressure, "oxygen pressure"),
                                 ("reaction.so2_pressure", r_.so2_pressure, "SO2 pressure")):
            r = PLAUSIBLE_RANGES[name]
            if _outside(value, r):
                warnings.append(f"{key} = {value:g} {r.unit}: {_range_text(r)}")

    summary = feed_summary(case)
    r = PLAUSIBLE_RANGES["mean fed diameter"]
    if _outside(summary.mean_diameter, r):
        key = ("the mass-weighted mean of feed.table_diameters" if case.feed.distribution == "table"
               else "feed.mean_diameter")
        warnings.append(f"{key} = {summary.mean_diameter:g} m: {_range_text(r)}")

    # The largest droplet a run can hold: the coalescence size limit, or else the largest fed droplet.
    if case.coalescence.enabled:
        key, d = "coalescence.size_limit", case.coalescence.size_limit
    elif case.feed.distribution == "table":
        key, d = "max(feed.table_diameters)", summary.largest
    else:
        key, d = "feed.mean_diameter x feed.scale_max", summary.largest
    with np.errstate(all="ignore"):
        v = float(settling_velocity(case, d))
        re = float(reynolds_number(d, v, s.density, mu))
    r = PLAUSIBLE_RANGES[f"Re_p {case.drag.law}"]
    if _outside(re, r):
        warnings.append(f"{key} = {d:g} m: the droplet Reynolds number at its terminal velocity ({v:.3g} m/s) is "
                        f"Re_p = {re:.3g} with drag.law = {case.drag.law!r}: {_range_text(r)}")
    return warnings
