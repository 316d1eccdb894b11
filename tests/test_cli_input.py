"""The command line takes what users type and refuses bad input in one line (issue 10, "a new user's first hour"):
overrides before or after options, times checked like case keys, strict JSON, no tracebacks."""

import json
import math
import subprocess
import sys

import pytest

from settler.cli import main


def _refuse_constant(token):
    raise ValueError(f"non-standard JSON constant {token}")


def test_overrides_after_options(capsys, tmp_path):
    assert main(["info", "simple", "--json", "slag.temperature=1600"]) == 0
    case = json.loads(capsys.readouterr().out)["case"]
    assert case["slag"]["temperature"] == 1600
    assert main(["reduced", "simple", "--out", str(tmp_path / "r"), "popbal.end_time=2", "--quiet"]) == 0
    assert json.loads((tmp_path / "r" / "metadata.json").read_text()) is not None
    assert "end_time = 2.0" in (tmp_path / "r" / "case.toml").read_text()


def test_overrides_mixed_with_options_in_any_order(capsys):
    assert main(["info", "simple", "slag.temperature=1600", "--json", "slag.density=3100"]) == 0
    case = json.loads(capsys.readouterr().out)["case"]
    assert case["slag"]["temperature"] == 1600 and case["slag"]["density"] == 3100


def test_stray_words_are_still_refused(capsys):
    with pytest.raises(SystemExit) as info:
        main(["info", "simple", "--json", "oops"])
    assert info.value.code == 2 and "unrecognized arguments: oops" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(["cases", "slag.density=3000"])
    assert info.value.code == 2 and "takes no overrides" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "=-inf", "abc"])
@pytest.mark.parametrize("command", ["full", "reduced"])
def test_command_line_times_are_checked_like_case_keys(command, value, capsys, tmp_path):
    with pytest.raises(SystemExit) as info:
        main([command, "demo", "--out", str(tmp_path / "o")]
             + (["--end-time" + value] if value.startswith("=") else ["--end-time", value]))
    err = capsys.readouterr().err
    assert info.value.code == 2 and "--end-time" in err and "allowed" in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_info_json_is_strict(capsys):
    """Derived numbers that do not apply are NaN inside; JSON has no NaN, so they are written as null."""
    assert main(["info", "simple", "--json"]) == 0
    text = capsys.readouterr().out
    data = json.loads(text, parse_constant=_refuse_constant)
    values = [r["value"] for r in data["derived"]]
    assert all(v is None or (isinstance(v, (int, float)) and math.isfinite(v)) or isinstance(v, str)
               for v in values)


def test_reduced_out_into_another_run_is_refused(capsys, tmp_path):
    out = tmp_path / "r"
    assert main(["reduced", "simple", "popbal.end_time=1", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["reduced", "simple", "popbal.end_time=1", "--out", str(out), "--quiet"]) == 2
    assert "holds another run" in capsys.readouterr().err
    assert main(["reduced", "simple", "popbal.end_time=1", "--out", str(out), "--quiet", "--overwrite"]) == 0


def test_droplet_list_errors_are_one_line(capsys, tmp_path):
    bad = tmp_path / "d.csv"
    bad.write_text("x,y,z,diameter,densty\n0.05,0.05,0.05,0.001,5000\n")
    assert main(["full", "demo", "--droplets", str(bad), "--no-feed", "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "densty" in err and "density" in err


def test_unexpected_errors_are_one_line_and_debug_shows_the_traceback(monkeypatch, capsys):
    import settler.derived

    def broken(case):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(settler.derived, "derived_numbers", broken)
    assert main(["info", "simple"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "internal error: ZeroDivisionError" in err and "--debug" in err
    with pytest.raises(ZeroDivisionError):
        main(["info", "simple", "--debug"])


def test_python_dash_m_settler():
    out = subprocess.run([sys.executable, "-m", "settler", "cases"], capture_output=True, text=True)
    assert out.returncode == 0 and "simple" in out.stdout


@pytest.mark.parametrize("argv", [["--version"], ["info", "demo"], ["cases"], ["info", "--help"]])
def test_shared_commands_load_no_engine(argv):
    """The shared layer dispatches to the engines by name (settler.cli.ENGINES) and imports one only when its
    command runs."""
    code = ("import sys\nfrom settler.cli import main\ntry:\n    main(%r)\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('popbal', 'fulldem')))" % (argv,))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_a_closed_pipe_stops_quietly(monkeypatch, capsys):
    """`settler info simple | head -1`: when the reader goes away, writing raises BrokenPipeError; the command stops
    with 141 (128 + SIGPIPE) and writes no error line."""
    class ClosedPipe:
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

        def flush(self):
            pass

    monkeypatch.setattr(sys, "stdout", ClosedPipe())
    assert main(["info", "simple"]) == 141
    assert capsys.readouterr().err == ""


def test_an_implausible_viscosity_is_warned_about_and_refused_in_one_line_where_the_reduced_model_overflows(
        capsys, tmp_path):
    """The README's promise for values far outside what the laws were made for: the warning names the value; where
    popbal's closures overflow on it (a 1e-300 Pa s slag: the plume Reynolds number is infinite) the run is refused
    in one line naming the key (exit 2), not stopped by an internal ZeroDivisionError (exit 1)."""
    out = tmp_path / "r"
    assert main(["reduced", "simple", "slag.viscosity_reference=1e-300", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert any("warning" in line and "1e-300 Pa s" in line for line in err)
    assert err[-1].startswith("settler reduced: error:") and "slag.viscosity_reference = 1e-300" in err[-1]
    assert "internal error" not in "\n".join(err) and not out.exists()
