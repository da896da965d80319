"""No import cycle between the modules of the `drivehierarchy` package: layers stay one-way,
as `env/tests/it/module_cycles.rs` checks for `env/`.

Nodes: every module of python/drivehierarchy (a package is its `__init__`). Edges: the imports a
module runs when it is imported — statements at module level, in `try`/`if`/`with` blocks too,
but not under `if TYPE_CHECKING:` (never run) nor inside functions or classes (run later, the
usual way to break a cycle). `from pkg import name` is an edge to `pkg.name` when that is a
module, else to `pkg`. Importing `a.b` also runs `a/__init__`, but that is Python's own order
(the parent is always loaded first) and is not counted, as in import-linter and pydeps.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = "drivehierarchy"
ROOT = Path(__file__).resolve().parents[2] / "python" / PKG


def modules(root: Path) -> dict[str, Path]:
    out = {}
    for f in sorted(root.rglob("*.py")):
        if "_data" in f.relative_to(root).parts:
            continue
        parts = [PKG, *f.relative_to(root).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = f
    return out


def is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def module_level_imports(tree: ast.Module):
    """Import statements run when the module is imported (line, node)."""
    todo: list[ast.stmt] = list(tree.body)
    while todo:
        node = todo.pop(0)
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, ast.If):
            if not is_type_checking(node.test):
                todo.extend(node.body)
            todo.extend(node.orelse)
        elif isinstance(node, ast.Try):
            todo.extend([*node.body, *node.orelse, *node.finalbody])
            for h in node.handlers:
                todo.extend(h.body)
        elif isinstance(node, (ast.With, ast.For, ast.While)):
            todo.extend([*node.body, *getattr(node, "orelse", [])])


def import_graph(mods: dict[str, Path]) -> dict[str, dict[str, int]]:
    """module → {imported module: first line}."""
    graph: dict[str, dict[str, int]] = {}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        edges: dict[str, int] = {}
        for node in module_level_imports(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    anchor = name.split(".") if is_pkg else name.split(".")[:-1]
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = ".".join([*anchor, base] if base else anchor)
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append(sub if sub in mods else base)
            for t in targets:
                # `import drivehierarchy.x.y` names the deepest module of ours on that path.
                while t and t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != name:
                    edges.setdefault(t, node.lineno)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def describe(graph: dict[str, dict[str, int]], mods: dict[str, Path], comp: list[str]) -> str:
    inside = set(comp)
    lines = [f"cycle among {', '.join(comp)}:"]
    for a in comp:
        for b, line in sorted(graph[a].items()):
            if b in inside:
                lines.append(f"  {mods[a].relative_to(ROOT.parent)}:{line} {a} -> {b}")
    return "\n".join(lines)


def test_package_has_no_module_cycle():
    mods = modules(ROOT)
    assert len(mods) > 30, f"read only {len(mods)} modules from {ROOT}"
    graph = import_graph(mods)
    # The checker sees real dependencies (guards against it silently seeing none).
    assert "drivehierarchy.scenarios" in graph["drivehierarchy.envs.r4"]
    found = cycles(graph)
    assert not found, "import cycles in python/drivehierarchy:\n" + "\n".join(
        describe(graph, mods, c) for c in found
    )


@pytest.mark.parametrize(
    ("files", "expected"),
    [
        ({"__init__.py": "", "a.py": "from . import b", "b.py": "import drivehierarchy.a"}, [["a", "b"]]),
        ({"__init__.py": "", "a.py": "def f():\n    from . import b", "b.py": "from .a import f"}, []),
        (
            {
                "__init__.py": "",
                "a.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .b import B",
                "b.py": "from .a import x",
            },
            [],
        ),
        (
            {
                "__init__.py": "",
                "p/__init__.py": "",
                "p/x.py": "from ..q import y",
                "q.py": "from .p.x import z",
            },
            [["p.x", "q"]],
        ),
    ],
)
def test_checker(tmp_path, files, expected):
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    mods = modules(tmp_path)
    found = cycles(import_graph(mods))
    assert found == [[f"{PKG}.{m}" for m in c] for c in expected]
