"""Every stored reference run (data/reference/<name>/) is evidence: it loads with analysis.load_run, names the
command, commit and seed that made it from a clean tree, names no folder of the machine that made it, conserves
matte to round-off, all of them ran one engine (equal engine trees in reference.json), and `settler figures` draws
each of them."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import numpy as np
import pytest

from analysis import load_run

ROOT = Path(__file__).resolve().parents[1]
#: The stored set (data/reference/README.md), held to its engine (data/reference/engines.toml).
SETS = [ROOT / "data" / "reference"]
STORED = sorted(p.parent for s in SETS for p in s.glob("*/reference.json"))


def _run_id(folder: Path) -> str:
    return folder.name


#: Strings that would name a machine's folders.
MACHINE_PATHS = re.compile(r"(^|[\s'\"=])/(work|home|tmp|root|Users|mnt|scratch)/")
#: Relative mass-accounting error allowed in a stored run's time series [-] (the engine holds it to round-off).
MASS_TOLERANCE = 1e-12
#: The figures of `settler figures` drawn from droplet snapshots (analysis.figures).
SNAPSHOT_FIGURES = ("slice_diameter", "slice_velocity", "slice_slag", "density_height", "velocity_height")


def _info(folder: Path) -> dict:
    return json.loads((folder / "reference.json").read_text())


@pytest.mark.parametrize("folder", STORED, ids=_run_id)
def test_a_stored_run_loads_and_conserves_matte(folder):
    run = load_run(folder)
    assert run.is_reference and run.engine == "fulldem" and len(run.timeseries) > 10
    assert np.nanmax(np.abs(run.timeseries["mass_balance_error"])) < MASS_TOLERANCE


@pytest.mark.parametrize("folder", STORED, ids=_run_id)
def test_provenance_names_command_commit_seed_and_a_clean_tree(folder):
    info = _info(folder)
    assert info["command"] == ("settler sweep --set data/reference/design.toml --engine full --only " + folder.name)
    assert re.fullmatch(r"[0-9a-f]{40}", info["commit"]) and info["dirty"] is False
    assert isinstance(info["seed"], int)
    assert set(info["engine_trees"]) == {"fulldem", "popbal", "settler"}
    for text in (info["command"], json.dumps(info.get("metadata", {}).get("command", "")),
                 (folder / "case.toml").read_text()):
        assert not MACHINE_PATHS.search(text), text[:200]


#: The runs whose figures the default test run draws: one with droplet snapshots (two of them) and one stored without
#: any (a seed replicate); every other run's are drawn under ``-m slow`` (about 3 s each on CI's 2 cores, 100 s in
#: all, which kept the default run above the guide's 15 minutes). [chosen]
FIGURES_BY_DEFAULT = ("demo", "demo_cell_25_seed2")
FIGURE_RUNS = [f if f.name in FIGURES_BY_DEFAULT else pytest.param(f, marks=pytest.mark.slow) for f in STORED]


def test_the_default_figure_runs_are_stored():
    """The default run's two figure runs exist (else the default run would draw no stored run's figures)."""
    assert {f.name for f in STORED} >= set(FIGURES_BY_DEFAULT)


@pytest.mark.parametrize("folder", FIGURE_RUNS, ids=_run_id)
def test_settler_figures_renders_every_stored_run(folder, tmp_path):
    """`settler figures` draws every figure of every stored run (the reference-run issue's "settler figures
    renders every stored run"), each a non-empty PNG; only a run stored without droplet snapshots (the seed
    replicates, whose time series and profiles measure the seed scatter, data/reference/README.md) goes without the
    figures drawn from snapshots, and says so."""
    from analysis import figures

    written = figures.render_all(folder, tmp_path / "figs")
    drawn = {name: path for name, path in written.items() if isinstance(path, Path)}
    not_drawn = {name: why for name, why in written.items() if not isinstance(why, Path)}
    if _info(folder)["snapshots"]["stored"] == 0:
        assert set(not_drawn) == set(SNAPSHOT_FIGURES), not_drawn
        assert all("no snapshots" in why for why in not_drawn.values()), not_drawn
    else:
        assert not not_drawn, not_drawn
    assert drawn and all(path.suffix == ".png" and path.stat().st_size > 0 for path in drawn.values())


def _engines(set_folder: Path) -> tuple[dict, list[dict]]:
    data = tomllib.loads((set_folder / "engines.toml").read_text())
    return data["set"], data.get("equivalent", [])


@pytest.mark.parametrize("set_folder", SETS, ids=lambda p: p.name)
def test_every_regenerated_run_ran_one_engine(set_folder):
    """The set's engine, or an engine change listed in engines.toml as leaving every other run bit for bit the same,
    with the check that showed it, and only for the runs it names."""
    the_set, equivalents = _engines(set_folder)
    keys = ("fulldem", "popbal", "settler")
    on_set = 0
    runs = [f for f in STORED if f.parent == set_folder]
    assert runs, f"{set_folder.name}: an engines.toml and no stored run"
    for folder in runs:
        trees = _info(folder)["engine_trees"]
        if trees == {k: the_set[k] for k in keys}:
            on_set += 1
            continue
        match = [e for e in equivalents if trees == {k: e[k] for k in keys}]
        assert match, f"{folder.name}: engine trees {trees} are neither the set's nor a listed equivalent"
        assert folder.name in match[0]["runs"], f"{folder.name}: not among the runs of its engine change"
    assert on_set >= 1  # an equivalent engine is an exception for named runs, never the set's engine
    for e in equivalents:
        assert re.fullmatch(r"[0-9a-f]{40}", e["commit"]) and e["change"] and "analysis.identity" in e["check"]
        assert "the same run bit for bit" in e["check"]


#: What all of data/reference/ may hold [bytes] (issue 21's storage budget: 40 MB).
STORAGE_LIMIT = 40_000_000


@pytest.mark.parametrize("folder", SETS, ids=lambda p: p.name)
def test_the_reference_set_stays_within_its_storage_budget(folder):
    """All of data/reference/ within the budget: runs, design, README and the kernel runs' droplet files."""
    total = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts)
    assert total <= STORAGE_LIMIT, f"data/{folder.name} holds {total / 1e6:.2f} MB, over {STORAGE_LIMIT / 1e6:g} MB"


def _git(*args):
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


def test_every_engine_commit_is_in_the_repository():
    """Provenance that names a commit nobody can check out is no provenance: every stored run's commit and every
    equivalent engine's commit is an object of this repository whose trees are the ones recorded (skipped where the
    checkout carries no history, as a shallow clone, or git is missing)."""
    if shutil.which("git") is None or _git("rev-parse", "--is-shallow-repository").stdout.strip() != "false":
        pytest.skip("no full git history in this checkout")
    for folder in STORED:
        info = _info(folder)
        for part, tree in info["engine_trees"].items():
            found = _git("rev-parse", f"{info['commit']}:{part}")
            assert found.returncode == 0, f"{folder.name}: commit {info['commit']} is not in the repository"
            assert found.stdout.strip() == tree, f"{folder.name}: {part} at {info['commit'][:7]} is not {tree[:7]}"
    for e in (e for set_folder in SETS for e in _engines(set_folder)[1]):
        for part in ("fulldem", "popbal", "settler"):
            assert _git("rev-parse", f"{e['commit']}:{part}").stdout.strip() == e[part], e["commit"]
