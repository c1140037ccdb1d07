"""The package's shape (docs/design.md, "Layers"): no import cycles between modules, counting the
imports inside functions too; no module far over 500 lines; function-local imports only where a
command's start-up time needs them (the command line and the library's dispatchers), or marked
``# lazy:`` with the reason (an optional or heavy package only one path uses)."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "diegocal"
#: Where imports inside functions are the point: the command line and the library's dispatchers
#: load a command's or a domain's code only when it runs (docs/design.md).
LAZY = ("cli/", "api.py", "predict.py", "batch/", "io/importers/", "diagnose/__init__.py")
MAX_LINES = 530


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        name = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = path
    return out


def _resolve(name: str, modules) -> str | None:
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def _imports(name: str, path: Path, modules) -> tuple[set[str], int]:
    """(the diegocal modules ``name`` imports, its imports inside functions)."""
    text = path.read_text()
    lines = text.splitlines()
    tree = ast.parse(text)
    out, local = set(), 0
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node, in_function in _walk(tree.body, False):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = package
                for _ in range(node.level - 1):
                    pkg = pkg.rpartition(".")[0]
                base = f"{pkg}.{base}" if base else pkg
            # ``from pkg import sub`` imports the submodule, not the package's other names
            targets = [_resolve(f"{base}.{a.name}", modules) for a in node.names]
        elif isinstance(node, ast.Import):
            targets = [_resolve(a.name, modules) for a in node.names]
        else:
            continue
        said = any("# lazy:" in lines[i] for i in (node.lineno - 1, node.lineno - 2) if i >= 0)
        if in_function and not said:
            local += 1
        out |= {t for t in targets if t and t != name and t.startswith("diegocal")}
    return out, local


def _walk(nodes, in_function: bool):
    """(node, whether it sits inside a function) for every node under ``nodes``."""
    for node in nodes:
        yield node, in_function
        inner = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        yield from _walk(ast.iter_child_nodes(node), inner)


def test_no_import_cycles():
    modules = _modules()
    graph = {m: _imports(m, p, modules)[0] for m, p in modules.items()}
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for m in graph:
        if m not in index:
            visit(m)
    assert cycles == []


def test_modules_stay_small():
    sizes = {str(p.relative_to(PACKAGE)): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")}
    long = {name: n for name, n in sizes.items() if n > MAX_LINES}
    assert long == {}


def test_imports_inside_functions_only_where_start_up_needs_them():
    modules = _modules()
    found = {}
    for name, path in modules.items():
        rel = str(path.relative_to(PACKAGE))
        if rel.startswith(LAZY):
            continue
        local = _imports(name, path, modules)[1]
        if local:
            found[rel] = local
    assert found == {}
