"""The layout: imports point one way, with no circles, and no source file outgrows its concept.

Every import statement of the project's packages is read from the source (those inside functions too, which run
later but tie the files together all the same) and resolved to the file it names: ``from a.b import c`` names
``a/b/c.py`` (or the package ``a/b/c/``) when that is a module, else ``a/b.py`` or ``a/b/__init__.py``. The package
a file sits in is not counted as imported by it (Python runs ``__init__.py`` first, but that is not an edge the
file chose). The rules, from shared/STYLE.md and the layout issue:

* no cycle between files;
* ``settler`` (the shared layer) imports neither engine nor ``analysis``; ``fulldem`` and ``popbal`` do not import
  each other; neither engine imports ``analysis``;
* no source file in ``fulldem/`` or ``analysis/`` is longer than :data:`MAX_LINES` lines.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("settler", "fulldem", "popbal", "analysis")
#: (importer, imported) package pairs that must not occur.
FORBIDDEN = {("settler", "fulldem"), ("settler", "popbal"), ("settler", "analysis"), ("fulldem", "popbal"),
             ("popbal", "fulldem"), ("fulldem", "analysis"), ("popbal", "analysis")}
MAX_LINES = 650


def _module_of(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _file_of(module: str) -> Path | None:
    base = ROOT.joinpath(*module.split("."))
    if base.with_suffix(".py").is_file():
        return base.with_suffix(".py")
    if (base / "__init__.py").is_file():
        return base / "__init__.py"
    return None


def source_files() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def imports_of(path: Path) -> list[tuple[int, Path]]:
    """(line, file) of every project file the source of ``path`` imports, at any depth of the code."""
    module = _module_of(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([node.module] if node.module else []))
            else:
                base = node.module
            names = []
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                names.append(sub if _file_of(sub) is not None else base)
        else:
            continue
        for name in names:
            if name.split(".")[0] not in PACKAGES:
                continue
            target = _file_of(name)
            if target is None:  # an attribute path such as a.b.c where c is a name: the deepest module named
                parts = name.split(".")
                while parts and _file_of(".".join(parts)) is None:
                    parts.pop()
                target = _file_of(".".join(parts)) if parts else None
            if target is not None and target != path:
                found.append((node.lineno, target))
    return found


def import_graph() -> dict[Path, list[tuple[int, Path]]]:
    return {path: imports_of(path) for path in source_files()}


def cycles(graph) -> list[list[Path]]:
    """The strongly connected components with more than one file (Tarjan), each a list of files."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for _, w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def test_the_graph_sees_function_level_and_relative_imports():
    """The parser itself, on files whose imports are known (absolute and relative), and the cycle finder on a
    graph whose one circle is known."""
    edges = {_rel(target) for _, target in imports_of(ROOT / "fulldem" / "stepper.py")}
    assert "fulldem/dem/stepper.py" in edges and "fulldem/droplets.py" in edges
    assert "settler/physics/__init__.py" in edges
    inner = {_rel(t) for _, t in imports_of(ROOT / "fulldem" / "dem" / "integrators.py")}
    assert "fulldem/dem/pairs.py" in inner  # from .pairs import ...
    # a function-level import is an edge too: a cycle made of them would be found
    assert cycles({"a": [(1, "b")], "b": [(9, "a")], "c": [(1, "a")]}) == [["a", "b"]]


def test_no_import_cycles():
    found = cycles(import_graph())
    assert not found, "import cycles between files:\n" + "\n".join(" <-> ".join(map(_rel, c)) for c in found)


def test_imports_point_one_way():
    bad = []
    for path, edges in import_graph().items():
        src = path.relative_to(ROOT).parts[0]
        for line, target in edges:
            dst = target.relative_to(ROOT).parts[0]
            if (src, dst) in FORBIDDEN:
                bad.append(f"{_rel(path)}:{line} imports {_rel(target)} ({src} -> {dst})")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("package", ["fulldem", "analysis"])
def test_no_source_file_outgrows_its_concept(package):
    long = {_rel(p): n for p in (ROOT / package).rglob("*.py") if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"longer than {MAX_LINES} lines: {long}"


@pytest.mark.parametrize("folder", sorted({p.parent for pkg in ("fulldem", "analysis")
                                           for p in (ROOT / pkg).rglob("__init__.py")}), ids=_rel)
def test_each_folder_says_what_belongs_in_it(folder):
    doc = ast.get_docstring(ast.parse((folder / "__init__.py").read_text()))
    assert doc and len(doc.split()) >= 12, f"{_rel(folder)}/__init__.py has no docstring saying what goes there"
