"""Sphinx configuration of the settler documentation.

Sphinx rather than MkDocs: the API reference comes from the docstrings with autodoc, the command-line reference from
the argparse parser itself (sphinx-argparse), and the tutorial is a notebook executed at every build (myst-nb),
all in one tool; pages are Markdown (MyST). Build: ``sphinx-build -W -b html docs docs/_build/html`` (what
tests/test_docs.py runs, warnings as errors).
"""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from settler import __version__  # noqa: E402

project = "settler"
author = "the settler developers"
copyright = "2026, the settler developers"  # noqa: A001 -- Sphinx's name
release = version = __version__

extensions = [
    "myst_nb",  # Markdown pages (MyST) and executed notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinxarg.ext",  # the command-line reference from settler.cli.build_parser
]
source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "_generated", "figures/*/README.md", "**/.ipynb_checkpoints"]
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]  # pages moved from the README start at their own level

# The tutorial runs at every build; an error in a cell fails the build (never a logged failure and exit 0).
nb_execution_mode = "force"
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "undoc-members": False}
napoleon_google_docstring = False
napoleon_numpy_docstring = True

html_theme = "furo"
html_title = f"settler {release}"
html_static_path = []


def write_generated(app):
    """Pages generated from the code before the build reads them: the case-key reference from the schema."""
    from settler.cli import schema_markdown

    out = Path(app.srcdir) / "_generated"
    out.mkdir(exist_ok=True)
    text = schema_markdown().replace("### [", "## [")
    target = out / "case_keys.md"
    if not target.is_file() or target.read_text() != text:  # unchanged: Sphinx need not reread the page
        target.write_text(text)


def setup(app):
    app.connect("builder-inited", write_generated)
