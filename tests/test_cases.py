"""Case loading: presets resolve, and every kind of bad input is refused with a message naming key, value, allowed."""

import re
from pathlib import Path

import pytest

from settler.cases import DATA_DIR, SCHEMA, CaseError, list_presets, load_case, parse_override, resolve


def test_presets_load_with_paper_values():
    assert {"cubic", "simple", "deep"} <= set(list_presets())
    simple, cubic, deep = (load_case(n) for n in ("simple", "cubic", "deep"))
    assert simple.geometry.height == 0.2 and simple.geometry.inlet_diameter == 0.15 and not simple.has_outlet
    assert cubic.slag.feed_rate == 0.022 and cubic.geometry.outlet_diameter == 0.015
    assert deep.geometry.height == 0.5 and deep.feed.mass_rate == 0.00015 and deep.reaction.enabled
    assert simple.coalescence.size_limit == 1.5e-3 and cubic.coalescence.size_limit == 2e-3
    assert deep.coalescence.size_limit == 40e-3
    assert simple.slag_viscosity == pytest.approx(0.45, rel=1e-15)
    assert deep.x_initial == pytest.approx(0.405, abs=5e-4)


def test_overrides_from_strings_and_dict():
    case = load_case("simple", ["slag.viscosity_reference=0.3", "coalescence.probability_form=luo",
                                "geometry.inlet_center=[0.09, 0.1]"])
    assert case.slag.viscosity_reference == 0.3
    assert case.coalescence.probability_form == "luo"
    assert case.inlet_center == (0.09, 0.1)
    assert load_case("simple", {"feed.mass_rate": 1e-3}).feed.mass_rate == 1e-3
    assert case.replace(slag__temperature=1500.0).slag_viscosity > 0.3
    assert parse_override("a.b = true") == ("a.b", True)


def test_resolved_case_roundtrips_through_toml(tmp_path):
    case = load_case("deep")
    path = tmp_path / "resolved.toml"
    path.write_text(case.to_toml())
    again = load_case(path)
    assert again.to_dict() == case.to_dict()


def _simple_raw():
    import tomllib

    return tomllib.loads((DATA_DIR / "cases" / "simple.toml").read_text())


BAD = [
    # (overrides, key named in the message, fragment of the allowed part)
    ({"slag.viscosity_reference": -0.45}, "slag.viscosity_reference", "allowed: a number > 0"),
    ({"slag.viscosity_reference": "thick"}, "slag.viscosity_reference", "wrong type"),
    ({"slag.density": True}, "slag.density", "wrong type"),
    ({"feed.seed": 1.5}, "feed.seed", "an integer"),
    ({"coalescence.enabled": "yes"}, "coalescence.enabled", "true or false"),
    ({"coalescence.probability_form": "fluent"}, "coalescence.probability_form", "one of 'seed', 'luo'"),
    ({"coalescence.threshold": 1.5}, "coalescence.threshold", "<= 1"),
    ({"coalescence.size_limit": 0.4e-3}, "coalescence.size_limit", "largest fed droplet"),
    ({"geometry.outlet_diameter": 0.015, "geometry.outlet_height": 0.5}, "geometry.outlet_height",
     "inside the side wall"),
    ({"geometry.outlet_diameter": 0.3, "geometry.outlet_height": 0.1}, "geometry.outlet_diameter", "must fit"),
    ({"geometry.inlet_diameter": 0.25}, "geometry.inlet_diameter", "inside the top face"),
    ({"geometry.inlet_center": [0.02, 0.1]}, "geometry.inlet_center", "inside the top face"),
    ({"geometry.inlet_center": [0.1]}, "geometry.inlet_center", "list of 2 numbers"),
    ({"geometry.height": 0.0}, "geometry.height", "> 0"),
    ({"slag.feed_rate": 0.01}, "slag.feed_rate", "closed box"),
    ({"matte.density": 3000.0}, "matte.density", "must exceed slag.density"),
    ({"feed.scale_min": 0.0}, "feed.scale_min", "> 0"),
    ({"feed.scale_max": 0.9}, "feed.scale_max", ">= 1"),
    ({"reaction.enabled": True, "reaction.x_final": 0.5}, "reaction.x_final", "must exceed the feed's Cu2S fraction"),
    ({"reaction.enabled": True, "matte.density": 5400.0}, "matte.density", "Cu2S fraction by Eq. 4"),
    ({"slag.temperature": float("nan")}, "slag.temperature", "finite"),
]


@pytest.mark.parametrize("overrides, key, allowed", BAD, ids=[b[1] + ":" + b[2][:12] for b in BAD])
def test_bad_values_are_refused_clearly(overrides, key, allowed):
    with pytest.raises(CaseError) as info:
        resolve(_simple_raw(), overrides)
    message = str(info.value)
    assert key in message
    assert allowed in message
    value = overrides.get(key, next(iter(overrides.values())))
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value == value:
        assert re.search(re.escape(repr(float(value) if isinstance(value, float) else value)), message) or \
            f"{value:g}" in message


def test_unknown_section_and_key():
    raw = _simple_raw()
    raw["slagg"] = {"density": 3000.0}
    with pytest.raises(CaseError, match=r"unknown section \[slagg\]; allowed sections: case, geometry"):
        resolve(raw)
    raw = _simple_raw()
    raw["slag"]["viscosty"] = 0.3
    with pytest.raises(CaseError, match=r"unknown key slag.viscosty; allowed keys in \[slag\]: density"):
        resolve(raw)
    with pytest.raises(CaseError, match="unknown key feed.rate"):
        load_case("simple", ["feed.rate=1"])
    with pytest.raises(CaseError, match="section.key=value"):
        load_case("simple", ["feed.mass_rate"])


def test_missing_key_and_bad_property_set():
    raw = _simple_raw()
    raw["case"]["properties"] = "nonexistent"
    with pytest.raises(CaseError, match="case.properties = 'nonexistent'.*available: flash_smelting"):
        resolve(raw)
    raw = _simple_raw()
    del raw["case"]["properties"]
    with pytest.raises(CaseError, match=r"slag.density is missing: allowed: a number > 0 \[kg/m\^3\]"):
        resolve(raw)


def test_bad_files(tmp_path):
    with pytest.raises(CaseError, match="neither a file nor a preset; presets: cubic, deep, demo, furnace, simple"):
        load_case("no_such_case")
    bad = tmp_path / "bad.toml"
    bad.write_text("[geometry\nheight = 1")
    with pytest.raises(CaseError, match="not valid TOML"):
        load_case(bad)
    bad.write_text("height = 1.0\n")
    with pytest.raises(CaseError, match="must be a \\[section\\] table"):
        load_case(bad)


def test_every_schema_key_is_documented():
    for section, fields in SCHEMA.items():
        for key, field in fields.items():
            assert field.doc, f"{section}.{key} has no documentation"


SOURCE_TAG = re.compile(r"#.*\[(paper|lit|derived|chosen)\]")


#: Input files of data/: the stored reference runs (data/reference/<case>/case.toml) are outputs, the resolved case of
#: a run, whose source is the command and commit in their reference.json (the guide's rule for stored runs).
STORED_RUNS = {"reference"}  # the stored set (data/reference)
DATA_INPUTS = sorted(p for p in Path(DATA_DIR).rglob("*.toml") if not STORED_RUNS & set(p.relative_to(DATA_DIR).parts))


@pytest.mark.parametrize("path", DATA_INPUTS, ids=lambda p: p.name)
def test_every_number_in_data_carries_its_source(path):
    """Developers' guide: every number in data/ carries its source or is marked as chosen (stored runs: see
    DATA_INPUTS)."""
    numeric = re.compile(r"^\s*\w+\s*=\s*[-+]?(\d|\.\d|\[)")
    missing = [line for line in path.read_text().splitlines() if numeric.match(line) and not SOURCE_TAG.search(line)]
    assert not missing, f"{path.name}: numbers without a source tag: {missing}"


# ------------------------------------------------------------------------ unreadable files, broken installs (issue 10)
def _one_line_error(call, *args) -> str:
    with pytest.raises(CaseError) as info:
        call(*args)
    message = str(info.value)
    assert "\n" not in message, message
    return message


def test_case_file_that_is_not_utf8_is_refused(tmp_path):
    bad = tmp_path / "latin1.toml"
    bad.write_bytes('[case]\nname = "café"\n'.encode("latin-1"))
    message = _one_line_error(load_case, bad)
    assert str(bad) in message and "not UTF-8" in message and "allowed: a UTF-8 TOML file" in message
    assert "b'\\xe9'" in message  # the offending byte


def test_case_path_that_is_a_folder_is_refused(tmp_path):
    message = _one_line_error(load_case, tmp_path)
    assert f"case file {tmp_path} is a folder; allowed: a TOML file" == message
    folder = tmp_path / "looks_like.toml"
    folder.mkdir()
    assert "is a folder" in _one_line_error(load_case, folder)


@pytest.fixture
def data_copy(tmp_path, monkeypatch):
    """A copy of the data folder that settler.cases reads instead of the real one."""
    import shutil

    import settler.cases

    copy = tmp_path / "data"
    shutil.copytree(DATA_DIR, copy, ignore=shutil.ignore_patterns("reference", "calibration"))
    monkeypatch.setattr(settler.cases, "DATA_DIR", copy)
    return copy


def test_property_set_that_is_not_utf8_or_a_folder_is_refused(data_copy):
    props = data_copy / "properties" / "flash_smelting.toml"
    props.write_bytes(props.read_bytes() + b"\n# \xff\xfe\n")
    message = _one_line_error(load_case, "simple")
    assert f"property set file {props} is not UTF-8" in message
    (data_copy / "properties" / "folder.toml").mkdir()
    message = _one_line_error(load_case, "simple", ["case.properties=folder"])
    assert f"property set file {data_copy / 'properties' / 'folder.toml'} is a folder" in message


def test_no_presets_is_an_error_naming_where_it_looked(data_copy):
    for preset in (data_copy / "cases").glob("*.toml"):
        preset.unlink()
    message = _one_line_error(list_presets)
    assert f"no case presets (*.toml) in {data_copy / 'cases'}" in message and "SETTLER_DATA" in message


@pytest.mark.parametrize("temperature, viscosity", [(300.0, "inf"), (3000.0, "0.0")])
def test_arrhenius_overflow_is_refused(temperature, viscosity):
    """E_a = 1e9 J/mol: exp overflows (cold) or underflows (hot); this used to be a ZeroDivisionError in info."""
    overrides = {"slag.activation_energy": 1e9, "slag.temperature": temperature}
    message = _one_line_error(resolve, _simple_raw(), overrides)
    assert message.startswith(f"slag.activation_energy = 1e+09 J/mol with slag.temperature = {temperature:g} K")
    assert f"slag viscosity of {viscosity} Pa s" in message and "allowed: values that give a finite viscosity > 0" \
        in message


def test_data_dir_order(tmp_path):
    """SETTLER_DATA, else the checkout's data/, else the copy beside the installed package."""
    from settler.paths import find_data_dir

    checkout = tmp_path / "checkout"
    (checkout / "settler").mkdir(parents=True)
    (checkout / "data").mkdir()
    (checkout / "pyproject.toml").write_text("")
    assert find_data_dir({"SETTLER_DATA": "/elsewhere"}, checkout / "settler")[0] == Path("/elsewhere")
    assert find_data_dir({"SETTLER_DATA": ""}, checkout / "settler")[0] == checkout / "data"
    assert find_data_dir({}, checkout / "settler")[0] == checkout / "data"
    site = tmp_path / "site-packages"
    (site / "settler").mkdir(parents=True)
    (site / "data").mkdir()  # some other distribution's top-level data/ is not a checkout
    path, source = find_data_dir({}, site / "settler")
    assert path == site / "settler" / "data" and source == "the installed package"


def test_importing_cases_leaves_scipy_stats_and_the_plotting_stack_out():
    """Every `settler` command imports settler.cases; scipy.stats alone used to cost about half a second."""
    import subprocess
    import sys

    heavy = ("scipy.stats", "scipy.optimize", "pandas", "matplotlib", "cantera")
    out = subprocess.run([sys.executable, "-c", "import sys, settler.cases, settler.derived\n"
                          f"print([m for m in {heavy!r} if m in sys.modules])"],
                         capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_a_folder_named_like_a_preset_does_not_hide_it(tmp_path, monkeypatch):
    """`settler full simple --out simple`, then `settler full simple --out simple --resume` from the same folder:
    the argument is still the preset (found 2026-12-02: 'case file cubic is a folder')."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cubic").mkdir()
    assert load_case("cubic").case.name == "cubic"
    (tmp_path / "mine").mkdir()  # a folder that is no preset is still refused as a case file
    with pytest.raises(CaseError, match="is a folder"):
        load_case("mine")
