"""Thermochemistry of FeS removal from settling matte droplets, with Cantera.

The reaction that turns a settling droplet richer in copper is the oxidation of its iron sulfide,

    FeS(l, matte) + 3/2 O2(g) = FeO(l, slag) + SO2(g),

with Cu2S left in the matte. Its reaction Gibbs energy is

    dG = dG°(T) + R T ln[ a_FeO (p_SO2/p°) / (a_FeS (p_O2/p°)^1.5) ],

and the matte stops losing FeS where dG = 0. Matte and slag are ideal solutions here (a_FeS = 1 - X, a_FeO given),
so the equilibrium Cu2S mole fraction X of a Cu2S-FeS matte has the closed form

    X = 1 - a_FeO (p_SO2/p°) / (K (p_O2/p°)^1.5),   K = exp(-dG° / (R T)),

clipped to [0, 1]. dG° comes from the species data in ``data/thermo/matte_slag.yaml`` (sources in that file and in
``data/thermo/README.md``); :func:`equilibrium_grade_multiphase` repeats the calculation as a genuine Cantera
multiphase equilibrium of gas, matte and slag.

What is quantitative and what is not: the pure-species standard data (dG°, K) are tabulated measurements; ideal
mixing of Cu2S-FeS and FeO-SiO2 is qualitative only, because both melts are strongly non-ideal. X from this module
shows trends (higher oxygen potential, higher grade; the temperature dependence) rather than plant matte grades.

Units are SI throughout: temperature in K, pressures in Pa, Gibbs energies in J/mol, mole and mass fractions
dimensionless. The standard pressure p° is 1 bar (1e5 Pa), the standard state of the NASA/JANAF data used.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import cantera as ct
import numpy as np

from .paths import DATA_DIR

__all__ = [
    "DEFAULT_MECHANISM",
    "STANDARD_PRESSURE",
    "ONE_ATMOSPHERE",
    "GAS_CONSTANT",
    "TEMPERATURE_RANGE",
    "DEFAULT_TEMPERATURE",
    "DEFAULT_P_SO2",
    "DEFAULT_A_FEO",
    "DEFAULT_LOG10_P_O2_ATM",
    "standard_reaction_gibbs",
    "equilibrium_constant",
    "fes_removal_driving_force",
    "equilibrium_grade",
    "oxygen_pressure_for_grade",
    "equilibrium_grade_multiphase",
    "equilibrium_end_state",
    "mass_fraction_cu",
    "x_cu2s_from_mass_fraction_cu",
]

DEFAULT_MECHANISM = DATA_DIR / "thermo" / "matte_slag.yaml"
"""Cantera input file with the phases ``gas``, ``matte``, ``slag``, ``slag-FeO-SiO2`` and ``cu2s-solid`` (in the data
folder of :mod:`settler.paths`: SETTLER_DATA, the checkout's data/ or the installed copy)."""

STANDARD_PRESSURE = 1.0e5
"""Standard pressure p° [Pa]: 1 bar, the standard state of the NASA (McBride et al. 1993) and JANAF data."""

ONE_ATMOSPHERE = ct.one_atm
"""101325 Pa, for oxygen potentials quoted as log10(p_O2 / atm)."""

GAS_CONSTANT = ct.gas_constant / 1000.0
"""Molar gas constant R [J/(mol K)]."""

TEMPERATURE_RANGE = (1200.0, 2000.0)
"""Temperatures [K] the species data of DEFAULT_MECHANISM are declared for (liquids extrapolated below their
melting points as supercooled liquids; see data/thermo/README.md)."""

DEFAULT_TEMPERATURE = 1543.15
"""Settler temperature [K]: 1270 C, the middle of the seed paper's 1220-1320 C [chosen]."""

DEFAULT_P_SO2 = 2.0e4
"""SO2 partial pressure [Pa] over the settler, 0.2 bar [chosen]: an SO2-rich furnace atmosphere, the same value as
``reaction.so2_pressure`` in data/properties/flash_smelting.toml; not a measured settler value."""

DEFAULT_A_FEO = 0.4
"""FeO activity in the slag [-] [chosen]: flash-smelting slags carry 40-45 wt % Fe as iron oxides, activity of order
0.3-0.5; the same value as ``reaction.feo_activity`` in data/properties/flash_smelting.toml."""

DEFAULT_LOG10_P_O2_ATM = -7.5
"""Oxygen potential log10(p_O2 / atm) [-]: about -7.5 (bar) at 1250 C for copper matte smelting with FeOx-SiO2
slags, after the abstract of "Oxidation potentials in matte smelting of copper and nickel" (JOM; authors and year not
verified in this session). The 0.006 difference between bar and atm is below the precision of that value."""

_REACTION = {"FeS(L)": ("matte", -1.0), "O2": ("gas", -1.5), "FeO(L)": ("slag", 1.0), "SO2": ("gas", 1.0)}


def _check_range(name, value, low, high, unit, *, low_open=False, high_open=False):
    """Return value as a float array; raise ValueError naming the argument, the bad value and the allowed range."""
    v = np.asarray(value, dtype=float)
    bad = ~np.isfinite(v) | ((v <= low) if low_open else (v < low)) | ((v >= high) if high_open else (v > high))
    if np.any(bad):
        first = float(v[bad].flat[0]) if v.ndim else float(v)
        interval = f"{'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
        units = f" {unit}" if unit else ""
        raise ValueError(f"{name} = {first!r}{units} is outside the allowed range {interval}{units}")
    return v


def _check_temperature(temperature, mechanism=DEFAULT_MECHANISM):
    low, high = TEMPERATURE_RANGE
    v = np.asarray(temperature, dtype=float)
    if np.any(v <= 0.0):
        first = v[v <= 0.0].flat[0] if v.ndim else float(v)
        raise ValueError(f"temperature = {first!r} K is not a temperature: it must be > 0 K, and within "
                         f"[{low:g}, {high:g}] K for the data in {Path(mechanism).name}")
    return _check_range("temperature", v, low, high, "K")


def _check_pressure(name, value):
    return _check_range(name, value, 0.0, np.inf, "Pa", low_open=True, high_open=True)


@lru_cache(maxsize=8)
def _species(mechanism: str):
    """{name: ct.Species} of the reaction species, read once per mechanism file."""
    out = {}
    for name, (phase, _) in _REACTION.items():
        out[name] = ct.Solution(mechanism, phase).species(name)
    return out


@lru_cache(maxsize=8)
def _molar_masses(mechanism: str):
    """Molar masses [kg/mol] of Cu, Cu2S and FeS from the mechanism's element and species data."""
    matte = ct.Solution(mechanism, "matte")
    w = dict(zip(matte.species_names, matte.molecular_weights / 1000.0))
    return matte.atomic_weight("Cu") / 1000.0, w["Cu2S(L)"], w["FeS(L)"]


def _standard_gibbs(species: ct.Species, temperature: float) -> float:
    """Standard-state molar Gibbs energy g°(T) = h°(T) - T s°(T) [J/mol] of one Cantera species."""
    thermo = species.thermo
    return (thermo.h(temperature) - temperature * thermo.s(temperature)) / 1000.0


def _scalar_or_array(x):
    x = np.asarray(x, dtype=float)
    return float(x) if x.ndim == 0 else x


def standard_reaction_gibbs(temperature, *, mechanism=DEFAULT_MECHANISM):
    """Standard reaction Gibbs energy dG°(T) [J/mol] of FeS(l) + 3/2 O2(g) = FeO(l) + SO2(g).

    Computed from the standard-state chemical potentials g°_k(T) = h°_k(T) - T s°_k(T) of the Cantera species
    FeS(L), O2, FeO(L) and SO2 in ``mechanism`` (pure liquids and ideal gases at p° = 1 bar), per mole of FeS.

    Parameters
    ----------
    temperature : float or array_like
        Temperature [K], within TEMPERATURE_RANGE.
    """
    t = _check_temperature(temperature, mechanism)
    species = _species(str(mechanism))

    def one(tk):
        return sum(nu * _standard_gibbs(species[name], tk) for name, (_, nu) in _REACTION.items())

    return _scalar_or_array(np.vectorize(one, otypes=[float])(t))


def equilibrium_constant(temperature, *, mechanism=DEFAULT_MECHANISM):
    """K(T) = exp(-dG°/(R T)) [-] of FeS(l) + 3/2 O2 = FeO(l) + SO2, pressures in units of p° = 1 bar."""
    t = _check_temperature(temperature, mechanism)
    return _scalar_or_array(np.exp(-np.asarray(standard_reaction_gibbs(t, mechanism=mechanism)) / (GAS_CONSTANT * t)))


def fes_removal_driving_force(temperature, p_o2, x_cu2s, p_so2=DEFAULT_P_SO2, a_feo=DEFAULT_A_FEO, *,
                              mechanism=DEFAULT_MECHANISM):
    """Reaction Gibbs energy dG [J/mol FeS] of FeS(l) + 3/2 O2 = FeO(l) + SO2 at the given state.

    dG = dG°(T) + R T ln[ a_FeO (p_SO2/p°) / (a_FeS (p_O2/p°)^1.5) ], with a_FeS = 1 - x_cu2s (ideal Cu2S-FeS matte)
    and p° = 1 bar. Negative: FeS is removed from the matte (the droplet gets richer in Cu2S); zero: equilibrium;
    positive: the reverse would run. At x_cu2s = 1 (no FeS left) the value is +inf.

    Parameters (numpy-broadcastable)
    ----------
    temperature : Temperature [K].
    p_o2 : Oxygen partial pressure [Pa], > 0.
    x_cu2s : Cu2S mole fraction of the Cu2S-FeS matte [-], in [0, 1].
    p_so2 : SO2 partial pressure [Pa], > 0.
    a_feo : FeO activity in the slag [-], in (0, 1].
    """
    t = _check_temperature(temperature, mechanism)
    po2 = _check_pressure("p_o2", p_o2)
    pso2 = _check_pressure("p_so2", p_so2)
    x = _check_range("x_cu2s", x_cu2s, 0.0, 1.0, "")
    afeo = _check_range("a_feo", a_feo, 0.0, 1.0, "", low_open=True)
    dg0 = np.asarray(standard_reaction_gibbs(t, mechanism=mechanism))
    a_fes = 1.0 - x
    with np.errstate(divide="ignore"):
        log_q = (np.log(afeo) + np.log(pso2 / STANDARD_PRESSURE) - np.log(a_fes)
                 - 1.5 * np.log(po2 / STANDARD_PRESSURE))
    return _scalar_or_array(dg0 + GAS_CONSTANT * t * log_q)


def equilibrium_grade(temperature, p_o2, p_so2=DEFAULT_P_SO2, a_feo=DEFAULT_A_FEO, *, mechanism=DEFAULT_MECHANISM):
    """Equilibrium Cu2S mole fraction X of a Cu2S-FeS matte under the given gas and slag [-].

    X = 1 - a_FeO (p_SO2/p°) / (K (p_O2/p°)^1.5), clipped to [0, 1]; ideal matte, K from
    :func:`equilibrium_constant`.
    X = 1 means the matte would lose all its FeS; X = 0 means even pure FeS matte is stable against oxidation.
    Rises with the oxygen potential; qualitative only (ideal mixing; see the module docstring).

    Parameters (numpy-broadcastable): temperature [K]; p_o2, p_so2 [Pa], > 0; a_feo [-] in (0, 1].
    """
    t = _check_temperature(temperature, mechanism)
    po2 = _check_pressure("p_o2", p_o2)
    pso2 = _check_pressure("p_so2", p_so2)
    afeo = _check_range("a_feo", a_feo, 0.0, 1.0, "", low_open=True)
    k = np.asarray(equilibrium_constant(t, mechanism=mechanism))
    a_fes = afeo * (pso2 / STANDARD_PRESSURE) / (k * (po2 / STANDARD_PRESSURE) ** 1.5)
    return _scalar_or_array(np.clip(1.0 - a_fes, 0.0, 1.0))


def oxygen_pressure_for_grade(temperature, x_cu2s, p_so2=DEFAULT_P_SO2, a_feo=DEFAULT_A_FEO, *,
                              mechanism=DEFAULT_MECHANISM):
    """Oxygen partial pressure [Pa] at which a matte of Cu2S mole fraction x_cu2s is in equilibrium (ideal mixing).

    The inverse of :func:`equilibrium_grade` for 0 <= x_cu2s < 1: p_O2 = p° [a_FeO (p_SO2/p°) / (K (1 - X))]^(2/3).
    """
    t = _check_temperature(temperature, mechanism)
    x = _check_range("x_cu2s", x_cu2s, 0.0, 1.0, "", high_open=True)
    pso2 = _check_pressure("p_so2", p_so2)
    afeo = _check_range("a_feo", a_feo, 0.0, 1.0, "", low_open=True)
    k = np.asarray(equilibrium_constant(t, mechanism=mechanism))
    return _scalar_or_array(STANDARD_PRESSURE * (afeo * (pso2 / STANDARD_PRESSURE) / (k * (1.0 - x))) ** (2.0 / 3.0))


def equilibrium_grade_multiphase(temperature, p_o2, p_so2=DEFAULT_P_SO2, a_feo=DEFAULT_A_FEO, *, x_initial=0.5,
                                 gas_moles=1.0e6, slag_moles=1.0e3, magnetite=False, total_pressure=ONE_ATMOSPHERE,
                                 mechanism=DEFAULT_MECHANISM, return_state=False):
    """Equilibrium Cu2S mole fraction X [-] from a Cantera multiphase equilibrium of gas, matte and slag.

    One mole of matte (Cu2S mole fraction ``x_initial``) is equilibrated at fixed T and P (``ct.Mixture``,
    'TP') with ``gas_moles`` of gas and ``slag_moles`` of slag. The gas holds O2 and SO2 at the requested partial
    pressures, N2 as balance and the S2 that makes 1/2 S2 + O2 = SO2 equilibrated: the large S2/SO2 reservoir then
    buffers p_O2 while FeS is oxidised. The slag starts as FeO-SiO2 with X_FeO = a_feo (ideal, so a_FeO = X_FeO).
    With large reservoirs the result approaches :func:`equilibrium_grade`; with the equilibrium state's own p_O2,
    p_SO2 and a_FeO (``return_state=True``) the closed form reproduces it exactly.

    Parameters
    ----------
    temperature : float, K.     p_o2, p_so2 : float, Pa (> 0).     a_feo : float in (0, 1), initial X_FeO of the slag.
    x_initial : initial Cu2S mole fraction of the matte, in (0, 1].
    gas_moles, slag_moles : amounts [mol] per mole of matte (> 0).
    magnetite : use the 'slag' phase (FeO, SiO2, Fe3O4) instead of 'slag-FeO-SiO2'; Fe3O4 then forms and lowers
        a_FeO below its initial value.
    total_pressure : Pa, must exceed the sum of the O2, SO2 and S2 partial pressures.
    return_state : also return a dict with the equilibrium p_o2 [Pa], p_so2 [Pa], p_s2 [Pa], a_feo [-],
        x_fe3o4 [-] and the phase amounts [mol].

    Returns
    -------
    X, or (X, state) when return_state is true.
    """
    t = float(_check_temperature(temperature, mechanism))
    po2 = float(_check_pressure("p_o2", p_o2))
    pso2 = float(_check_pressure("p_so2", p_so2))
    afeo = float(_check_range("a_feo", a_feo, 0.0, 1.0, "", low_open=True, high_open=True))
    x0 = float(_check_range("x_initial", x_initial, 0.0, 1.0, "", low_open=True))
    n_gas = float(_check_range("gas_moles", gas_moles, 0.0, np.inf, "mol", low_open=True, high_open=True))
    n_slag = float(_check_range("slag_moles", slag_moles, 0.0, np.inf, "mol", low_open=True, high_open=True))
    p_tot = float(_check_pressure("total_pressure", total_pressure))

    mechanism = str(mechanism)
    gas = ct.Solution(mechanism, "gas")
    matte = ct.Solution(mechanism, "matte")
    slag = ct.Solution(mechanism, "slag" if magnetite else "slag-FeO-SiO2")

    # S2 partial pressure in equilibrium with the requested O2 and SO2: 1/2 S2 + O2 = SO2.
    g = {name: _standard_gibbs(gas.species(name), t) for name in ("O2", "SO2", "S2")}
    k_so2 = np.exp(-(g["SO2"] - 0.5 * g["S2"] - g["O2"]) / (GAS_CONSTANT * t))
    ps2 = STANDARD_PRESSURE * ((pso2 / STANDARD_PRESSURE) / (k_so2 * po2 / STANDARD_PRESSURE)) ** 2
    if po2 + pso2 + ps2 >= p_tot:
        raise ValueError(f"total_pressure = {p_tot!r} Pa must exceed p_O2 + p_SO2 + p_S2 = {po2 + pso2 + ps2!r} Pa")

    gas.TPX = t, p_tot, {"O2": po2 / p_tot, "SO2": pso2 / p_tot, "S2": ps2 / p_tot,
                         "N2": 1.0 - (po2 + pso2 + ps2) / p_tot}
    matte.TPX = t, p_tot, {"Cu2S(L)": x0, "FeS(L)": 1.0 - x0}
    slag.TPX = t, p_tot, {"FeO(L)": afeo, "SiO2(L)": 1.0 - afeo}
    mix = ct.Mixture([(gas, n_gas), (matte, 1.0), (slag, n_slag)])
    mix.T = t
    mix.P = p_tot
    mix.equilibrate("TP", max_steps=10000)

    x_eq = float(matte["Cu2S(L)"].X[0])
    if not return_state:
        return x_eq
    names = slag.species_names
    state = {
        "p_o2": float(gas["O2"].X[0] * p_tot),
        "p_so2": float(gas["SO2"].X[0] * p_tot),
        "p_s2": float(gas["S2"].X[0] * p_tot),
        "a_feo": float(slag["FeO(L)"].X[0]),
        "x_fe3o4": float(slag["Fe3O4(s)"].X[0]) if "Fe3O4(s)" in names else 0.0,
        "phase_moles": {"gas": float(mix.phase_moles(0)), "matte": float(mix.phase_moles(1)),
                        "slag": float(mix.phase_moles(2))},
    }
    return x_eq, state


def equilibrium_end_state(temperature=DEFAULT_TEMPERATURE, log10_p_o2_atm=DEFAULT_LOG10_P_O2_ATM,
                          p_so2=DEFAULT_P_SO2, a_feo=DEFAULT_A_FEO, *, mechanism=DEFAULT_MECHANISM):
    """End state X_inf [-] of the reaction fit X(age) = X_inf - (X_inf - X0) exp(-age/tau).

    The equilibrium Cu2S mole fraction of :func:`equilibrium_grade` at an oxygen potential given, as metallurgists
    quote it, as log10(p_O2 / atm); temperature [K], p_so2 [Pa], a_feo [-].
    """
    lg = np.asarray(log10_p_o2_atm, dtype=float)
    if not np.all(np.isfinite(lg)):
        raise ValueError(f"log10_p_o2_atm = {log10_p_o2_atm!r} must be finite")
    return equilibrium_grade(temperature, 10.0 ** lg * ONE_ATMOSPHERE, p_so2, a_feo, mechanism=mechanism)


def mass_fraction_cu(x_cu2s, *, mechanism=DEFAULT_MECHANISM):
    """Copper mass fraction [-] of a Cu2S-FeS matte of Cu2S mole fraction x_cu2s; x 100 gives the grade, wt % Cu.

    w_Cu = 2 M_Cu X / (X M_Cu2S + (1 - X) M_FeS); e.g. the seed paper's 55-70 wt % Cu mattes are X = 0.55-0.80.
    """
    x = _check_range("x_cu2s", x_cu2s, 0.0, 1.0, "")
    m_cu, m_cu2s, m_fes = _molar_masses(str(mechanism))
    return _scalar_or_array(2.0 * m_cu * x / (x * m_cu2s + (1.0 - x) * m_fes))


def x_cu2s_from_mass_fraction_cu(w_cu, *, mechanism=DEFAULT_MECHANISM):
    """Cu2S mole fraction [-] of a Cu2S-FeS matte with copper mass fraction w_cu [-] (inverse of mass_fraction_cu).

    w_cu must lie in [0, 2 M_Cu / M_Cu2S] (0 to 0.7986, pure Cu2S).
    """
    m_cu, m_cu2s, m_fes = _molar_masses(str(mechanism))
    w = _check_range("w_cu", w_cu, 0.0, 2.0 * m_cu / m_cu2s, "")
    return _scalar_or_array(w * m_fes / (2.0 * m_cu - w * (m_cu2s - m_fes)))
