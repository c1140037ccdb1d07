"""The report package's structure (issue #30): imports go one way (no cycle, no module importing the
package that imports it), modules stay small, imports sit at the top of modules (the package is
loaded only when `diegocal report` runs, so nothing in it needs deferring), every plot is a
``(result, ax=None) -> Axes`` function."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import diegocal.report

PACKAGE = Path(diegocal.report.__file__).parent
MODULES = {f"diegocal.report.{p.stem}" if p.stem != "__init__" else "diegocal.report": p for p in PACKAGE.glob("*.py")}
MAX_LINES = 500


def _imports(path: Path) -> list[tuple[str, bool]]:
    """(imported module, whether the import is inside a function) of every import in ``path``;
    ``from diegocal.report import x`` imports the package (its ``__init__``)."""
    tree = ast.parse(path.read_text())
    local = {
        id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)) for n in ast.walk(f)
    }
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, id(node) in local) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.append((node.module, id(node) in local))
    return out


def _graph() -> dict[str, set[str]]:
    return {name: {m for m, _ in _imports(path) if m in MODULES and m != name} for name, path in MODULES.items()}


def test_imports_inside_the_package_go_one_way():
    graph = _graph()
    for name, deps in graph.items():
        if name != "diegocal.report":
            assert "diegocal.report" not in deps, f"{name} imports the package that imports it"
    done, stack = set(), []

    def visit(name):
        assert name not in stack, "import cycle: " + " -> ".join([*stack[stack.index(name) :], name])
        if name in done:
            return
        stack.append(name)
        for dep in sorted(graph[name]):
            visit(dep)
        stack.pop()
        done.add(name)

    for name in sorted(graph):
        visit(name)


def test_modules_are_small():
    long = {p.name: n for p in MODULES.values() if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_no_function_local_imports():
    """The package is imported only inside `diegocal report`'s command (and `batch --report`): its
    modules import at the top, where a reader sees what each depends on."""
    local = {p.name: sorted({m for m, inside in _imports(p) if inside}) for p in MODULES.values()}
    assert not {k: v for k, v in local.items() if v}, local


def test_the_command_defers_the_report_for_start_up_and_says_so():
    """`diegocal report`'s module imports the report (matplotlib) inside the command, so that
    `diegocal --help` does not load it; one comment says why."""
    source = (PACKAGE.parent / "cli" / "report_cmd.py").read_text()
    top = [m for m, inside in _imports(PACKAGE.parent / "cli" / "report_cmd.py") if not inside]
    assert not [m for m in top if m.startswith("diegocal.report") or m.startswith("matplotlib")], top
    assert "start-up" in source


def test_every_plot_takes_an_axes_and_returns_it():
    plots = []
    for name in MODULES:
        module = importlib.import_module(name)
        plots += [
            f
            for n, f in inspect.getmembers(module, inspect.isfunction)
            if n.startswith("plot_") and f.__module__ == name
        ]
    assert len(plots) >= 15
    for f in plots:
        ax = inspect.signature(f).parameters.get("ax")
        assert ax is not None and ax.default is None, f"{f.__module__}.{f.__name__} has no ax=None"
        assert "return ax" in inspect.getsource(f), f"{f.__module__}.{f.__name__} does not return its Axes"
