"""The house's rules, read from the source with ``ast`` (docs/architecture.md).

* no import cycle among the modules of ``cosim`` and ``fmu_src`` (imports inside functions
  count: a lazy import is still a dependency; ``if TYPE_CHECKING:`` blocks do not, they never run);
* the layers: ``fmu_src`` imports nothing of ``cosim``; the master imports neither the peers,
  the applications nor the command line; the peers no application; no library module imports a
  command-line module (``cosim.cli`` and the shims);
* argparse only in ``cosim/cli.py``; no ``sys.path`` edit, argparse or benchmark in ``fmu_src``.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("cosim", "fmu_src")
#: the command-line modules: the one command line, its shims and ``python -m cosim``
COMMAND_LINE = {"cosim.cli", "cosim.__main__", "cosim.run", "cosim.study", "cosim.calibrate", "cosim.report"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for package in PACKAGES for p in sorted((ROOT / package).rglob("*.py"))}


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """Modules of the two packages that module ``name`` imports (resolved; runtime imports only)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def visit(node):
        if isinstance(node, ast.If) and _is_type_checking(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.add(alias.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in known else target)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    out = set()
    for target in found:
        # the module itself, or the nearest enclosing module of ours (a name imported from it)
        while target and target not in known:
            target = target.rpartition(".")[0]
        if target and target != name:
            out.add(target)
    return out


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    mods = modules()
    known = set(mods)
    return {name: imports(name, path, known) for name, path in mods.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (as a path that returns to its start), or None."""
    WHITE, GREY, BLACK = 0, 1, 2
    colour = {n: WHITE for n in graph}
    stack: list[str] = []

    def dfs(n):
        colour[n] = GREY
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if colour.get(m, BLACK) == GREY:
                return stack[stack.index(m):] + [m]
            if colour.get(m) == WHITE:
                cycle = dfs(m)
                if cycle:
                    return cycle
        stack.pop()
        colour[n] = BLACK
        return None

    for n in sorted(graph):
        if colour[n] == WHITE:
            cycle = dfs(n)
            if cycle:
                return cycle
    return None


def test_the_cycle_finder_finds_a_cycle():
    # the oracle first: a graph with a circle, one without
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_the_graph_sees_relative_lazy_and_package_imports(graph):
    assert "cosim.master.guard" in graph["cosim.master.coupling.adaptive"]          # from ..guard import
    assert "cosim.master.system" not in graph["cosim.master.coupling.adaptive"]     # TYPE_CHECKING only
    assert "fmu_src.contact_laws" in graph["fmu_src.resolver"]                      # from .contact_laws import
    assert "cosim.apps.report" in graph["cosim.cli"]                                # lazy, inside a function


def test_no_import_cycle(graph):
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def layer(name: str) -> str:
    if name.startswith("fmu_src"):
        return "physics"
    if name in COMMAND_LINE:
        return "command line"
    for part in ("master", "peers", "apps"):
        if name.startswith(f"cosim.{part}"):
            return part
    return "base"          # cosim, cosim.fmus, cosim.files


#: what each layer may import (besides itself)
ALLOWED = {
    "physics": {"physics"},
    "base": {"base", "physics"},
    "master": {"master", "base", "physics"},
    "peers": {"peers", "master", "base", "physics"},
    "apps": {"apps", "peers", "master", "base", "physics"},
    "command line": {"command line", "apps", "peers", "master", "base", "physics"},
}


def test_layers(graph):
    wrong = [f"{a} ({layer(a)}) imports {b} ({layer(b)})" for a, targets in graph.items() for b in targets
             if layer(b) not in ALLOWED[layer(a)]]
    assert not wrong, "\n".join(wrong)


def test_no_library_module_imports_a_command_line_module(graph):
    wrong = [(a, b) for a, targets in graph.items() if a not in COMMAND_LINE for b in targets if b in COMMAND_LINE]
    assert not wrong


def _imports_module(path: Path, module: str) -> bool:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == module for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == module and not node.level:
            return True
    return False


def test_argparse_only_in_the_command_line_module():
    users = sorted(name for name, path in modules().items() if _imports_module(path, "argparse"))
    assert users == ["cosim.cli"]


def test_fmu_src_has_no_command_line_no_benchmark_no_sys_path_edit():
    for name, path in modules().items():
        if not name.startswith("fmu_src"):
            continue
        text = path.read_text(encoding="utf-8")
        assert "sys.path" not in text, name
        assert not _imports_module(path, "argparse"), name
        assert "__main__" not in text and "def benchmark" not in text and "perf_counter" not in text, name
        assert not _imports_module(path, "cosim"), name
