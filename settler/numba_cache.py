"""Numba's on-disk cache, kept in a folder per version of the toolkit's source.

Numba checks a cached kernel against its own file's time stamp only. A kernel that calls or inlines a function of
*another* file (the DEM kernels call ``fulldem.dem.laws`` and ``settler.physics``) is therefore not recompiled when
only that other file changes: it keeps running the old code. Measured 2026-12-01: the demo's DEM kernels, loaded from
a cache filled before an edit elsewhere, gave forces differing by 1e-18 N from a fresh compilation of the same
source; a changed law would have been silently ignored.

So the cache lives in ``<base>/<digest>``, the digest a hash of every ``.py`` file of the packages that hold kernels
(settler, fulldem, popbal): any edit, or another installed version, compiles into a fresh folder, and unchanged
sources reuse theirs. ``<base>`` is ``$NUMBA_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/settler/numba`` (default
``~/.cache/settler/numba``). The :data:`KEEP` most recently used folders are kept, older ones removed. Child
processes (tests, parallel sweeps) inherit the choice through the environment and compute the same digest.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

#: Packages whose sources make up the digest (those with Numba kernels, and what they import).
PACKAGES = ("settler", "fulldem", "popbal")
#: Cache folders (source versions) kept under the base; older ones are removed.
KEEP = 4
#: Environment variable remembering the base folder (NUMBA_CACHE_DIR is set to the versioned folder).
BASE_VARIABLE = "SETTLER_NUMBA_CACHE_BASE"


def source_digest(root: Path | None = None) -> str:
    """A hash of the ``.py`` files of :data:`PACKAGES` (their relative paths and contents) [16 hex digits]."""
    root = Path(__file__).resolve().parents[1] if root is None else Path(root)
    digest = hashlib.sha256()
    for package in PACKAGES:
        folder = root / package
        if not folder.is_dir():
            continue
        for path in sorted(folder.rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def base_folder() -> Path:
    """The folder holding one cache folder per source version (see the module docstring)."""
    for variable in (BASE_VARIABLE, "NUMBA_CACHE_DIR"):
        if os.environ.get(variable):
            return Path(os.environ[variable])
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(xdg) / "settler" / "numba"


def _prune(base: Path, current: Path) -> None:
    try:
        folders = [p for p in base.iterdir() if p.is_dir() and p != current and len(p.name) == 16]
    except OSError:
        return
    folders.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    for old in folders[KEEP - 1:]:
        shutil.rmtree(old, ignore_errors=True)


def configure() -> Path | None:
    """Point Numba's cache at this source version's folder (before or after numba is imported); returns it, or
    None where no folder can be made (Numba then keeps its own default)."""
    base = base_folder()
    folder = base / source_digest()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        os.utime(folder)  # most recently used
    except OSError:
        return None
    os.environ[BASE_VARIABLE] = str(base)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    import sys

    if "numba" in sys.modules:  # numba read its configuration at import: set it there too
        sys.modules["numba"].config.CACHE_DIR = str(folder)
    _prune(base, folder)
    return folder
