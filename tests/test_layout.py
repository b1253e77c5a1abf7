"""The package's layout holds (issue 15): no import cycle among `app`'s modules, no module over 600 lines
unless its docstring says why, the pure core free of the simulator and the UI, and README's layout table
matching the tree.

Imports are read with `ast`, so an import inside a function counts as much as one at the top: a lazy
import hides a cycle from the interpreter, not from a reader.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
APP = ROOT / "app"
MAX_LINES = 600
WHY_LONG = "Over 600 lines because"


def module_files(root: Path = APP) -> dict[str, Path]:
    """Dotted module name → file, for every ``.py`` under ``root`` (packages by their ``__init__``)."""
    out = {}
    for f in sorted(root.rglob("*.py")):
        parts = list(f.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def _resolve(name: str, mods: dict[str, Path]) -> str | None:
    """The project module ``name`` refers to (its longest known prefix), or None outside the project."""
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Module → the project modules it imports anywhere in its body (``from a import b`` names ``a.b``
    when ``b`` is a module, else ``a``). Importing a package's submodule is not counted as importing
    the package itself: Python runs the ``__init__`` first, but that is not a dependency of the code."""
    graph: dict[str, set[str]] = {}
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        deps: set[str] = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                deps.update(r for a in node.names if (r := _resolve(a.name, mods)))
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    name = ".".join(base + ([node.module] if node.module else []))
                else:
                    name = node.module or ""
                for a in node.names:
                    r = _resolve(f"{name}.{a.name}", mods) or _resolve(name, mods)
                    if r:
                        deps.add(r)
        deps.discard(mod)
        graph[mod] = deps
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in graph:
                    continue
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def test_the_cycle_finder_finds_a_known_cycle_and_passes_a_dag() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_the_import_walker_sees_imports_inside_functions(tmp_path: Path) -> None:
    pkg = tmp_path / "app"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    from app.sub import b\n")
    (pkg / "sub" / "b.py").write_text("from .. import a\n")
    graph = import_graph(module_files(pkg))
    assert graph["app.a"] == {"app.sub.b"} and graph["app.sub.b"] == {"app.a"}
    assert cycles(graph) == [["app.a", "app.sub.b"]]


def test_no_import_cycle_among_the_project_modules() -> None:
    found = cycles(import_graph(module_files()))
    assert not found, "import cycles: " + "; ".join(" ↔ ".join(c) for c in found)


def test_no_module_over_600_lines_unless_its_docstring_says_why() -> None:
    long = []
    for mod, path in module_files().items():
        n = len(path.read_text(encoding="utf-8").splitlines())
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
        if n > MAX_LINES and WHY_LONG not in doc:
            long.append(f"{mod} ({n} lines)")
    assert not long, "modules over 600 lines with no reason in their docstring: " + ", ".join(long)


@pytest.mark.parametrize("forbidden", ["pybullet", "viser"])
def test_the_core_imports_neither_the_simulator_nor_the_ui(forbidden: str) -> None:
    bad = []
    for mod, path in module_files().items():
        if not mod.startswith("app.ocslam"):
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and not node.level:
                names = [node.module or ""]
            if any(n == forbidden or n.startswith(forbidden + ".") for n in names):
                bad.append(mod)
    assert not bad, f"app/ocslam imports {forbidden}: {sorted(set(bad))}"


def _readme_layout_paths() -> list[str]:
    """The ``app/...`` paths in the first column of README's layout table (one or more per row)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    paths = []
    for line in section.splitlines():
        if line.startswith("|"):
            first_cell = line.split("|")[1]
            paths += [p.rstrip("/") for p in re.findall(r"`(app/[^`]*)`", first_cell)]
    return paths


def test_readme_layout_table_matches_the_tree() -> None:
    listed = _readme_layout_paths()
    assert listed, "README has no layout table under '## Layout'"
    missing = [p for p in listed if not (ROOT / p).exists() and not (ROOT / (p + ".py")).exists()]
    assert not missing, f"README's layout table names paths that do not exist: {missing}"
    # every top-level module and package of app/, and every package below it, has a row
    entries = {p.relative_to(ROOT).as_posix() for p in APP.iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    entries |= {p.parent.relative_to(ROOT).as_posix() for p in APP.rglob("__init__.py")}
    entries -= {"app/__init__.py", "app/__main__.py", "app"}
    covered = set(listed)
    unlisted = sorted(e for e in entries if e not in covered and e.removesuffix(".py") not in covered)
    assert not unlisted, f"README's layout table lacks rows for: {unlisted}"
