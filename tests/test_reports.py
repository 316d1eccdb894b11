"""Reports executed from notebooks (analysis.report, ``settler report``).

Every report in reports/ (a jupytext percent script with a parameters cell: found, not listed, so a new report is
covered when its file is dropped in) renders with ``quick = true`` through the command, and its HTML holds what the
kernel printed. Small notebooks made here check that a failing cell of any kind (an exception, also in a cell tagged
raises-exception; sys.exit(0), which papermill lets pass; a kernel that dies; a cell over the timeout) fails the
command with exit status 3 and a one-line message naming the cell, and that parameters are checked against the
parameters cell (exit status 2) before any kernel starts.
"""

from __future__ import annotations

import html
import json

import nbformat
import pytest

from analysis import report
from settler.cli import main

REPORTS = report.report_files()


def _write(tmp_path, name, body, parameters="quick = False\nlabel = \"x\"\ncount = 3\nscale = 1.0\n"):
    """A report script in tmp_path: a title cell, the parameters cell, then ``body`` (cells split at '# %%')."""
    path = tmp_path / f"{name}.py"
    path.write_text(f'# %% [markdown]\n# # Toy report {name}\n\n# %% tags=["parameters"]\n{parameters}\n'
                    f"# %%\n{body}\n")
    return path


def _stream_text(notebook) -> str:
    return "".join(output.get("text", "") for cell in notebook.cells for output in cell.get("outputs", [])
                   if output.get("output_type") == "stream" and output.get("name") == "stdout")


def test_reports_are_found():
    names = {path.stem for path in REPORTS}
    assert {"verification", "paper_cases"} <= names


@pytest.mark.parametrize("path", REPORTS, ids=[path.stem for path in REPORTS])
def test_every_report_renders_quick(path, tmp_path, capsys):
    defaults = report.parameter_defaults(report.read_report(path), path)
    assert defaults.get("quick") is False, "every report has a parameter quick = False (CI renders it with true)"
    out = tmp_path / "out"
    assert main(["report", path.stem, "--param", "quick=true", "--out", str(out), "--quiet"]) == 0
    executed = nbformat.read(out / f"{path.stem}.ipynb", as_version=4)
    code = [cell for cell in executed.cells if cell.cell_type == "code" and cell.source.strip()]
    assert all(cell.execution_count is not None for cell in code)
    assert any("quick = True" in cell.source for cell in executed.cells
               if report.INJECTED_TAG in cell.metadata.get("tags", []))
    page = html.unescape((out / f"{path.stem}.html").read_text(encoding="utf-8"))
    printed = [line for line in _stream_text(executed).splitlines() if len(line.strip()) > 10]
    assert printed, "a report prints at least one line of results"
    assert all(line.strip() in page for line in printed[:5])
    assert not (out / f"{path.stem}.failed.ipynb").exists()


def test_parameters_folder_and_environment_reach_the_kernel(tmp_path):
    body = ("import os, sys, matplotlib, settler\nprint('values', repr(label), count, scale, quick)\n"
            "print('cwd', os.getcwd())\nprint('backend', matplotlib.get_backend())\n"
            "import matplotlib.pyplot as plt\nfrom analysis.report import show\n"
            "fig = plt.figure(); plt.plot([0, 1]); show(fig)")
    path = _write(tmp_path, "toy", body)
    out = tmp_path / "out"
    assert main(["report", str(path), "--out", str(out), "--quiet", "--param", "label=hello", "--param",
                 "count=7", "--param", "scale=2", "--param", "quick=true"]) == 0
    executed = nbformat.read(out / "toy.ipynb", as_version=4)
    text = _stream_text(executed)
    assert "values 'hello' 7 2.0 True" in text  # TOML literals; an integer given for a float default becomes 2.0
    assert f"cwd {out.resolve()}" in text
    assert "backend agg" in text.lower()
    page = html.unescape((out / "toy.html").read_text(encoding="utf-8"))
    assert "values 'hello' 7 2.0 True" in page
    assert "data:image/png;base64," in page  # the figure shown is embedded


@pytest.mark.parametrize("body, expected", [
    ("print('before')\n\n# %%\n1 / 0\n\n# %%\nprint('after')", "cell 4 (1 / 0) failed: ZeroDivisionError"),
    ("import sys\nsys.exit(0)", "cell 3 (import sys) failed: SystemExit: 0"),
    ('# %% tags=["raises-exception"]\nraise ValueError("let pass by nbclient")', "failed: ValueError: let pass"),
    ("import os\nos._exit(1)", "the kernel died during cell 3 (import os)"),
    ("import time\ntime.sleep(60)", "cell 3 (import time) ran longer than the per-cell timeout of 3 s"),
], ids=["exception", "sys_exit_0", "raises_exception_tag", "dead_kernel", "timeout"])
def test_a_failing_cell_fails_the_command(tmp_path, capsys, body, expected):
    path = _write(tmp_path, "broken", body)
    out = tmp_path / "out"
    (out).mkdir()
    (out / "broken.html").write_text("an earlier success")
    status = main(["report", str(path), "--out", str(out), "--quiet", "--timeout", "3"])
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert status == 3
    assert message.startswith("settler report: error: broken: ") and expected in message
    assert (out / "broken.failed.ipynb").is_file() and not (out / "broken.ipynb").exists()
    assert (out / "broken.html").read_text() == "an earlier success"  # left as it was
    assert not list(out.glob(".broken.*"))  # no partial file left behind


@pytest.mark.parametrize("arguments, expected", [
    (["--param", "nope=1"], "--param nope=1: broken has no parameter 'nope'; allowed: quick, label, count, scale"),
    (["--param", "quick=1"], "--param quick=1: allowed: a boolean"),
    (["--param", "quick=True"], "--param quick=True: not a TOML literal"),
    (["--param", "count=2.5"], "--param count=2.5: allowed: an integer"),
    (["--param", "count"], "--param 'count': allowed: key=value"),
    (["--param", "scale=nan"], "--param scale=nan: allowed: a finite number"),
], ids=["unknown", "int_for_bool", "python_spelling", "float_for_int", "no_value", "nan"])
def test_bad_parameters_are_refused_before_running(tmp_path, capsys, arguments, expected):
    path = _write(tmp_path, "broken", "raise RuntimeError('must not run')")
    out = tmp_path / "out"
    assert main(["report", str(path), "--out", str(out), "--quiet", *arguments]) == 2
    assert expected in capsys.readouterr().err
    assert not out.exists() or not list(out.iterdir())


def test_unknown_report_and_missing_out_are_refused(tmp_path, capsys):
    assert main(["report", "no_such_report", "--out", str(tmp_path)]) == 2
    assert "report 'no_such_report': no such report; allowed: " in capsys.readouterr().err
    assert main(["report", "verification"]) == 2
    assert "--out: missing" in capsys.readouterr().err
    plain = tmp_path / "plain.py"
    plain.write_text("print('a script, not a report')\n")
    assert main(["report", str(plain), "--out", str(tmp_path / "out")]) == 2
    assert "not a report" in capsys.readouterr().err


def test_list_shows_every_report_with_its_title(tmp_path, capsys):
    _write(tmp_path, "first", "print(1)")
    _write(tmp_path, "second", "print(2)")
    (tmp_path / "helper.py").write_text("x = 1\n")  # not a report: no parameters cell
    assert main(["report", "--list", "--reports", str(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines == ["first   Toy report first", "second  Toy report second"]
    assert main(["report"]) == 0  # no NAME: the checkout's reports
    listed = capsys.readouterr().out
    assert all(path.stem in listed for path in REPORTS)
    assert "Verification: Stokes" in listed


@pytest.mark.parametrize("text, value", [("2", 2), ("0.5", 0.5), ("1e-3", 1e-3), ("true", True), ('"deep"', "deep"),
                                         ("deep", "deep"), ('["simple", "deep"]', ["simple", "deep"])])
def test_param_values_are_toml_literals(text, value):
    assert report.parse_value("key", text) == value
    assert type(report.parse_value("key", text)) is type(value)


def test_list_parameter_is_passed_as_a_list(tmp_path):
    path = _write(tmp_path, "lists", "print('cases', json.dumps(cases))", parameters='quick = False\ncases = ["a"]\n'
                  "import json\n")
    out = tmp_path / "out"
    assert main(["report", str(path), "--out", str(out), "--quiet", "--param", 'cases=["b", "c"]']) == 0
    text = _stream_text(nbformat.read(out / "lists.ipynb", as_version=4))
    assert f"cases {json.dumps(['b', 'c'])}" in text
