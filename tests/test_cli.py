"""The command line: every subcommand has --help; info prints the derived numbers the issue asks for."""

import json
import subprocess
import sys

import pytest

from settler.cli import COMMANDS, main


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_for_every_subcommand(command, capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"] if command is None else [command, "--help"])
    assert info.value.code == 0
    assert "usage: settler" in capsys.readouterr().out


def _derived(case, capsys, *extra):
    assert main(["info", case, *extra, "--json"]) == 0
    records = json.loads(capsys.readouterr().out)["derived"]
    return {r["name"]: r["value"] for r in records}


@pytest.mark.parametrize("case", ["simple", "deep", "furnace"])
def test_info_json_keys_are_unique_identifiers(case, capsys):
    """settler info --json: each derived number has a key a program can use (an identifier, the same for every
    case, unique), besides its name in words."""
    assert main(["info", case, "--json"]) == 0
    records = json.loads(capsys.readouterr().out)["derived"]
    keys = [r["key"] for r in records]
    assert all(k.isidentifier() and k == k.lower() for k in keys) and len(set(keys)) == len(keys)
    assert "feed_droplets_fed_per_second_at_d_mean" in keys and "settling_stokes_velocity_smallest_fed" in keys


def test_info_simple_droplet_rate(capsys):
    numbers = _derived("simple", capsys)
    # physics.md section 2: ~25 800 droplets/s at the 500 um mean size
    assert numbers["droplets fed per second at d_mean"] == pytest.approx(25_800, rel=5e-3)
    # the feed distribution's mean mass is E[s^3] = 1.029x larger
    assert numbers["droplets fed per second"] == pytest.approx(25_800 / 1.029, rel=5e-3)
    # physics.md section 4: cluster volume fraction of order 0.1
    assert 0.05 < numbers["volume fraction, dilute estimate"] < 0.3


def test_info_deep_droplet_rate(capsys):
    numbers = _derived("deep", capsys)
    # deep feeds fresh matte at 4500 kg/m^3 (age 0 of the reaction curve): 0.00015 kg/s / (4500 pi/6 (0.5 mm)^3)
    assert numbers["droplets fed per second at d_mean"] == pytest.approx(509.3, rel=1e-3)
    # at the coalescence runs' 5100 kg/m^3 the same feed is physics.md's ~450 droplets/s
    assert _derived("deep", capsys, "matte.density=5100")["droplets fed per second at d_mean"] == pytest.approx(
        450, rel=5e-3)


def test_info_bad_override_exits_2(capsys):
    assert main(["info", "simple", "slag.viscosity_reference=-1"]) == 2
    err = capsys.readouterr().err
    assert "slag.viscosity_reference = -1.0" in err and "allowed" in err


def test_console_script_runs():
    out = subprocess.run([sys.executable, "-m", "settler.cli", "cases"], capture_output=True, text=True, check=True)
    assert "simple" in out.stdout and "deep" in out.stdout


def test_info_table_feed_counts_every_class(capsys):
    from settler.cases import load_case
    from settler.physics import table_droplet_rate

    case = load_case("furnace")
    f = case.feed
    expected = table_droplet_rate(f.mass_rate, f.table_diameters, f.table_mass_fractions, case.matte.density)
    assert _derived("furnace", capsys)["droplets fed per second"] == pytest.approx(expected, rel=1e-12)


def test_docs_case_reference_is_generated_from_the_schema():
    """The documentation's case-key reference is generated from the schema when the docs are built (docs/conf.py
    writes schema_markdown() into the page docs/guide/cases.md includes), so it cannot fall behind the code."""
    from pathlib import Path

    docs = Path(__file__).resolve().parents[1] / "docs"
    assert "{include} ../_generated/case_keys.md" in (docs / "guide" / "cases.md").read_text()
    assert "schema_markdown()" in (docs / "conf.py").read_text()


