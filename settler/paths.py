"""Where the package's data lives: case presets, property sets and thermodynamic data.

The repository keeps them in its top-level ``data/`` folder; a wheel ships the same files as ``settler/data/``
(pyproject.toml maps the one onto the other). :data:`DATA_DIR` is, in this order:

1. the ``SETTLER_DATA`` environment variable, if set and not empty;
2. the checkout's ``data/``, when this module runs from a source checkout (editable install or the repository on
   ``sys.path``): the folder above the package holds ``pyproject.toml`` and ``data/``;
3. the copy installed beside the package, ``settler/data/``.

This module imports nothing heavy, so that :mod:`settler.thermo` and :mod:`settler.cases` share it cheaply.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent


def find_data_dir(environ: Mapping[str, str] | None = None, package_dir: Path = PACKAGE_DIR) -> tuple[Path, str]:
    """(data folder, where it came from in words) by the rules of this module's docstring."""
    environ = os.environ if environ is None else environ
    if environ.get("SETTLER_DATA"):
        return Path(environ["SETTLER_DATA"]), "the SETTLER_DATA environment variable"
    checkout = Path(package_dir).parent
    if (checkout / "pyproject.toml").is_file() and (checkout / "data").is_dir():
        return checkout / "data", f"the source checkout {checkout}"
    return Path(package_dir) / "data", "the installed package"


#: Folder of the property sets (properties/), case presets (cases/) and thermodynamic data (thermo/).
DATA_DIR, DATA_DIR_SOURCE = find_data_dir()


def preset_names(data_dir: Path | None = None) -> list[str]:
    """Names of the case presets in ``data_dir/cases`` (default :data:`DATA_DIR`; sorted; empty if none)."""
    return sorted(p.stem for p in (Path(data_dir or DATA_DIR) / "cases").glob("*.toml"))
