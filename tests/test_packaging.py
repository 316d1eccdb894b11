"""A wheel built from the repository carries its data and runs outside the checkout (issue 10, a new user's first hour).

The wheel is built without build isolation (nothing is downloaded; the test extra installs setuptools) from a copy of
the working tree, installed with ``--no-deps`` into a fresh virtual environment that borrows numpy, numba and the rest
from this environment (``--system-site-packages``), and run from a folder outside the checkout with SETTLER_DATA
unset. The full run compiles the Numba kernels anew into the installed copy, which takes a minute or two.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PRESETS = ["cubic", "deep", "demo", "furnace", "simple"]
PACKAGE_ROOTS = ["settler", "fulldem", "popbal", "analysis"]
SHIPPED_DATA = ["cases", "properties", "thermo", "calibration"]  # data/reference stays in the repository
IGNORED = shutil.ignore_patterns(".git", "build", "dist", "*.egg-info", "__pycache__", "*.pyc", "runs",
                                 ".pytest_cache")


def _run(args, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([str(a) for a in args], capture_output=True, text=True, **kwargs)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel of a copy of the working tree (setuptools builds inside the source folder, and a stale build/lib of
    the checkout would ship files deleted since)."""
    import setuptools

    if int(setuptools.__version__.split(".")[0]) < 77:
        pytest.fail(f"building the wheel needs setuptools >= 77, this environment has {setuptools.__version__}: "
                    "pip install -e '.[test]'")
    tmp = tmp_path_factory.mktemp("wheel")
    source = tmp / "source"
    shutil.copytree(ROOT, source, ignore=IGNORED)
    out = tmp / "dist"
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
                  "--disable-pip-version-check", "-w", out, source])
    assert built.returncode == 0, built.stdout + built.stderr
    (path,) = out.glob("settler-*.whl")
    return path


def test_wheel_holds_every_package_and_the_data(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(ROOT).as_posix() for root in PACKAGE_ROOTS for p in (ROOT / root).rglob("*.py")
               if "__pycache__" not in p.parts}
    assert modules - names == set(), "modules missing from the wheel: add their packages to pyproject.toml"
    data = {p.relative_to(ROOT).as_posix() for folder in SHIPPED_DATA for p in (ROOT / "data" / folder).rglob("*")
            if p.is_file() and "__pycache__" not in p.parts}
    assert {f"data/cases/{n}.toml" for n in PRESETS} <= data
    assert {"settler/" + d for d in data} <= names
    assert not [n for n in names if n.startswith(("data/", "tests/", "settler/data/reference"))]


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory):
    """(environment for subprocesses, bin folder, work folder) of a fresh venv holding only the wheel's settler."""
    tmp = tmp_path_factory.mktemp("installed")
    env_dir = tmp / "venv"
    # Without pip of its own: this environment's pip (a system site package) installs into the venv's prefix.
    made = _run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", env_dir])
    assert made.returncode == 0, made.stderr
    bindir = env_dir / "bin"
    python = bindir / "python"
    # --ignore-installed: the editable settler of this environment is visible through the system site packages
    # and would otherwise count as "already installed".
    done = _run([python, "-m", "pip", "install", "--no-deps", "--no-index", "--ignore-installed",
                 "--disable-pip-version-check", wheel])
    assert done.returncode == 0, done.stdout + done.stderr
    env = {k: v for k, v in os.environ.items() if k not in ("SETTLER_DATA", "PYTHONPATH", "PYTHONHOME")}
    env["PATH"] = f"{bindir}{os.pathsep}{env.get('PATH', '')}"
    env["VIRTUAL_ENV"] = str(env_dir)
    work = tmp / "work"
    work.mkdir()
    return env, bindir, work, env_dir


def test_installed_copy_is_the_one_imported(installed):
    env, bindir, work, env_dir = installed
    shown = _run([bindir / "python", "-c", "import settler, settler.cases, settler.thermo\n"
                  "print(settler.__file__); print(settler.cases.DATA_DIR); print(settler.thermo.DEFAULT_MECHANISM)"],
                 cwd=work, env=env)
    assert shown.returncode == 0, shown.stderr
    module, data, mechanism = (Path(line) for line in shown.stdout.splitlines())
    site = next(env_dir.glob("lib/python*/site-packages"))
    assert module == site / "settler" / "__init__.py"  # not the checkout's (the editable finder does not shadow it)
    assert data == site / "settler" / "data"
    assert mechanism.is_file() and mechanism.is_relative_to(data)


def test_installed_commands_find_the_presets(installed):
    env, bindir, work, _ = installed
    cases = _run([bindir / "settler", "cases"], cwd=work, env=env)
    assert cases.returncode == 0, cases.stderr
    assert [line.split()[0] for line in cases.stdout.splitlines()] == PRESETS
    # deep has reactions on: its derived numbers read the thermodynamic data; simple names a calibration layer
    for name in ("demo", "deep", "simple"):
        info = _run([bindir / "settler", "info", name], cwd=work, env=env)
        assert info.returncode == 0, info.stderr
        assert "# derived numbers" in info.stdout
    version = _run([bindir / "python", "-m", "settler", "--version"], cwd=work, env=env)
    assert version.returncode == 0 and version.stdout.startswith("settler "), version.stderr


@pytest.mark.slow
def test_installed_full_run(installed):
    """The installed copy runs the full engine (`settler full demo`). Under ``-m slow``: Numba compiles the engine
    again in the installed copy, about 130 s on CI's 2 cores; the default run keeps the installed commands and data
    (above), and every fulldem test runs the same engine from the checkout."""
    env, bindir, work, _ = installed
    out = work / "out"
    run = _run([bindir / "settler", "full", "demo", "--out", out, "--end-time", "0.01", "--quiet"], cwd=work, env=env,
               timeout=900)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert (out / "timeseries.csv").is_file()


def test_every_dependency_is_imported():
    """Each runtime dependency is imported by the toolkit's own code (the five Jupyter packages listed before issue
    10 were not, and cost a new user 73 MB)."""
    import re
    import tomllib

    modules = {"numpy": "numpy", "scipy": "scipy", "numba": "numba", "pandas": "pandas", "matplotlib": "matplotlib",
               "cantera": "cantera", "meshio": "meshio", "tqdm": "tqdm", "dask": "(dask|distributed)"}
    # used by name, not imported: xarray's netCDF engine="h5netcdf" (analysis.runs) and the Jupyter kernel papermill
    # starts for a report (analysis.report)
    by_name = {"h5netcdf": ("analysis/runs.py", 'engine="h5netcdf"'), "ipykernel": ("analysis/report.py", "python3")}
    declared = [re.split(r"[<>=!~ \[]", d, maxsplit=1)[0]
                for d in tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]]
    source = "\n".join(p.read_text() for root in PACKAGE_ROOTS for p in (ROOT / root).rglob("*.py"))
    for name, (path, text) in by_name.items():
        assert text in (ROOT / path).read_text(), f"{name}: {path} no longer uses it ({text!r})"
    unused = [d for d in declared if d not in by_name
              and not re.search(rf"^\s*(import|from)\s+{modules.get(d, d.replace('-', '_'))}\b", source, re.M)]
    assert not unused, f"declared in pyproject.toml but never imported: {unused}"
