"""Tests of settler.thermo and data/thermo/matte_slag.yaml: real thermodynamics, each with a stated tolerance.

(a) the equilibrium grade rises with the oxygen potential;  (b) the driving force vanishes at the equilibrium grade
and has the right sign on either side;  (c) dG° against independent published data for its parts;  (d) the Cantera
multiphase equilibrium against the closed form;  (e) the Cu2S data against the source numbers they were built
from;  (f) bad input raises ValueError naming argument, value and range.
"""

import math

import cantera as ct
import numpy as np
import pytest
from scipy import constants as sc

from settler import thermo
from settler.thermo import (
    DEFAULT_MECHANISM,
    GAS_CONSTANT,
    ONE_ATMOSPHERE,
    STANDARD_PRESSURE,
    equilibrium_end_state,
    equilibrium_grade,
    equilibrium_grade_multiphase,
    fes_removal_driving_force,
    mass_fraction_cu,
    oxygen_pressure_for_grade,
    standard_reaction_gibbs,
    x_cu2s_from_mass_fraction_cu,
)

T_SETTLER = 1543.15  # K, 1270 C
CAL = 4.184  # J/cal (thermochemical calorie)


def _g(species: ct.Species, temperature: float) -> float:
    """g°(T) = h° - T s° [J/mol] of a Cantera species."""
    return (species.thermo.h(temperature) - temperature * species.thermo.s(temperature)) / 1000.0


def _species(name: str, phase: str) -> ct.Species:
    return ct.Solution(str(DEFAULT_MECHANISM), phase).species(name)


# ----------------------------------------------------------------------------------------------------------------
# (a) Monotonic in the oxygen potential; the reaction is exothermic, so the grade falls with temperature.

@pytest.mark.parametrize("temperature", [1493.15, 1543.15, 1593.15])
def test_grade_rises_with_oxygen_potential(temperature):
    p_o2 = ONE_ATMOSPHERE * np.logspace(-10.0, -6.0, 81)
    x = equilibrium_grade(temperature, p_o2)
    steps = np.diff(x)
    assert np.all(steps >= 0.0)  # never decreases (tolerance 0: the closed form is monotone by construction)
    interior = (x[:-1] > 0.0) & (x[1:] < 1.0)
    assert interior.sum() >= 5  # the range actually crosses from X = 0 towards X = 1
    assert np.all(steps[interior] > 0.0)  # strictly rising where 0 < X < 1
    assert x[0] == 0.0 and x[-1] > 0.99


def test_gibbs_helmholtz_and_temperature_trend():
    """d(dG°/T)/d(1/T) = dH° (Gibbs-Helmholtz), with dH° summed from the species enthalpies; dH° < 0 (exothermic),
    so at fixed p_O2 the equilibrium grade falls as the temperature rises (van 't Hoff). Tolerance 1e-6 relative
    on the centred finite difference."""
    t, dt = T_SETTLER, 0.5
    slope = ((standard_reaction_gibbs(t + dt) / (t + dt) - standard_reaction_gibbs(t - dt) / (t - dt))
             / (1.0 / (t + dt) - 1.0 / (t - dt)))
    nu = {("FeS(L)", "matte"): -1.0, ("O2", "gas"): -1.5, ("FeO(L)", "slag"): 1.0, ("SO2", "gas"): 1.0}
    dh = sum(n * _species(name, phase).thermo.h(t) / 1000.0 for (name, phase), n in nu.items())
    assert slope == pytest.approx(dh, rel=1e-6)
    assert dh < -3.0e5  # strongly exothermic (about -450 kJ/mol FeS)
    x = equilibrium_grade([1493.15, 1543.15, 1593.15], 1.0e-8 * ONE_ATMOSPHERE)
    assert np.all(np.diff(x) < 0.0)


# ----------------------------------------------------------------------------------------------------------------
# (b) Driving force: zero at the equilibrium grade, negative below it, positive above it.

@pytest.mark.parametrize("temperature,log10_p_o2_atm", [
    (1493.15, -8.5), (1493.15, -8.0), (1543.15, -8.5), (1543.15, -8.0), (1543.15, -7.5), (1593.15, -8.0),
    (1593.15, -7.5)])
def test_driving_force_vanishes_at_equilibrium_grade(temperature, log10_p_o2_atm):
    p_o2 = 10.0 ** log10_p_o2_atm * ONE_ATMOSPHERE
    x_eq = equilibrium_grade(temperature, p_o2)
    assert 0.0 < x_eq < 1.0  # these states lie inside the two-phase range
    dg0 = abs(standard_reaction_gibbs(temperature))
    assert abs(fes_removal_driving_force(temperature, p_o2, x_eq)) <= 1e-6 * dg0  # zero to 1e-6 relative
    below = fes_removal_driving_force(temperature, p_o2, x_eq * np.array([0.0, 0.5, 0.99]))
    above = fes_removal_driving_force(temperature, p_o2, x_eq + (1.0 - x_eq) * np.array([0.01, 0.5, 0.999]))
    assert np.all(below < 0.0) and np.all(above > 0.0)
    # Ideal mixing: dG(X) - dG(X_eq) = -R T ln((1 - X)/(1 - X_eq)) exactly (tolerance 1e-9 relative).
    x = 0.5 * x_eq
    assert fes_removal_driving_force(temperature, p_o2, x) == pytest.approx(
        -GAS_CONSTANT * temperature * math.log((1.0 - x) / (1.0 - x_eq)), rel=1e-9)


def test_oxygen_pressure_for_grade_inverts_equilibrium_grade():
    x = np.array([0.2, 0.55, 0.8, 0.95])
    p_o2 = oxygen_pressure_for_grade(T_SETTLER, x)
    assert equilibrium_grade(T_SETTLER, p_o2) == pytest.approx(x, abs=1e-12)


# ----------------------------------------------------------------------------------------------------------------
# (c) dG° against independent published values for its parts, at 1500 K.
#
# Independent data used (none of them is the NASA fit in the YAML file):
# * SO2, O2 enthalpies of formation at 298.15 K: CODATA Key Values (Cox, Wagman & Medvedev 1989), as listed by the
#   NIST CCCBDB: dfH(SO2, g) = -296.81 +- 0.20 kJ/mol, S(SO2, 298.15 K) = 248.22 +- 0.05 J/mol/K; S(O2) = 205.152.
# * SO2 and O2 at high temperature from statistical mechanics (rigid rotor, harmonic oscillator) with published
#   molecular constants: SO2 fundamentals 1151, 518, 1362 cm^-1 and rotational constants A, B, C = 2.02736,
#   0.34417, 0.29354 cm^-1, symmetry number 2 (NIST CCCBDB, after Herzberg 1966); O2 omega_e = 1580.19 cm^-1,
#   B_e = 1.4377 cm^-1, ground state 3Sigma_g- (degeneracy 3), symmetry number 2 (Huber & Herzberg 1979). The
#   neglected anharmonicity is worth about 0.5 kJ/mol in g° at 1500 K, hence the 1.5 kJ/mol tolerance per gas.
# * FeO: NIST-JANAF 4th ed. (Chase 1998) via the NIST WebBook Shomate table for solid FeO: dfH(298.15) =
#   -272.04 kJ/mol, H(1500) - H(298.15) = 69.50 kJ/mol, S(1500) = 151.3 J/mol/K; plus the CRC Handbook enthalpy of
#   fusion 24.1 kJ/mol at the melting point 1650 K: g(l) - g(s) = dH_fus (1 - T/T_m) (neglecting dCp: < 0.1 kJ/mol).
# * FeS: CRC Handbook enthalpy of fusion 31.5 kJ/mol (m.p. 1195 C = 1468 K) against h(FeS(L)) - h(FeS(c)) of the
#   NASA data at their 1463 K melting point; FeS(l) itself has no independent high-temperature source here.

def _rrho_h_s(temperature, mass_amu, rotational_cm, sigma, vibrations_cm, degeneracy=1):
    """Ideal-gas H(T) - H(0) [J/mol] and S(T) [J/mol/K] at p° = 1 bar, rigid rotor + harmonic oscillator."""
    k, h, c, n_a = sc.k, sc.h, sc.c * 100.0, sc.N_A
    r = k * n_a
    m = mass_amu * sc.atomic_mass
    s = r * (math.log((2.0 * math.pi * m * k * temperature / h**2) ** 1.5 * k * temperature / STANDARD_PRESSURE)
             + 2.5)
    enthalpy = 2.5 * r * temperature
    thetas = [h * c * b / k for b in rotational_cm]
    if len(thetas) == 1:  # linear
        s += r * (math.log(temperature / (sigma * thetas[0])) + 1.0)
        enthalpy += r * temperature
    else:
        q_rot = math.sqrt(math.pi) / sigma * math.sqrt(temperature**3 / (thetas[0] * thetas[1] * thetas[2]))
        s += r * (math.log(q_rot) + 1.5)
        enthalpy += 1.5 * r * temperature
    for nu in vibrations_cm:
        x = h * c * nu / (k * temperature)
        s += r * (x / math.expm1(x) - math.log1p(-math.exp(-x)))
        enthalpy += r * temperature * x / math.expm1(x)
    return enthalpy, s + r * math.log(degeneracy)


SO2_CONSTANTS = dict(mass_amu=64.064, rotational_cm=(2.02736, 0.34417, 0.29354), sigma=2,
                     vibrations_cm=(1151.0, 518.0, 1362.0))
O2_CONSTANTS = dict(mass_amu=31.9988, rotational_cm=(1.4377,), sigma=2, vibrations_cm=(1580.19,), degeneracy=3)


def _g_rrho(temperature, dfh_298, constants):
    h_t, s_t = _rrho_h_s(temperature, **constants)
    h_298, _ = _rrho_h_s(298.15, **constants)
    return (dfh_298 + h_t - h_298) - temperature * s_t  # J/mol, same element reference as the NASA data


def test_so2_formation_data_match_codata():
    so2 = _species("SO2", "gas")
    assert so2.thermo.h(298.15) / 1e6 == pytest.approx(-296.81, abs=0.20)  # kJ/mol, CODATA +- 0.20
    assert so2.thermo.s(298.15) / 1e3 == pytest.approx(248.22, abs=0.05)  # J/mol/K, CODATA +- 0.05 (1 bar)
    assert _species("O2", "gas").thermo.s(298.15) / 1e3 == pytest.approx(205.152, abs=0.05)
    # the statistical-mechanics model itself reproduces the CODATA entropies at 298.15 K (0.05 J/mol/K)
    assert _rrho_h_s(298.15, **SO2_CONSTANTS)[1] == pytest.approx(248.22, abs=0.05)
    assert _rrho_h_s(298.15, **O2_CONSTANTS)[1] == pytest.approx(205.152, abs=0.05)


def test_standard_reaction_gibbs_against_independent_parts():
    t = 1500.0
    g_so2 = _g_rrho(t, -296.81e3, SO2_CONSTANTS)
    g_o2 = _g_rrho(t, 0.0, O2_CONSTANTS)
    g_feo_s = (-272.04e3 + 69.50e3) - t * 151.3  # NIST-JANAF (Chase 1998), WebBook table
    g_feo_l = g_feo_s + 24.1e3 * (1.0 - t / 1650.0)  # CRC enthalpy of fusion, m.p. 1650 K
    assert _g(_species("SO2", "gas"), t) == pytest.approx(g_so2, abs=1.5e3)
    assert _g(_species("O2", "gas"), t) == pytest.approx(g_o2, abs=1.5e3)
    assert _g(_species("FeO(L)", "slag"), t) == pytest.approx(g_feo_l, abs=1.0e3)
    # FeS: the NASA liquid and crystal data melt with the CRC enthalpy of fusion (31.5 kJ/mol, tolerance 1 kJ/mol),
    # and their Gibbs energies cross at the 1463 K melting point (0.1 kJ/mol).
    fes_c = {s.name: s for s in ct.Species.list_from_file("nasa_condensed.yaml")}["FeS(c)"]
    fes_l = _species("FeS(L)", "matte")
    assert (fes_l.thermo.h(1463.0) - fes_c.thermo.h(1463.0)) / 1e6 == pytest.approx(31.5, abs=1.0)
    assert _g(fes_l, 1463.0) == pytest.approx(_g(fes_c, 1463.0), abs=100.0)
    # Assembled reaction: only FeS(l) comes from the same data; tolerance = sum of the part tolerances, 4.75 kJ/mol
    # (about 1.4 % of dG°).
    independent = g_feo_l + g_so2 - 1.5 * g_o2 - _g(fes_l, t)
    assert standard_reaction_gibbs(t) == pytest.approx(independent, abs=4.75e3)
    assert -4.0e5 < standard_reaction_gibbs(t) < -3.0e5  # J/mol: FeS oxidation strongly favoured


# ----------------------------------------------------------------------------------------------------------------
# (d) Cantera multiphase equilibrium against the closed form.

@pytest.mark.parametrize("temperature,log10_p_o2_atm", [(1493.15, -8.5), (1543.15, -8.0), (1593.15, -7.5)])
def test_multiphase_equilibrium_matches_closed_form(temperature, log10_p_o2_atm):
    p_o2 = 10.0 ** log10_p_o2_atm * ONE_ATMOSPHERE
    x_mp, state = equilibrium_grade_multiphase(temperature, p_o2, return_state=True)
    assert 0.0 < x_mp < 1.0
    # With the equilibrium state's own p_O2, p_SO2 and a_FeO the closed form is exact (solver tolerance, 1e-6).
    assert equilibrium_grade(temperature, state["p_o2"], state["p_so2"], state["a_feo"]) == pytest.approx(
        x_mp, abs=1e-6)
    # Large reservoirs (1e6 mol gas, 1e3 mol slag per mol matte) keep the nominal state: |dX| < 2e-3.
    assert state["p_o2"] == pytest.approx(p_o2, rel=2e-3)
    assert equilibrium_grade(temperature, p_o2) == pytest.approx(x_mp, abs=2e-3)


def test_multiphase_equilibrium_with_magnetite():
    """With Fe3O4 allowed in the slag, magnetite forms and lowers a_FeO; the closed form still reproduces the
    equilibrium at the equilibrium state's a_FeO (1e-6), and the lower a_FeO gives a higher grade."""
    p_o2 = 1.0e-8 * ONE_ATMOSPHERE
    x_mp, state = equilibrium_grade_multiphase(T_SETTLER, p_o2, magnetite=True, return_state=True)
    assert state["x_fe3o4"] > 1e-3 and state["a_feo"] < thermo.DEFAULT_A_FEO
    assert equilibrium_grade(T_SETTLER, state["p_o2"], state["p_so2"], state["a_feo"]) == pytest.approx(
        x_mp, abs=1e-6)
    assert x_mp > equilibrium_grade(T_SETTLER, p_o2)


def test_multiphase_result_does_not_depend_on_initial_matte():
    p_o2 = 1.0e-8 * ONE_ATMOSPHERE
    x = [equilibrium_grade_multiphase(T_SETTLER, p_o2, x_initial=x0) for x0 in (0.3, 0.6, 0.95)]
    assert np.ptp(x) < 2e-3  # differences only through the (finite) reservoirs


# ----------------------------------------------------------------------------------------------------------------
# (e) Cu2S data reproduce the source numbers they were built from.

CU2S_SOURCE = dict(
    dfh_298=-79.5e3, s_298=120.9, cp_298=76.3,  # CRC Handbook, Standard Thermodynamic Properties
    cp_alpha=(9.38, 0.0312), t_alpha=376.0,  # Perry's Table 2-151, cal/mol/K, 273-376 K
    h_trans_376=0.865e3 * CAL, h_trans_720=0.280e3 * CAL,  # US Bureau of Mines RI 8305 (1978)
    cp_beta=20.9 * CAL,  # Perry's Table 2-151, 376-1173 K
    t_melt=1400.0, h_fusion=3.070e3 * CAL,  # RI 8305
)


def _cu2s_from_sources(temperature):
    """(h, s) [J/mol, J/mol/K] of Cu2S at 720 K (solid, after the transition) or at 1400 K (liquid)."""
    src = CU2S_SOURCE
    a, b = src["cp_alpha"]
    t0, ta, tb, tm = 298.15, src["t_alpha"], 720.0, src["t_melt"]
    h = src["dfh_298"] + CAL * (a * (ta - t0) + 0.5 * b * (ta**2 - t0**2)) + src["h_trans_376"]
    s = src["s_298"] + CAL * (a * math.log(ta / t0) + b * (ta - t0)) + src["h_trans_376"] / ta
    h += src["cp_beta"] * (tb - ta) + src["h_trans_720"]
    s += src["cp_beta"] * math.log(tb / ta) + src["h_trans_720"] / tb
    if temperature == tb:
        return h, s
    h += src["cp_beta"] * (tm - tb) + src["h_fusion"]
    s += src["cp_beta"] * math.log(tm / tb) + src["h_fusion"] / tm
    return h, s


def test_cu2s_data_reproduce_sources():
    liquid = _species("Cu2S(L)", "matte")
    solid = _species("Cu2S(cr)", "cu2s-solid")
    for species, temperature in ((solid, 720.0), (liquid, 1400.0)):
        h, s = _cu2s_from_sources(temperature)
        assert species.thermo.h(temperature) / 1000.0 == pytest.approx(h, abs=1.0)  # J/mol
        assert species.thermo.s(temperature) / 1000.0 == pytest.approx(s, abs=1e-3)  # J/mol/K
    # Perry's beta-Cu2S heat capacity, 20.9 cal/mol/K (exact, it is copied)
    assert solid.thermo.cp(1000.0) / 1000.0 == pytest.approx(20.9 * CAL, rel=1e-12)
    # RI 8305: melting at 1400 K with 3.070 kcal/mol; solid and liquid Gibbs energies equal there (1 J/mol)
    assert (liquid.thermo.h(1400.0) - solid.thermo.h(1400.0)) / 1000.0 == pytest.approx(3.070e3 * CAL, abs=1.0)
    assert _g(liquid, 1400.0) == pytest.approx(_g(solid, 1400.0), abs=1.0)
    # the alpha-Cu2S fit of Perry (3 % stated error) agrees with the CRC Cp(298.15) = 76.3 J/mol/K within 3 %
    a, b = CU2S_SOURCE["cp_alpha"]
    assert CAL * (a + b * 298.15) == pytest.approx(CU2S_SOURCE["cp_298"], rel=0.03)


def test_matte_grade_conversions():
    m_cu, m_cu2s = 63.546, 159.152  # g/mol (IUPAC atomic weights as used by Cantera)
    assert mass_fraction_cu(1.0) == pytest.approx(2 * m_cu / m_cu2s, rel=1e-4)  # pure Cu2S: 79.86 wt % Cu
    assert mass_fraction_cu(0.0) == 0.0
    w = np.array([0.55, 0.70])  # the seed paper's matte grades, 55-70 wt % Cu
    x = x_cu2s_from_mass_fraction_cu(w)
    assert mass_fraction_cu(x) == pytest.approx(w, rel=1e-12)
    assert 0.5 < x[0] < x[1] < 0.85


def test_equilibrium_end_state_uses_atm_oxygen_potential():
    x = equilibrium_end_state(T_SETTLER, -8.0)
    assert x == pytest.approx(equilibrium_grade(T_SETTLER, 1e-8 * 101325.0), rel=1e-12)
    assert 0.0 < equilibrium_end_state() <= 1.0


# ----------------------------------------------------------------------------------------------------------------
# (f) Bad input raises ValueError naming the argument, its value and the allowed range.

@pytest.mark.parametrize("call,pattern", [
    (lambda: standard_reaction_gibbs(-10.0), r"temperature = -10\.0 K .*> 0 K"),
    (lambda: standard_reaction_gibbs(0.0), r"temperature = 0\.0 K"),
    (lambda: standard_reaction_gibbs(300.0), r"temperature = 300\.0 K is outside the allowed range \[1200, 2000\] K"),
    (lambda: equilibrium_grade(T_SETTLER, -1.0), r"p_o2 = -1\.0 Pa is outside the allowed range \(0, inf\) Pa"),
    (lambda: equilibrium_grade(T_SETTLER, 1e-3, p_so2=0.0), r"p_so2 = 0\.0 Pa .*\(0, inf\)"),
    (lambda: equilibrium_grade(T_SETTLER, 1e-3, a_feo=1.5), r"a_feo = 1\.5 is outside the allowed range \(0, 1\]"),
    (lambda: fes_removal_driving_force(T_SETTLER, 1e-3, 1.2), r"x_cu2s = 1\.2 is outside the allowed range \[0, 1\]"),
    (lambda: fes_removal_driving_force(T_SETTLER, 1e-3, [0.5, -0.1]), r"x_cu2s = -0\.1"),
    (lambda: mass_fraction_cu(-0.5), r"x_cu2s = -0\.5"),
    (lambda: x_cu2s_from_mass_fraction_cu(0.9), r"w_cu = 0\.9 is outside the allowed range \[0, 0\.79"),
    (lambda: equilibrium_end_state(T_SETTLER, float("nan")), r"log10_p_o2_atm"),
    (lambda: equilibrium_grade_multiphase(T_SETTLER, 1e-3, gas_moles=0.0), r"gas_moles = 0\.0 mol"),
    (lambda: equilibrium_grade_multiphase(T_SETTLER, 2e5), r"total_pressure"),
])
def test_bad_input_raises_clear_message(call, pattern):
    with pytest.raises(ValueError, match=pattern):
        call()
