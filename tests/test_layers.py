"""The packages stand in layers: no module imports a package above its own, at any depth."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

#: Bottom to top: each package may import itself and the ones before it.
LAYERS = ("psm_control", "safety", "sim", "policies", "hardware_if", "tissue_retract")
ROOT = Path(__file__).resolve().parents[1]


def imported_modules(tree: ast.AST) -> list[tuple[int, str]]:
    """Every absolute import in a module, function-level ones included, as (line, module)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
    return found


def upward_imports(root: Path) -> list[str]:
    """``path:line: package -> module`` for each import of a higher layer under ``root``."""
    upward = []
    for level, package in enumerate(LAYERS):
        for path in sorted((root / package).rglob("*.py")):
            for line, module in imported_modules(ast.parse(path.read_text(encoding="utf-8"))):
                top = module.split(".")[0]
                if top in LAYERS and LAYERS.index(top) > level:
                    upward.append(f"{path.relative_to(root)}:{line}: {package} -> {module}")
    return upward


def test_no_module_imports_a_higher_layer() -> None:
    """0 upward imports across the first-party packages."""
    upward = upward_imports(ROOT)
    print(f"{len(upward)} upward imports")
    assert upward == []


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("import policies.checkpoint\n", 1),
        ("def f():\n    from hardware_if.deploy.run import deploy\n", 1),
        ("from sim.envs import make\nimport numpy\n", 0),
    ],
)
def test_an_upward_import_is_found_even_inside_a_function(tmp_path: Path, source: str, expected: int) -> None:
    """The checker sees module- and function-level imports of a higher layer, and nothing else."""
    for package in LAYERS:
        (tmp_path / package).mkdir()
    (tmp_path / "sim" / "module.py").write_text(source, encoding="utf-8")
    assert len(upward_imports(tmp_path)) == expected


def module_graph(root: Path) -> dict[str, set[str]]:
    """First-party module -> the first-party modules it imports (function-level imports included)."""
    paths = {}
    for package in LAYERS:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            paths[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                for alias in node.names:  # ``from a import b`` imports the module a.b where there is one
                    full = f"{node.module}.{alias.name}"
                    found.add(full if full in paths else node.module)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
        graph[name] = {module for module in found if module in paths and module != name}
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The groups of modules that import each other, directly or through others (strongly connected)."""
    order: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles: list[list[str]] = []

    def visit(module: str) -> None:  # Tarjan's algorithm; the graph is a few hundred modules deep at most
        order[module] = low[module] = len(order)
        stack.append(module)
        for other in graph[module]:
            if other not in order:
                visit(other)
                low[module] = min(low[module], low[other])
            elif other in stack:
                low[module] = min(low[module], order[other])
        if low[module] == order[module]:
            group = []
            while True:
                other = stack.pop()
                group.append(other)
                if other == module:
                    break
            if len(group) > 1:
                circles.append(sorted(group))

    for module in graph:
        if module not in order:
            visit(module)
    return circles


def test_no_modules_import_each_other() -> None:
    """No import circle among the first-party modules (a shared piece belongs in a module below both)."""
    assert import_circles(module_graph(ROOT)) == []


def test_an_import_circle_is_found_even_through_a_function(tmp_path: Path) -> None:
    """Two modules that import each other, one inside a function, are one circle; one direction is none."""
    for package in LAYERS:
        (tmp_path / package).mkdir()
    (tmp_path / "policies" / "a.py").write_text("from policies.b import f\n", encoding="utf-8")
    (tmp_path / "policies" / "b.py").write_text("def f():\n    from policies import a\n", encoding="utf-8")
    assert import_circles(module_graph(tmp_path)) == [["policies.a", "policies.b"]]
    (tmp_path / "policies" / "b.py").write_text("def f():\n    pass\n", encoding="utf-8")
    assert import_circles(module_graph(tmp_path)) == []
