"""The optional dependencies of the analysis commands, installed as extras (pyproject.toml): ``sweep``
(dask.distributed for parallel points, SALib for sampled designs and sensitivity) and ``reports`` (jupytext,
papermill, nbconvert and a Jupyter kernel). A command that needs one that is missing stops with one line saying
what to install (exit status 2), never an ImportError traceback."""

from __future__ import annotations

import importlib

from settler.errors import OutputError

#: Module -> (the extra that installs it, what needs it).
EXTRAS = {"distributed": ("sweep", "a sweep on worker processes or a dask cluster (--workers 0 needs none)"),
          "SALib": ("sweep", "sampled designs (lhs, sobol, morris) and their sensitivity analysis"),
          "jupytext": ("reports", "reports"), "papermill": ("reports", "reports"),
          "nbconvert": ("reports", "reports"), "nbformat": ("reports", "reports"), "ipykernel": ("reports", "reports")}


def require(*modules: str) -> None:
    """Raise OutputError naming the extra to install if any of ``modules`` (keys of :data:`EXTRAS`) is missing."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            extra, what = EXTRAS[module]
            raise OutputError(f"{what} needs the Python package {module!r}, which is not installed; allowed: install "
                              f"the '{extra}' extra: pip install 'settler[{extra}]' (or -e '.[{extra}]' in a "
                              "checkout)") from None
