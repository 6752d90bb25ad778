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
        ("def f():\n    from hardware_if.deploy import deploy\n", 1),
        ("from sim.envs import make\nimport numpy\n", 0),
    ],
)
def test_an_upward_import_is_found_even_inside_a_function(tmp_path: Path, source: str, expected: int) -> None:
    """The checker sees module- and function-level imports of a higher layer, and nothing else."""
    for package in LAYERS:
        (tmp_path / package).mkdir()
    (tmp_path / "sim" / "module.py").write_text(source, encoding="utf-8")
    assert len(upward_imports(tmp_path)) == expected
