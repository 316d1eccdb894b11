"""Derived numbers: printable as TOML comments, robust to absurd cases; plausibility warnings (issue 10)."""

import math
import tomllib

import pytest

from settler.cases import list_presets, load_case
from settler.derived import PLAUSIBLE_RANGES, derived_numbers, format_numbers, plausibility_warnings

PRESETS = ["cubic", "deep", "demo", "furnace", "simple"]


@pytest.mark.parametrize("name", PRESETS)
def test_info_output_is_valid_toml_that_loads_as_the_case(name, tmp_path):
    """`settler info CASE > my.toml`: the case, then the derived numbers as comments; the file is the case again."""
    case = load_case(name)
    table = format_numbers(derived_numbers(case))
    assert all(line.startswith("# ") for line in table.splitlines())
    text = case.to_toml() + "\n# derived numbers\n" + table + "\n"
    assert tomllib.loads(text) == tomllib.loads(case.to_toml())
    path = tmp_path / "my.toml"
    path.write_text(text)
    assert load_case(path).to_dict() == case.to_dict()


def test_presets_give_no_plausibility_warnings():
    assert set(PRESETS) <= set(list_presets())
    for name in list_presets():
        assert plausibility_warnings(load_case(name)) == [], name


def test_tiny_viscosity_is_warned_about_with_key_value_and_range():
    warnings = plausibility_warnings(load_case("simple", {"slag.viscosity_reference": 1e-300}))
    viscosity = [w for w in warnings if "slag.viscosity_reference" in w]
    assert len(viscosity) == 1 and "1e-300 Pa s" in viscosity[0] and "outside 0.01 to 10 Pa s" in viscosity[0]
    # the settling velocities it implies (2e281 m/s) are far beyond the drag law's Reynolds range
    assert any("coalescence.size_limit" in w and "Re_p = inf" in w and "above 800" in w for w in warnings)
    assert all("\n" not in w for w in warnings)


WARNED = [
    ({"slag.activation_energy": 1e6, "slag.temperature": 1450.0}, "slag.activation_energy = 1e+06 J/mol"),
    ({"slag.density": 1000.0}, "slag.density = 1000 kg/m^3: outside 2500 to 4500 kg/m^3"),
    ({"matte.density": 9000.0}, "matte.density = 9000 kg/m^3: outside 3500 to 6000 kg/m^3"),
    ({"slag.temperature": 1300.0}, "slag.temperature = 1300 K: outside 1400 to 1700 K"),
    ({"matte.interfacial_tension": 5.0}, "matte.interfacial_tension = 5 N/m: outside 0.01 to 1 N/m"),
    ({"matte.interfacial_tension": 1e-3}, "matte.interfacial_tension = 0.001 N/m"),
    ({"feed.mean_diameter": 1e-7}, "feed.mean_diameter = 1e-07 m: outside 1e-06 to 0.05 m"),
    ({"feed.mean_diameter": 0.1, "coalescence.size_limit": 0.2}, "feed.mean_diameter = 0.1 m"),
    ({"drag.law": "stokes", "coalescence.size_limit": 0.01}, "coalescence.size_limit = 0.01 m"),
    ({"coalescence.size_limit": 0.1}, "drag.law = 'schiller_naumann': above 800"),
    ({"coalescence.enabled": False, "drag.law": "stokes", "feed.mean_diameter": 5e-3},
     "feed.mean_diameter x feed.scale_max = 0.0065 m"),
    ({"reaction.enabled": True, "reaction.end_state": "equilibrium", "reaction.oxygen_pressure": 1e30},
     "reaction.oxygen_pressure = 1e+30 Pa: outside 1e-09 to 101325 Pa"),
    ({"reaction.enabled": True, "reaction.end_state": "equilibrium", "reaction.so2_pressure": 1e6},
     "reaction.so2_pressure = 1e+06 Pa: outside 1 to 101325 Pa"),
]


def test_equilibrium_pressures_are_judged_only_where_they_are_read():
    """The stored pressures of a case without the equilibrium end state are not used, so not warned about; the
    preset's own (1e-3 Pa O2, 2e4 Pa SO2) pass where they are."""
    assert plausibility_warnings(load_case("simple", {"reaction.oxygen_pressure": 1e30})) == []
    assert plausibility_warnings(load_case("simple", {"reaction.enabled": True,
                                                      "reaction.end_state": "equilibrium"})) == []


def test_settler_info_says_the_warnings_a_run_says(capsys):
    """settler info prints the run's plausibility warnings to stderr (a 1e-300 Pa s viscosity, a 1e30 Pa oxygen
    pressure), not only the numbers."""
    from settler.cli import main

    assert main(["info", "simple", "slag.viscosity_reference=1e-300", "reaction.enabled=true",
                 "reaction.end_state=equilibrium", "reaction.oxygen_pressure=1e30"]) == 0
    err = capsys.readouterr().err
    assert "settler info: warning: slag viscosity" in err and "reaction.oxygen_pressure = 1e+30 Pa" in err


@pytest.mark.parametrize("overrides, fragment", WARNED, ids=[w[1][:30] for w in WARNED])
def test_values_far_outside_the_laws_are_warned_about(overrides, fragment):
    warnings = plausibility_warnings(load_case("simple", overrides))
    assert any(fragment in w for w in warnings), warnings


def test_reynolds_limit_follows_the_drag_law():
    """A 6 mm droplet settles at Re_p of about 3: fine for Schiller-Naumann, beyond Stokes drag."""
    sn = load_case("simple", {"coalescence.size_limit": 6e-3})
    assert plausibility_warnings(sn) == []
    stokes = plausibility_warnings(sn.replace(drag__law="stokes"))
    assert len(stokes) == 1 and "creeping flow" in stokes[0] and "above 1," in stokes[0]


def test_every_range_has_a_reason():
    for name, r in PLAUSIBLE_RANGES.items():
        assert r.low < r.high and len(r.reason) > 20, name


@pytest.mark.parametrize("overrides", [
    {"slag.viscosity_reference": 1e308},  # settling velocity underflows: was a ZeroDivisionError
    {"feed.mean_diameter": 1e-300, "coalescence.size_limit": 1.0},  # droplet mass underflows to 0
    {"feed.mean_diameter": 1e300, "coalescence.size_limit": 1e301},  # d^3 overflows: was an OverflowError
    {"geometry.inlet_diameter": 1e-300},  # inlet area underflows to 0
    {"feed.distribution": "table", "feed.table_diameters": [1e300, 1e300], "feed.table_mass_fractions": [0.5, 0.5],
     "coalescence.enabled": False},
])
def test_absurd_but_valid_cases_get_numbers_and_warnings_not_exceptions(overrides):
    case = load_case("simple", overrides)
    assert isinstance(plausibility_warnings(case), list)
    numbers = derived_numbers(case)
    values = [q.value for items in numbers.values() for q in items]
    assert any(not math.isfinite(v) or v == 0.0 for v in values)
    format_numbers(numbers)
