"""The packages stand in layers: no module imports a package above its own, at any depth.

Within ``hardware_if`` the rooms (its sub-packages) do the same: each imports only the rooms its docstring
names, and no first-party module imports through a path kept for user scripts.
"""

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


#: The rooms of ``hardware_if`` and the other rooms each may import (each room's docstring says why).
ROOMS = {
    "common": (),
    "console": ("common",),
    "recording": ("common",),
    "wrench": ("common", "recording"),
    "client": ("common", "wrench"),
    "deploy": ("common", "recording", "wrench", "client"),
}
ROOMED = "hardware_if"


def imported_names(tree: ast.AST) -> list[tuple[int, str]]:
    """Every absolute import as (line, dotted name): ``from a import b`` gives ``a.b``, function-level ones too."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found += [(node.lineno, f"{node.module}.{alias.name}") for alias in node.names]
    return found


def room_imports(root: Path) -> list[str]:
    """``path:line: importer -> name (why)`` for each import of a room that the importer's room may not import,
    and each first-party import through a path kept for user scripts: a module at the top of ``hardware_if``,
    or a room's own names (``from hardware_if.deploy import deploy``), where the defining module is meant."""
    base = root / ROOMED
    old_paths = {path.stem for path in base.glob("*.py") if path.stem != "__init__"}
    found = []
    for top in (*LAYERS, "tests"):
        for path in sorted((root / top).rglob("*.py")):
            parts = path.relative_to(root).parts
            if parts[0] == ROOMED and len(parts) == 2:
                continue  # the package's own docstring and the old paths themselves
            room = parts[1] if parts[0] == ROOMED else None
            for line, name in imported_names(ast.parse(path.read_text(encoding="utf-8"))):
                dotted = name.split(".")
                if dotted[0] != ROOMED or len(dotted) < 2:
                    continue
                why = ""
                if dotted[1] in old_paths:
                    why = "a path kept for user scripts"
                elif len(dotted) == 3 and dotted[1] in ROOMS:
                    module = base / dotted[1] / dotted[2]
                    if not (module.with_suffix(".py").exists() or (module / "__init__.py").exists()):
                        why = "a room's name kept for user scripts, not its module"
                elif len(dotted) == 2 and dotted[1] in ROOMS:
                    why = "a room, not one of its modules"
                if not why and room in ROOMS and dotted[1] in ROOMS and dotted[1] not in (room, *ROOMS[room]):
                    why = f"{room} may import only {', '.join(ROOMS[room]) or 'itself'}"
                if why:
                    found.append(f"{path.relative_to(root)}:{line}: {room or parts[0]} -> {name} ({why})")
    return found


def test_each_room_imports_only_the_rooms_it_may() -> None:
    """0 imports of a room another room may not import, and 0 first-party imports through a kept old path."""
    found = room_imports(ROOT)
    print(f"{len(found)} imports across the rooms of {ROOMED} that they may not make")
    assert found == []


def test_every_room_has_its_rules() -> None:
    """The rules name every sub-package of ``hardware_if``, and only those."""
    assert {path.parent.name for path in (ROOT / ROOMED).glob("*/__init__.py")} == set(ROOMS)


@pytest.mark.parametrize(
    ("room", "source", "expected"),
    [
        ("console", "def f():\n    from hardware_if.deploy.run import deploy\n", 1),
        ("console", "from hardware_if.client.psm_client import PsmClient\n", 1),
        ("recording", "import hardware_if.console.sim_dvrk\n", 1),
        ("common", "from hardware_if.wrench.calibration import WrenchCalibration\n", 1),
        ("client", "from hardware_if.psm_client import PsmClient\n", 1),
        ("client", "def f():\n    from hardware_if.recording import Recorder\n", 1),
        ("deploy", "from hardware_if.recording import recorder\nfrom hardware_if.client.psm_client import C\n", 0),
        ("console", "from hardware_if.common import crtk\nfrom hardware_if.console.motion import f\nimport numpy\n", 0),
    ],
)
def test_an_import_across_rooms_is_found_even_inside_a_function(
    tmp_path: Path, room: str, source: str, expected: int
) -> None:
    """The checker sees a room importing one above or beside it, and imports through the kept old paths."""
    for package in LAYERS:
        (tmp_path / package).mkdir()
    for name in ROOMS:
        (tmp_path / ROOMED / name).mkdir()
        (tmp_path / ROOMED / name / "__init__.py").write_text('"""A room."""\n', encoding="utf-8")
    for module in ("recording/recorder.py", "common/crtk.py"):
        (tmp_path / ROOMED / module).write_text("A = 1\n", encoding="utf-8")
    old_path = "from hardware_if.client.psm_client import PsmClient\n"
    (tmp_path / ROOMED / "psm_client.py").write_text(old_path, encoding="utf-8")
    (tmp_path / ROOMED / room / "module.py").write_text(source, encoding="utf-8")
    assert len(room_imports(tmp_path)) == expected


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
