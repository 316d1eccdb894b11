"""Reports executed from notebooks: ``settler report NAME [--param key=value ...] --out DIR``.

A report is a notebook kept as text: a jupytext *percent* script ``reports/NAME.py`` (cells start at ``# %%``; text
in git, never outputs) with exactly one code cell tagged ``parameters`` (``# %% tags=["parameters"]``) that assigns
the report's parameters as plain literals (``quick = False``). Its first Markdown cell's first line is its title,
shown by ``settler report --list``. Adding a report is dropping such a file into ``reports/``.

:func:`render_report` converts the script with jupytext, executes it in a fresh Python kernel with papermill
(parameters injected after the parameters cell, an explicit per-cell timeout) and writes ``DIR/NAME.ipynb`` (the
executed notebook) and ``DIR/NAME.html`` (nbconvert's HTML exporter, figures embedded) atomically.

**Working folder.** The kernel runs in the output folder ``DIR``: whatever a report writes (reduced runs, CSV
tables, PNGs) lands beside its ``.ipynb`` and ``.html``, and a report never writes into the checkout. Reports find
the toolkit's data through :data:`settler.paths.DATA_DIR` (the checkout's ``data/``, ``$SETTLER_DATA``, or the
installed copy) rather than through relative paths. The kernel's environment has ``MPLBACKEND=Agg`` (figures need
no display) and, when the toolkit runs from a source checkout that is not installed, the checkout prepended to
``PYTHONPATH``, so ``import settler`` works in the kernel either way.

**Failures.** Any failure of any cell fails the command (exit status 3) with one line naming the cell (its number
among the report's cells, 1-based, and its first line) and the error: an exception (also in a cell tagged
``raises-exception``, which nbclient would let pass), ``sys.exit`` inside a cell, a cell over the timeout, a kernel
that dies (``os._exit``, a crash, killed for memory) or does not start. The partly executed notebook is then kept as
``DIR/NAME.failed.ipynb`` for its traceback, and ``NAME.ipynb`` / ``NAME.html`` are not written (those of an earlier
success are left as they were). Refused input exits 2, before any kernel starts: an unknown report, an unknown
parameter name (one not assigned in the parameters cell), a value that is neither a TOML literal nor a bare word (a
bare word is a string), or one not of the default's type.
"""

from __future__ import annotations

import ast
import contextlib
import math
import os
import re
import sys
import tomllib
from pathlib import Path

from settler.output import OutputError, atomic_write_text, prepare_output_folder

#: The report folder: the checkout's reports/ beside the analysis package, else the copy a wheel installs as
#: settler/reports/ (pyproject.toml maps the one onto the other).
REPORTS_DIR = next((folder for folder in (Path(__file__).resolve().parents[1] / "reports",
                                          Path(__file__).resolve().parents[1] / "settler" / "reports")
                    if folder.is_dir()), Path(__file__).resolve().parents[1] / "reports")
#: The cell tag that marks a report's parameters cell (papermill's convention).
PARAMETERS_TAG = "parameters"
#: The tag papermill gives the cell it inserts with the given parameters.
INJECTED_TAG = "injected-parameters"
#: The tag of the Markdown banners papermill adds to a notebook whose execution failed.
ERROR_BANNER_TAG = "papermill-error-cell-tag"
#: Default per-cell timeout [s] of ``settler report``.
DEFAULT_TIMEOUT = 600.0
#: How long [s] the kernel may take to start.
START_TIMEOUT = 120.0
#: Kernel the notebooks run in (jupyter_client starts it with this interpreter, sys.executable).
KERNEL_NAME = "python3"
#: Environment of the kernel, on top of this process's.
KERNEL_ENVIRONMENT = {"MPLBACKEND": "Agg"}


class ReportError(OutputError):
    """Refused input to a report (unknown report or parameter, a bad value); settler.cli exits 2 with the message."""


class ReportFailed(RuntimeError):
    """A report whose execution failed (a cell error, a timeout, a dead kernel); the message is one line."""


# ------------------------------------------------------------------------------------------------------- finding
def report_files(reports_dir=None) -> list[Path]:
    """The reports in ``reports_dir`` (default :data:`REPORTS_DIR`): ``*.py`` files that are percent scripts with
    a parameters cell, sorted by name."""
    folder = Path(reports_dir) if reports_dir is not None else REPORTS_DIR
    if not folder.is_dir():
        return []
    return [path for path in sorted(folder.glob("*.py")) if is_report(path)]


def is_report(path) -> bool:
    """Whether ``path`` is a jupytext percent script with a cell tagged ``parameters`` (read as text, not run)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return False
    return re.search(r'^# %%.*\btags\s*=\s*\[[^\]]*"parameters"', text, re.MULTILINE) is not None


def find_report(name, reports_dir=None) -> Path:
    """The script of report ``name``: a path to a ``.py`` file, or the name of one in ``reports_dir`` (default
    :data:`REPORTS_DIR`). Raises :class:`ReportError` naming what is available."""
    text = str(name)
    if text.endswith(".py") or os.sep in text or "/" in text:
        path = Path(text)
        if not path.is_file():
            raise ReportError(f"report {text!r}: no such file; give a report name ({_available(reports_dir)}) or a "
                              "path to a jupytext percent script")
    else:
        path = Path(reports_dir if reports_dir is not None else REPORTS_DIR) / f"{text}.py"
        if not path.is_file():
            raise ReportError(f"report {text!r}: no such report; allowed: {_available(reports_dir)}")
    if not is_report(path):
        raise ReportError(f"report {str(path)!r}: not a report: a jupytext percent script ('# %%' cells) with one "
                          'cell tagged parameters (# %% tags=["parameters"]) is needed')
    return path


def _available(reports_dir) -> str:
    names = [p.stem for p in report_files(reports_dir)]
    folder = Path(reports_dir) if reports_dir is not None else REPORTS_DIR
    return ", ".join(names) if names else f"none in {folder}"


def read_report(path):
    """The report script ``path`` as a notebook (nbformat NotebookNode, no outputs), read by jupytext."""
    import jupytext

    return jupytext.read(Path(path), fmt="py:percent")


def title(notebook) -> str:
    """The first line of the notebook's first Markdown cell, without heading marks ('' if it has none)."""
    for cell in notebook.cells:
        if cell.cell_type == "markdown":
            for line in cell.source.splitlines():
                if line.strip():
                    return line.strip().lstrip("#").strip()
    return ""


def list_reports(reports_dir=None) -> dict[str, str]:
    """Report name -> title (:func:`title`) of every report in ``reports_dir`` (default :data:`REPORTS_DIR`)."""
    return {path.stem: title(read_report(path)) for path in report_files(reports_dir)}


# ---------------------------------------------------------------------------------------------------- parameters
def parameters_cell(notebook, path="report") -> int:
    """Index of the notebook's one code cell tagged ``parameters``. Raises :class:`ReportError` if there is none
    or more than one."""
    found = [k for k, cell in enumerate(notebook.cells)
             if cell.cell_type == "code" and PARAMETERS_TAG in cell.metadata.get("tags", [])]
    if len(found) != 1:
        raise ReportError(f"{path}: {len(found)} code cells tagged {PARAMETERS_TAG!r}; a report needs exactly one")
    return found[0]


def parameter_defaults(notebook, path="report") -> dict:
    """Name -> default value of every name the parameters cell assigns at top level (``name = literal`` or
    ``name: type = literal``); a default that is not a Python literal is given as None (any value accepted)."""
    cell = notebook.cells[parameters_cell(notebook, path)]
    try:
        tree = ast.parse(cell.source)
    except SyntaxError as exc:
        raise ReportError(f"{path}: the parameters cell is not valid Python ({exc.msg}, line {exc.lineno})") from None
    defaults = {}
    for node in tree.body:
        if isinstance(node, ast.Assign):
            targets, value = node.targets, node.value
        elif isinstance(node, ast.AnnAssign) and node.value is not None:
            targets, value = [node.target], node.value
        else:
            continue
        try:
            literal = ast.literal_eval(value)
        except ValueError:
            literal = None
        for target in targets:
            if isinstance(target, ast.Name):
                defaults[target.id] = literal
    return defaults


def parse_value(key: str, text: str):
    """A ``--param`` value parsed as a TOML literal: numbers (``2``, ``0.5``, ``1e-3``), booleans (``true``,
    ``false``), quoted strings (``'"simple"'``), arrays (``'["simple", "deep"]'``). A bare word that TOML does not
    read (``simple``) is taken as that string; Python's ``True``/``False``/``None`` are refused with the TOML
    spelling. Raises :class:`ReportError` naming the key and the value."""
    try:
        return tomllib.loads(f"value = {text}")["value"]
    except tomllib.TOMLDecodeError:
        pass
    if text in ("True", "False", "None"):
        raise ReportError(f"--param {key}={text}: not a TOML literal; allowed: true or false (lower case), numbers, "
                          'quoted strings ("text"), arrays ([1, 2])')
    if re.fullmatch(r"[A-Za-z_][\w.\-/]*", text):
        return text
    raise ReportError(f"--param {key}={text}: not a TOML literal; allowed: numbers (2, 0.5), booleans (true, "
                      'false), quoted strings ("text"), arrays ([1, 2])')


def _type_name(value) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "an array"}.get(
        type(value), type(value).__name__)


def check_parameters(parameters: dict, defaults: dict, report="report") -> dict:
    """``parameters`` checked against the report's ``defaults``: every name must be one of them and every value of
    its default's type (an integer where a number is expected is converted; a default of None takes anything).
    Returns the checked values; raises :class:`ReportError` naming the key, the value and what is allowed."""
    checked = {}
    for key, value in parameters.items():
        if key not in defaults:
            raise ReportError(f"--param {key}={value!r}: {report} has no parameter {key!r}; allowed: "
                              + (", ".join(defaults) if defaults else "none"))
        default = defaults[key]
        if default is not None:
            if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
                value = float(value)
            if type(value) is not type(default) and not (isinstance(default, (list, tuple))
                                                         and isinstance(value, (list, tuple))):
                raise ReportError(f"--param {key}={value!r}: allowed: {_type_name(default)} (the default is "
                                  f"{default!r})")
            if isinstance(value, float) and not math.isfinite(value):
                raise ReportError(f"--param {key}={value!r}: allowed: a finite number")
        checked[key] = value
    return checked


def parse_parameters(pairs, defaults: dict, report="report") -> dict:
    """``key=value`` strings (the ``--param`` options) -> checked values (:func:`parse_value`,
    :func:`check_parameters`). A key given twice takes the last value."""
    parsed = {}
    for pair in pairs or []:
        key, sep, text = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ReportError(f"--param {pair!r}: allowed: key=value, the key one of: " + ", ".join(defaults))
        parsed[key] = parse_value(key, text.strip())
    return check_parameters(parsed, defaults, report)


# ------------------------------------------------------------------------------------------------------ executing
def _source_root() -> Path | None:
    """The source checkout this toolkit runs from (the folder holding pyproject.toml and the settler package), or
    None when it runs as an installed package."""
    import settler

    root = Path(settler.__file__).resolve().parents[1]
    return root if (root / "pyproject.toml").is_file() and (root / "analysis").is_dir() else None


@contextlib.contextmanager
def kernel_environment():
    """This process's environment set up for the kernel it starts (:data:`KERNEL_ENVIRONMENT`, and the source
    checkout first on PYTHONPATH), restored afterwards. jupyter_client passes os.environ on to the kernel."""
    saved = {key: os.environ.get(key) for key in (*KERNEL_ENVIRONMENT, "PYTHONPATH")}
    try:
        os.environ.update(KERNEL_ENVIRONMENT)
        root = _source_root()
        if root is not None:
            rest = os.environ.get("PYTHONPATH", "")
            os.environ["PYTHONPATH"] = str(root) + (os.pathsep + rest if rest else "")
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def _cell_label(notebook, index: int) -> str:
    """'cell N (first line)' for the executed notebook's cell ``index``, N counting the report's own cells from 1
    (papermill's injected parameters cell and its error banners are not among them)."""
    cells = notebook.cells
    added = sum(1 for cell in cells[:index] if _added_by_papermill(cell))
    cell = cells[index]
    first = next((line.strip() for line in cell.source.splitlines() if line.strip()), "")
    if len(first) > 60:
        first = first[:57] + "..."
    what = "the injected parameters cell" if INJECTED_TAG in cell.metadata.get("tags", []) else \
        f"cell {index + 1 - added}"
    return f"{what} ({first})" if first else what


def _added_by_papermill(cell) -> bool:
    """Whether papermill added ``cell`` (the injected parameters, an error banner)."""
    return bool({INJECTED_TAG, ERROR_BANNER_TAG} & set(cell.metadata.get("tags", [])))


def _one_line(text) -> str:
    text = re.sub(r"\x1b\[[0-9;]*m", "", str(text))  # ANSI colours of IPython's tracebacks
    text = " ".join(text.split())
    return text if len(text) <= 300 else text[:297] + "..."


def first_error(notebook) -> tuple[int, str] | None:
    """(cell index, 'EName: value') of the first error output of an executed notebook, or None. Also finds errors
    that nbclient lets pass (a cell tagged raises-exception) and ``sys.exit(0)``, which papermill lets pass."""
    for index, cell in enumerate(notebook.cells):
        for output in cell.get("outputs", []):
            if output.get("output_type") == "error":
                return index, f"{output.get('ename', 'Error')}: {output.get('evalue', '')}"
    return None


def unfinished_cell(notebook) -> int | None:
    """Index of the first non-empty code cell the kernel did not answer (no ``shell.execute_reply`` time in its
    metadata: the cell running when the kernel died or timed out, or one never reached), or None. (papermill's own
    status marks are no guide: after such a failure it marks every cell completed.)"""
    for index, cell in enumerate(notebook.cells):
        if cell.cell_type == "code" and cell.source.strip() and \
                "shell.execute_reply" not in cell.metadata.get("execution", {}):
            return index
    return None


def failed_cell(notebook) -> int | None:
    """Index of the cell where an execution failed: the first with an error output, else :func:`unfinished_cell`."""
    error = first_error(notebook)
    return error[0] if error is not None else unfinished_cell(notebook)


def _failure(exc, partial: Path, timeout: float) -> str:
    """The one-line reason of a failed execution: which cell (:func:`failed_cell` of the notebook papermill saved
    at ``partial``), what error."""
    from nbclient.exceptions import CellTimeoutError, DeadKernelError
    from papermill.exceptions import PapermillExecutionError

    saved = _read(partial)
    index = failed_cell(saved) if saved is not None else None
    where = _cell_label(saved, index) if index is not None else "a cell"
    if index is None and getattr(exc, "source", None):
        first = next((line.strip() for line in exc.source.splitlines() if line.strip()), "")
        where = f"the cell starting {first[:60]!r}"
    if isinstance(exc, PapermillExecutionError):
        return f"{where} failed: {exc.ename}: {_one_line(exc.evalue)}"
    if isinstance(exc, CellTimeoutError):
        return f"{where} ran longer than the per-cell timeout of {timeout:g} s"
    if isinstance(exc, DeadKernelError):
        return f"the kernel died during {where} ({_one_line(exc) or 'no reason given'})"
    return f"{where}: {type(exc).__name__}: {_one_line(exc)}"


def execute(notebook, parameters: dict, cwd: Path, timeout: float, partial: Path, progress: bool = False):
    """Execute ``notebook`` with papermill in a fresh kernel in folder ``cwd`` (per-cell ``timeout`` [s]), saving it
    to ``partial`` as it goes. Returns the executed notebook; raises :class:`ReportFailed` (one line) on any
    failure."""
    import papermill

    try:
        with kernel_environment():
            executed = papermill.execute_notebook(
                notebook, str(partial), parameters=parameters, kernel_name=KERNEL_NAME, language="python",
                cwd=str(cwd), progress_bar=progress, log_output=False, execution_timeout=timeout,
                start_timeout=START_TIMEOUT)
    except KeyboardInterrupt:
        raise
    except Exception as exc:  # noqa: BLE001 -- every failure of the execution is reported in one line
        raise ReportFailed(_failure(exc, partial, timeout)) from exc
    error = first_error(executed)
    if error is not None:
        raise ReportFailed(f"{_cell_label(executed, error[0])} failed: {_one_line(error[1])}")
    missing = unfinished_cell(executed)
    if missing is not None:
        raise ReportFailed(f"{_cell_label(executed, missing)} was not executed")
    return executed


def _read(path: Path):
    import nbformat

    try:
        return nbformat.read(path, as_version=4)
    except Exception:  # noqa: BLE001 -- not written yet, or partly
        return None


def jupyter_data_folders() -> list[str]:
    """Jupyter data folders (PREFIX/share/jupyter) of this interpreter's prefix and its base prefix, where they hold
    nbconvert's templates. Jupyter's search path holds only this environment's prefix, so a virtual environment that
    takes nbconvert from the system's site packages (``python -m venv --system-site-packages``) would not find them
    ("No template sub-directory with name 'lab'")."""
    folders = []
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix)):
        folder = Path(prefix) / "share" / "jupyter"
        if (folder / "nbconvert" / "templates").is_dir():
            folders.append(str(folder))
    return folders


def to_html(notebook) -> str:
    """The executed notebook as a standalone HTML page (nbconvert's HTML exporter; figures embedded)."""
    from nbconvert import HTMLExporter

    saved = os.environ.get("JUPYTER_PATH")
    os.environ["JUPYTER_PATH"] = os.pathsep.join([p for p in (saved or "").split(os.pathsep) if p]
                                                 + jupyter_data_folders())
    try:
        body, _ = HTMLExporter().from_notebook_node(notebook)
    finally:
        if saved is None:
            os.environ.pop("JUPYTER_PATH", None)
        else:
            os.environ["JUPYTER_PATH"] = saved
    return body


def render_report(name, out, parameters: dict | None = None, timeout: float = DEFAULT_TIMEOUT, reports_dir=None,
                  progress: bool = False) -> dict[str, Path]:
    """Execute report ``name`` (a name in ``reports_dir``, default :data:`REPORTS_DIR`, or a path to a percent
    script) with ``parameters`` (name -> value, checked against the parameters cell) in a fresh kernel working in
    the folder ``out`` (created), each cell within ``timeout`` [s]; write ``out/NAME.ipynb`` and ``out/NAME.html``
    atomically. Returns {"ipynb": path, "html": path}.

    Raises :class:`ReportError` (refused input) or :class:`ReportFailed` (execution failed; the partly executed
    notebook is then ``out/NAME.failed.ipynb``).
    """
    if not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
        raise ReportError(f"--timeout {timeout!r}: allowed: a finite number of seconds > 0")
    path = find_report(name, reports_dir)
    notebook = read_report(path)
    checked = check_parameters(dict(parameters or {}), parameter_defaults(notebook, path), path.stem)
    folder = prepare_output_folder(out, resume=True).resolve()
    stem = path.stem
    partial = folder / f".{stem}.running.ipynb"
    failed = folder / f"{stem}.failed.ipynb"
    try:
        executed = execute(notebook, checked, folder, float(timeout), partial, progress)
    except ReportFailed as exc:
        if partial.is_file():
            os.replace(partial, failed)
            raise ReportFailed(f"{exc} (partly executed notebook: {failed}; {stem}.ipynb and {stem}.html not "
                               "written)") from exc.__cause__
        raise
    finally:
        if partial.exists():
            partial.unlink()
    import nbformat

    written = {"ipynb": folder / f"{stem}.ipynb", "html": folder / f"{stem}.html"}
    atomic_write_text(written["ipynb"], nbformat.writes(executed))
    atomic_write_text(written["html"], to_html(executed))
    if failed.exists():
        failed.unlink()  # an earlier failure's notebook, now out of date
    return written


# ------------------------------------------------------------------------------------------ inside the notebooks
#: Resolution of the figures :func:`show` puts into a report [dots per inch].
FIGURE_DPI = 100


def show(fig, dpi: int = FIGURE_DPI) -> None:
    """Display a matplotlib Figure in a report as a PNG and release it. The kernel runs with the Agg backend, which
    displays nothing by itself; figures made without pyplot (:mod:`analysis.figures`) have no other way in."""
    import io

    from IPython.display import Image, display

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    display(Image(data=buffer.getvalue(), format="png"))
    fig.clear()


# ---------------------------------------------------------------------------------------------------- command line
def _timeout(text: str) -> float:
    from settler.arguments import seconds

    return seconds("--timeout")(text)


def add_arguments(parser) -> None:
    """Arguments of ``settler report``."""
    parser.add_argument("name", nargs="?", default=None,
                        help="the report: a name from reports/ (see --list) or a path to a jupytext percent script "
                             "with a parameters cell; without it the reports are listed")
    parser.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                        help="set a parameter of the report's parameters cell (repeatable); VALUE is a TOML literal: "
                             '2, 0.5, true, "text" (a bare word is a string), ["a", "b"]; a name the parameters '
                             "cell does not assign is refused")
    parser.add_argument("--out", metavar="DIR", default=None,
                        help="output folder (created): NAME.ipynb and NAME.html are written there, and the notebook "
                             "runs there, so its own files (runs, tables, figures) land there too; required with "
                             "NAME")
    parser.add_argument("--timeout", type=_timeout, default=DEFAULT_TIMEOUT, metavar="S",
                        help=f"per-cell time limit [s] (default {DEFAULT_TIMEOUT:g}); a cell over it fails the report")
    parser.add_argument("--list", action="store_true", help="list the reports with their titles and exit")
    parser.add_argument("--reports", metavar="DIR", default=None,
                        help=f"folder of the reports (default: the checkout's reports/, {REPORTS_DIR})")
    parser.add_argument("--quiet", action="store_true", help="no progress bar over the cells")


def _print_list(reports_dir) -> int:
    reports = list_reports(reports_dir)
    if not reports:
        folder = Path(reports_dir) if reports_dir is not None else REPORTS_DIR
        raise ReportError(f"--reports {folder}: no reports there (jupytext percent scripts with a parameters cell); "
                          "run from a source checkout, or give --reports")
    width = max(len(name) for name in reports)
    for name, text in reports.items():
        print(f"{name:<{width}s}  {text}")
    return 0


def main(args) -> int:
    """``settler report``: exit status 0 written, 2 refused input, 3 the report failed (one-line reason)."""
    from .extras import require

    require("jupytext", "papermill", "nbconvert", "nbformat", "ipykernel")
    if args.list or args.name is None:
        return _print_list(args.reports)
    if args.out is None:
        raise ReportError("--out: missing; give the folder to write NAME.ipynb and NAME.html into")
    path = find_report(args.name, args.reports)
    defaults = parameter_defaults(read_report(path), path)
    parameters = parse_parameters(args.param, defaults, path.stem)
    try:
        written = render_report(path, args.out, parameters, args.timeout, args.reports, progress=not args.quiet)
    except ReportFailed as exc:
        print(f"settler report: error: {path.stem}: {exc}", file=sys.stderr)
        return 3
    print(f"settler report {path.stem}: wrote {written['ipynb']} and {written['html']}")
    return 0
