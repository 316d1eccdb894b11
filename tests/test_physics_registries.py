"""Every entry of every registry of settler.physics against its own definition: drag laws (force balance of the
terminal velocity, Stokes limit), hindrance corrections (1 in a clear fluid), coalescence-probability forms (P_c in
[0, 1], falling with the Weber number), coalescence rules (step and probability), and the case schema's choices.

Each test reads its references from a table keyed by entry name and first checks that the table covers the registry,
so a new entry fails here until it is given a reference."""

import math

import numpy as np
import pytest

from settler import physics as p
from settler.cases import SCHEMA, load_case
from settler.derived import settling_velocity
from settler.physics.registry import Entry, Registry


G = p.STANDARD_GRAVITY
RHO_D, RHO_S, MU, SIGMA = 5100.0, 3150.0, 0.45, 0.1  # matte, slag [kg/m^3], slag viscosity [Pa s], sigma [N/m]

REGISTRIES = {"DRAG_LAWS": p.DRAG_LAWS, "HINDRANCE": p.HINDRANCE, "PROBABILITY_FORMS": p.PROBABILITY_FORMS,
              "COALESCENCE_RULES": p.COALESCENCE_RULES}
ALL_ENTRIES = [(name, e) for name, registry in REGISTRIES.items() for e in registry.entries]

#: Drag correction f = C_D Re / 24 of each law, written out independently.
DRAG_FACTOR = {
    "stokes": lambda re: 1.0,
    "schiller_naumann": lambda re: 1.0 + 0.15 * re**0.687 if re <= 1000.0 else 0.44 * re / 24.0,
}
#: Factor on beta of model A of each hindrance correction (void fraction eps, Reynolds number re).
HINDRANCE_FACTOR = {
    "di_felice": lambda eps, re: eps ** (1.0 - (3.7 - 0.65 * math.exp(-0.5 * (1.5 - math.log10(re)) ** 2))),
    "none": lambda eps, re: 1.0,
}
#: Merged fraction of collisions of each coalescence rule, given P_c and the threshold.
RULE_FRACTION = {
    "step": lambda pc, threshold: 1.0 if pc >= threshold else 0.0,
    "probability": lambda pc, threshold: pc,
}
#: Schema key whose allowed values each registry gives.
SCHEMA_KEY = {"DRAG_LAWS": ("drag", "law"), "HINDRANCE": ("fulldem", "hindrance"),
              "PROBABILITY_FORMS": ("coalescence", "probability_form"),
              "COALESCENCE_RULES": ("popbal", "coalescence_rule")}


@pytest.mark.parametrize("table, registry", [(DRAG_FACTOR, p.DRAG_LAWS), (HINDRANCE_FACTOR, p.HINDRANCE),
                                             (RULE_FRACTION, p.COALESCENCE_RULES)])
def test_reference_tables_cover_their_registry(table, registry):
    assert tuple(table) == registry.names()


@pytest.mark.parametrize("registry_name, entry", ALL_ENTRIES, ids=[f"{r}-{e.name}" for r, e in ALL_ENTRIES])
def test_entry_has_description_citation_and_its_code(registry_name, entry):
    registry = REGISTRIES[registry_name]
    assert entry.description.strip() and entry.citation.strip()
    assert "\n" not in entry.description  # one line
    assert registry[entry.name] == entry.code and type(entry.code) is int
    assert registry.entry(entry.name) is entry and registry.name_of(entry.code) == entry.name


@pytest.mark.parametrize("registry_name", list(REGISTRIES))
def test_registry_is_frozen_ordered_and_names_its_choices(registry_name):
    registry = REGISTRIES[registry_name]
    assert tuple(registry) == registry.names() == tuple(e.name for e in registry.entries)
    assert len({e.code for e in registry.entries}) == len(registry)
    with pytest.raises(TypeError):
        registry["new"] = 7
    with pytest.raises(AttributeError):
        registry.kind = "other"
    with pytest.raises(KeyError, match="not one of " + ", ".join(repr(n) for n in registry.names())):
        registry["no such model"]
    assert "no such model" not in registry


def test_registry_refuses_duplicates_and_missing_citations():
    with pytest.raises(ValueError):
        Registry("x", Entry("a", 0, "one", "Someone 2000"), Entry("a", 1, "two", "Someone 2000"))
    with pytest.raises(ValueError):
        Registry("x", Entry("a", 0, "one", "Someone 2000"), Entry("b", 0, "two", "Someone 2000"))
    with pytest.raises(ValueError):
        Registry("x", Entry("a", 0, "one", " "))


@pytest.mark.parametrize("registry_name", list(REGISTRIES))
def test_schema_choices_are_the_registry_names(registry_name):
    section, key = SCHEMA_KEY[registry_name]
    assert SCHEMA[section][key].choices == REGISTRIES[registry_name].names()


# ------------------------------------------------------------------------------------------------------- drag laws
@pytest.mark.parametrize("law", p.DRAG_LAWS.names())
@pytest.mark.parametrize("reynolds", [1e-6, 0.3, 5.0, 200.0, 999.0, 2000.0])
def test_drag_factor_matches_its_law(law, reynolds):
    assert p.drag_factor(reynolds, p.DRAG_LAWS[law]) == pytest.approx(DRAG_FACTOR[law](reynolds), rel=1e-14)


@pytest.mark.parametrize("law", p.DRAG_LAWS.names())
@pytest.mark.parametrize("viscosity_ratio", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("diameter", [50e-6, 500e-6, 2e-3, 10e-3, 40e-3])
def test_terminal_velocity_balances_drag_and_buoyant_weight(law, viscosity_ratio, diameter):
    """3 pi mu d f(Re) v / HR(lam) = (rho_d - rho_s) g pi d^3 / 6 with the law's own f (HR = 1 for rigid spheres)."""
    v = p.terminal_velocity(diameter, RHO_D, RHO_S, MU, p.DRAG_LAWS[law], viscosity_ratio)
    reynolds = RHO_S * v * diameter / MU
    hr = p.hadamard_rybczynski_factor(viscosity_ratio) if viscosity_ratio > 0 else 1.0
    drag = 3.0 * math.pi * MU * diameter * DRAG_FACTOR[law](reynolds) * v / hr
    weight = (RHO_D - RHO_S) * G * math.pi / 6.0 * diameter**3
    assert v > 0.0 and drag == pytest.approx(weight, rel=1e-12)


@pytest.mark.parametrize("law", p.DRAG_LAWS.names())
@pytest.mark.parametrize("viscosity_ratio", [0.0, 0.5])
def test_terminal_velocity_balances_the_fulldem_drag_kernel(law, viscosity_ratio):
    """The shared terminal velocity is where fulldem's drag coefficient (eps = 1, no hindrance) carries the buoyant
    weight: one law, honoured the same way by both."""
    from fulldem.coupling.drag import drag_coefficient

    d = 5e-3
    v = p.terminal_velocity(d, RHO_D, RHO_S, MU, p.DRAG_LAWS[law], viscosity_ratio)
    beta = drag_coefficient(d, v, 1.0, RHO_S, MU, p.DRAG_LAWS[law], p.HINDRANCE_NONE, viscosity_ratio)
    assert beta * v == pytest.approx((RHO_D - RHO_S) * G * math.pi / 6.0 * d**3, rel=1e-12)


@pytest.mark.parametrize("law", p.DRAG_LAWS.names())
def test_every_drag_law_is_stokes_at_vanishing_reynolds(law):
    d = 10e-6  # Re ~ 2e-8
    v = p.terminal_velocity(d, RHO_D, RHO_S, MU, p.DRAG_LAWS[law])
    assert RHO_S * v * d / MU < 1e-7
    assert v == pytest.approx(p.stokes_velocity(d, RHO_D, RHO_S, MU), rel=1e-5)
    assert p.terminal_velocity(d, 2000.0, RHO_S, MU, p.DRAG_LAWS[law]) < 0.0  # a lighter droplet rises


@pytest.mark.parametrize("law", p.DRAG_LAWS.names())
@pytest.mark.parametrize("viscosity_ratio", [0.05, 1.0, 20.0])
def test_fluid_drop_factor_is_honoured_by_the_shared_terminal_velocity(law, viscosity_ratio):
    """At Re -> 0 a clean fluid drop settles at HR(lam) = 3(1 + lam)/(2 + 3 lam) times the rigid sphere; at
    finite Re a Reynolds-dependent law gives a little less (the drag factor grows with the speed)."""
    code = p.DRAG_LAWS[law]
    d = 10e-6
    rigid = p.terminal_velocity(d, RHO_D, RHO_S, MU, code, 0.0)
    drop = p.terminal_velocity(d, RHO_D, RHO_S, MU, code, viscosity_ratio)
    hr = 3.0 * (1.0 + viscosity_ratio) / (2.0 + 3.0 * viscosity_ratio)
    assert drop / rigid == pytest.approx(hr, rel=1e-5)
    d = 10e-3  # Re ~ 10
    rigid = p.terminal_velocity(d, RHO_D, RHO_S, MU, code, 0.0)
    drop = p.terminal_velocity(d, RHO_D, RHO_S, MU, code, viscosity_ratio)
    if law == "stokes":
        assert drop / rigid == pytest.approx(hr, rel=1e-14)
    else:
        assert 1.0 < drop / rigid < hr


@pytest.mark.parametrize("law", p.DRAG_LAWS.names())
@pytest.mark.parametrize("fluid_drop", [False, True])
def test_case_settling_velocity_is_the_shared_terminal_velocity(law, fluid_drop):
    case = load_case("simple", [f"drag.law={law}", f"drag.fluid_drop={str(fluid_drop).lower()}"])
    ratio = case.matte.viscosity / case.slag_viscosity if fluid_drop else 0.0
    d = np.array([300e-6, 1e-3, 8e-3])
    expected = [p.terminal_velocity(x, case.matte.density, case.slag.density, case.slag_viscosity,
                                    p.DRAG_LAWS[law], ratio) for x in d]
    assert [settling_velocity(case, x) for x in d] == expected
    np.testing.assert_allclose(settling_velocity(case, d), expected, rtol=1e-14)


# ------------------------------------------------------------------------------------------------------- hindrance
@pytest.mark.parametrize("hindrance", p.HINDRANCE.names())
@pytest.mark.parametrize("reynolds", [1e-4, 0.1, 30.0, 3000.0])
def test_hindrance_is_one_in_a_clear_fluid_and_matches_its_law(hindrance, reynolds):
    code = p.HINDRANCE[hindrance]
    assert p.hindrance_factor(1.0, reynolds, code) == 1.0
    for eps in (0.4, 0.7, 0.95):
        assert p.hindrance_factor(eps, reynolds, code) == pytest.approx(HINDRANCE_FACTOR[hindrance](eps, reynolds),
                                                                        rel=1e-13)
        assert p.hindrance_factor(eps, reynolds, code) >= 1.0  # crowding never lowers the drag


# ------------------------------------------------------------------------------------------- probability forms
@pytest.mark.parametrize("form", p.PROBABILITY_FORMS.names())
@pytest.mark.parametrize("d1, d2", [(500e-6, 500e-6), (300e-6, 2e-3), (1e-3, 40e-3)])
def test_probability_form_is_bounded_and_falls_with_weber_number(form, d1, d2):
    speeds = np.logspace(-5, 2, 50)
    pc = np.array([p.coalescence_probability(d1, d2, u, RHO_D, RHO_S, SIGMA, 1.0, 0.5, p.PROBABILITY_FORMS[form])
                   for u in speeds])
    we = p.weber_number_v(min(d1, d2), speeds, RHO_S, SIGMA)
    assert np.all(np.diff(we) > 0)
    assert np.all((pc >= 0.0) & (pc <= 1.0))
    assert np.all(np.diff(pc) < 0) and pc[0] > 0.99 and pc[-1] < 0.01
    assert p.coalescence_probability(d1, d2, 0.0, RHO_D, RHO_S, SIGMA, 1.0, 0.5, p.PROBABILITY_FORMS[form]) == 1.0


# ------------------------------------------------------------------------------------------- coalescence rules
@pytest.mark.parametrize("rule", p.COALESCENCE_RULES.names())
@pytest.mark.parametrize("threshold", [0.0, 0.5, 1.0])
def test_coalescence_rule_agrees_with_its_definition(rule, threshold):
    code = p.COALESCENCE_RULES[rule]
    uniforms = (np.arange(100000) + 0.5) / 100000  # a uniform grid in [0, 1): its mean is the expectation
    for pc in (0.0, 0.2, 0.5, 0.7, 1.0):
        fraction = p.merger_fraction(pc, threshold, code)
        assert fraction == RULE_FRACTION[rule](pc, threshold)
        merged = np.mean([p.collision_merges(pc, threshold, code, u) for u in uniforms])
        assert merged == pytest.approx(fraction, abs=1e-5)  # one collision's outcome agrees in expectation
        # merger_efficiency (the popbal kernel's) is the rule applied to Eq. 2 at the approach speed
        for speed in (1e-3, 0.05, 0.5):
            pc_eq2 = p.coalescence_probability(400e-6, 900e-6, speed, RHO_D, RHO_S, SIGMA, 1.0, 0.5, p.FORM_SEED)
            assert p.merger_efficiency(400e-6, 900e-6, speed, RHO_D, RHO_S, SIGMA, 1.0, 0.5, p.FORM_SEED, threshold,
                                       code) == RULE_FRACTION[rule](pc_eq2, threshold)


def test_popbal_takes_its_rules_from_settler_physics():
    import popbal
    from popbal import kernels

    assert popbal.COALESCENCE_RULES is p.COALESCENCE_RULES
    assert kernels.merger_efficiency is p.merger_efficiency
    assert (kernels.RULE_STEP, kernels.RULE_PROBABILITY) == (p.RULE_STEP, p.RULE_PROBABILITY)
