"""Imports stay at the top of each module (docs/ARCHITECTURE.md, "Imports").

Every module of the project is parsed (never imported) and three rules are checked:

- an import inside a function says why on its line or the line above with ``# lazy: <reason>``;
  the command-line modules (``game/cli.py``, ``game/cli_*.py``, ``game/play.py``) are exempt by
  the policy in ``game/cli.py``'s docstring: each command imports its module when it runs;
- no private name (``_name``) is imported from another module of the project;
- the project's modules import each other without a cycle, at module level or through an import
  inside a function (imports under ``if TYPE_CHECKING:`` do not run and do not count).

Each rule is also shown to fail on a small planted violation.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("calibration", "tracking", "game", "content")
LAZY = re.compile(r"#\s*lazy:\s*\S")
CLI = re.compile(r"game\.(cli(_\w+)?|play)$")
_parse = functools.lru_cache(maxsize=None)(ast.parse)  # each module parsed once for the three rules


def project_sources(root: Path = ROOT) -> dict[str, tuple[str, bool]]:
    """Module name -> (source, is a package) for every module of the project under ``root``."""
    sources = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            name = ".".join(parts[:-1] if is_package else parts)
            sources[name] = (path.read_text(encoding="utf-8"), is_package)
    return sources


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute module name of ``from ... import`` (relative imports resolved)."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _module_level_imports(tree: ast.Module):
    """The imports that run when the module is imported (not in functions, not TYPE_CHECKING)."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            continue
        elif isinstance(node, ast.If) and _is_type_checking(node):
            stack.extend(node.orelse)
        else:
            stack.extend(ast.iter_child_nodes(node))


def _function_imports(tree: ast.Module):
    """The imports inside a function (run when the function runs)."""
    seen = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for sub in ast.walk(node):
                if isinstance(sub, (ast.Import, ast.ImportFrom)) and id(sub) not in seen:
                    seen.add(id(sub))
                    yield sub


def unexplained_lazy_imports(sources: dict[str, tuple[str, bool]]) -> list[str]:
    """``module:line`` of each import inside a function without ``# lazy: <reason>``."""
    bad = []
    for module, (source, _) in sources.items():
        if CLI.match(module):
            continue
        lines = source.splitlines()
        for node in _function_imports(_parse(source)):
            above = lines[node.lineno - 2].strip() if node.lineno > 1 else ""
            said = lines[node.lineno - 1:node.end_lineno] + ([above] if above.startswith("#") else [])
            if not any(LAZY.search(line) for line in said):
                bad.append(f"{module}:{node.lineno}: {lines[node.lineno - 1].strip()}")
    return sorted(bad)


def private_imports(sources: dict[str, tuple[str, bool]]) -> list[str]:
    """``module:line name`` of each private name imported from another module of the project."""
    bad = []
    for module, (source, is_package) in sources.items():
        for node in ast.walk(_parse(source)):
            if isinstance(node, ast.ImportFrom):
                target = _absolute(module, is_package, node)
                if target.split(".")[0] not in PACKAGES or target == module:
                    continue
                names = [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names if a.name.split(".")[0] in PACKAGES]
                names = [part for name in names for part in name.split(".")]
            else:
                continue
            for name in names:
                if name.startswith("_") and not name.startswith("__"):
                    bad.append(f"{module}:{node.lineno} {name}")
    return sorted(bad)


def import_graph(sources: dict[str, tuple[str, bool]], *, lazy: bool = False) -> dict[str, set[str]]:
    """Module -> the project's modules it imports at module level (``lazy``: and inside functions)."""
    graph = {}
    for module, (source, is_package) in sources.items():
        edges = set()
        tree = _parse(source)
        nodes = [*_module_level_imports(tree), *(_function_imports(tree) if lazy else ())]
        for node in nodes:
            if isinstance(node, ast.Import):
                edges.update(a.name for a in node.names if a.name in sources)
            else:
                target = _absolute(module, is_package, node)
                for alias in node.names:
                    if f"{target}.{alias.name}" in sources:
                        edges.add(f"{target}.{alias.name}")
                    elif target in sources:
                        edges.add(target)
        edges.discard(module)
        graph[module] = edges
    return graph


def import_cycles(sources: dict[str, tuple[str, bool]], *, lazy: bool = False) -> list[list[str]]:
    """The modules of each import cycle (strongly connected components of more than one module);
    ``lazy``: counting the imports inside functions too (a cycle a lazy import only hides)."""
    graph = import_graph(sources, lazy=lazy)
    index, low, on_stack, stack, cycles = {}, {}, set(), [], []

    def visit(start: str) -> None:  # Tarjan's algorithm, iterative (the graph is deep)
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return sorted(cycles)


# --------------------------------------------------------------------------- the tree


@pytest.fixture(scope="module")
def sources():
    return project_sources()


def test_the_tree_is_found(sources):
    assert {"tracking.tracker", "game.cli", "calibration.camera", "content"} <= set(sources)


def test_lazy_imports_say_why(sources):
    bad = unexplained_lazy_imports(sources)
    assert bad == [], "imports inside functions without '# lazy: <reason>':\n" + "\n".join(bad)


def test_no_private_names_across_modules(sources):
    bad = private_imports(sources)
    assert bad == [], "private names imported from another module:\n" + "\n".join(bad)


def test_no_import_cycles(sources):
    cycles = import_cycles(sources)
    assert cycles == [], "import cycles at module level:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_import_cycle_hidden_by_a_lazy_import(sources):
    cycles = import_cycles(sources, lazy=True)
    assert cycles == [], "import cycles through imports inside functions:\n" + "\n".join(" <-> ".join(c) for c in cycles)


# --------------------------------------------------------------------------- planted violations


def _planted(**modules: str) -> dict[str, tuple[str, bool]]:
    return {name.replace("__", "."): (source, False) for name, source in modules.items()}


def test_a_lazy_import_without_a_reason_is_found():
    sources = _planted(
        tracking__a="def f():\n    import json\n    return json\n",
        tracking__b="def f():\n    # lazy: keeps pygame out of the tracker process\n    import pygame\n",
        tracking__c="def f():\n    import pygame  # lazy: keeps pygame out of the tracker process\n",
        tracking__d="def f():\n    import pygame  # needed here\n",
        tracking__e="import json\n\n\nclass A:\n    def f(self):\n        from tracking.a import f\n",
        tracking__f="def f():\n    import pygame  # lazy: keeps pygame out of the tracker process\n    import moderngl\n",
        game__cli_x="def f():\n    import json\n",
    )
    assert unexplained_lazy_imports(sources) == [
        "tracking.a:2: import json", "tracking.d:2: import pygame  # needed here",
        "tracking.e:6: from tracking.a import f",
        "tracking.f:3: import moderngl"]


def test_a_private_name_across_modules_is_found():
    sources = _planted(
        tracking__a="def _helper():\n    pass\n",
        tracking__b="from tracking.a import _helper\n",
        tracking__c="from .a import __version__, helper\n",
        tracking__d="def f():\n    from . import a as _a, b\n    from numpy import _private\n",
        tracking__e="import tracking.a._inner\n",
    )
    assert private_imports(sources) == ["tracking.b:1 _helper", "tracking.e:1 _inner"]


def test_an_import_cycle_is_found():
    sources = _planted(
        tracking__a="from tracking.b import x\n",
        tracking__b="from tracking import c\n\nx = 1\n",
        tracking__c="import tracking.a\n",
        tracking__d="from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from tracking.e import y\n",
        tracking__e="from tracking.d import z\n\ndef f():\n    from tracking.f import w  # lazy: planted\n",
        tracking__f="from tracking.e import z\n",
    )
    sources["tracking"] = ("", True)
    assert import_cycles(sources) == [["tracking.a", "tracking.b", "tracking.c"]]
    # the lazy import in tracking.e closes the cycle e -> f -> e
    assert import_cycles(sources, lazy=True) == [["tracking.a", "tracking.b", "tracking.c"], ["tracking.e", "tracking.f"]]
