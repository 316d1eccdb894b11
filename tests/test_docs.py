"""The documentation site and what a new user meets first: the docs build with warnings as errors, the tutorial
notebook executes in that build (an error in a cell fails it), the generated references cover every command and
case key, and the README stays a short front page whose picture and links exist."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: The README's length limit [lines]: a front page, not the manual (the manual is docs/).
README_MAX_LINES = 150


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """Build the docs once into a temporary folder with -W (warnings are errors); the HTML folder."""
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_nb")
    out = tmp_path_factory.mktemp("docs") / "html"
    # the kernel draws inline (a MPLBACKEND of the caller's, Agg say, would keep the tutorial's figure out of the page)
    env = {k: v for k, v in os.environ.items() if k != "MPLBACKEND"} | {"PYDEVD_DISABLE_FILE_VALIDATION": "1"}
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS),
                           str(out), "-d", str(out.parent / "doctrees")], capture_output=True, text=True, env=env,
                          timeout=1200)
    assert done.returncode == 0, "docs build failed:\n" + done.stderr[-6000:]
    return out


def test_docs_build_with_warnings_as_errors_and_the_tutorial_executes(built):
    tutorial = (built / "tutorial" / "own-furnace-case.html").read_text()
    # outputs of executed cells: the refusal, the mass balance line, the temperature table and the figure
    assert "refused:" in tutorial and "slag.viscosity_reference" in tutorial
    assert "lost with the slag" in tutorial
    assert len(re.findall(r"\d+ °C +slag viscosity [\d.]+ Pa s +matte lost [\d.]+ %", tutorial)) == 3
    assert re.search(r'<img[^>]+src="[^"]*\.png"', tutorial)


def test_generated_references_cover_every_command_and_case_key(built):
    from settler.cases import SCHEMA
    from settler.cli import COMMANDS

    cli = _text(built / "reference" / "cli.html")
    for command in COMMANDS:
        assert f"settler {command} [ - h ]" in cli, command
    keys = (built / "guide" / "cases.html").read_text()
    for section, fields in SCHEMA.items():
        for key in fields:
            assert f"<code class=\"docutils literal notranslate\"><span class=\"pre\">{key}</span></code>" in keys, \
                f"{section}.{key}"
    api = (built / "api" / "analysis.html").read_text()
    assert "load_run" in api and "droplet_counts" in api


def _text(path: Path) -> str:
    """The words of an HTML page: tags dropped, entities decoded, white space collapsed."""
    import html

    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", path.read_text())).split())


def test_readme_is_a_short_front_page_whose_picture_and_links_exist():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= README_MAX_LINES
    targets = re.findall(r"\]\(([^)\s]+)\)", text)
    assert any(t.endswith(".png") for t in targets)
    for target in targets:
        if not target.startswith("http"):
            assert (ROOT / target).exists(), target
    # the two commands of the developers' guide: the main job and the tests
    assert "pip install -e . && settler full demo --out runs/demo" in text
    assert 'pip install -e ".[test]" && python -m pytest' in text
    assert (ROOT / ".ci" / "run").read_text().strip().endswith('pip install -e ".[test]" && python -m pytest')
    assert "issue" not in text.lower()  # no internal tracker numbers on the front page


def test_licence_and_citation_name_the_seed_paper():
    import yaml

    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["cff-version"].startswith("1.2")
    assert citation["preferred-citation"]["doi"] == "10.1016/j.heliyon.2023.e21570"
    assert "MIT License" in (ROOT / "LICENSE").read_text()


def _csv_files() -> list[Path]:
    """Every CSV of the stored runs (written by the full engine and analysis.reference)."""
    return sorted((ROOT / "data" / "reference").glob("*/*.csv"))


@pytest.mark.parametrize("path", _csv_files(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_stored_csv_reads_with_the_readme_one_liner(path):
    """The README: 'pandas.read_csv(path, comment="#") reads it' -- and the columns are those its units line
    names, in order, each with a unit."""
    import pandas as pd

    first = path.read_text(encoding="utf-8").splitlines()[0]
    assert first.startswith("# units: ")
    named = re.findall(r"(\w+) \[([^\]]*)\]", first[len("# units: "):])
    frame = pd.read_csv(path, comment="#")
    assert list(frame.columns) == [name for name, _ in named]
    assert len(frame) > 0 and all(frame[c].dtype.kind in "fiu" for c in frame.columns)
