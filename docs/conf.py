"""Sphinx configuration of the settler documentation.

Sphinx rather than MkDocs: the API reference comes from the docstrings with autodoc, the command-line reference from
the argparse parser itself (sphinx-argparse), and the tutorial is a notebook executed at every build (myst-nb),
all in one tool; pages are Markdown (MyST). Build: ``sphinx-build -W -b html docs docs/_build/html`` (what
tests/test_docs.py runs, warnings as errors).
"""

import os
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

# The tutorial runs at every build; an error in a cell fails the build (never a logged failure and exit 0). The
# reports (rendered-reports/) run too when SETTLER_DOCS_REPORTS=1: minutes even in their quick mode on 2 cores, so
# the default build (and the test suite's) shows them unexecuted; tests/test_reports.py executes each in CI.
nb_execution_mode = "force"
nb_execution_excludepatterns = [] if os.environ.get("SETTLER_DOCS_REPORTS") == "1" else ["rendered-reports/*"]
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


#: Folder (in docs/, ignored by git) of the report notebooks the build writes from reports/*.py and executes.
REPORT_PAGES = "rendered-reports"


def write_reports(srcdir: Path) -> None:
    """Each report of reports/ (analysis.report.report_files) as a notebook in docs/rendered-reports/, with the
    cell papermill would inject after its parameters cell setting ``quick = True``: the build executes it (quick
    mode, seconds each) and renders it as a page. Unchanged notebooks are not rewritten."""
    import nbformat

    from analysis.report import INJECTED_TAG, PARAMETERS_TAG, read_report, report_files, title

    out = srcdir / REPORT_PAGES
    out.mkdir(exist_ok=True)
    wanted = set()
    for path in report_files():
        notebook = read_report(path)
        at = next(i for i, cell in enumerate(notebook.cells) if PARAMETERS_TAG in cell.metadata.get("tags", []))
        injected = nbformat.v4.new_code_cell("# quick mode for the documentation (settler report NAME "
                                             "--param quick=true renders the same)\nquick = True",
                                             metadata={"tags": [INJECTED_TAG]})
        notebook.cells.insert(at + 1, injected)
        if not title(notebook):
            notebook.cells.insert(0, nbformat.v4.new_markdown_cell(f"# {path.stem}"))
        notebook.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
        text = nbformat.writes(notebook)
        target = out / f"{path.stem}.ipynb"
        wanted.add(target.name)
        if not target.is_file() or target.read_text() != text:
            target.write_text(text)
    for stale in out.glob("*.ipynb"):
        if stale.name not in wanted:
            stale.unlink()


def write_generated(app):
    """Pages generated from the code before the build reads them: the case-key reference from the schema and the
    reports as notebooks."""
    from settler.cli import schema_markdown

    write_reports(Path(app.srcdir))

    out = Path(app.srcdir) / "_generated"
    out.mkdir(exist_ok=True)
    text = schema_markdown().replace("### [", "## [")
    target = out / "case_keys.md"
    if not target.is_file() or target.read_text() != text:  # unchanged: Sphinx need not reread the page
        target.write_text(text)


def setup(app):
    app.connect("builder-inited", write_generated)
