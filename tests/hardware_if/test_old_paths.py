"""The paths ``hardware_if``'s modules had before its rooms still offer what they offered, and nothing more."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: Each path kept for user scripts -> the modules its names now come from.
OLD_PATHS = {
    "hardware_if.deploy": (
        "hardware_if.deploy.options",
        "hardware_if.deploy.report",
        "hardware_if.deploy.run",
        "hardware_if.deploy.stopping",
    ),
    "hardware_if.recording": ("hardware_if.recording.recorder",),
    "hardware_if.psm_client": ("hardware_if.client.psm_client",),
    "hardware_if.sim_dvrk": ("hardware_if.console.console_arm", "hardware_if.console.sim_dvrk"),
    "hardware_if.wrench_calibration": ("hardware_if.wrench.calibration", "hardware_if.wrench.fit"),
}


@pytest.mark.parametrize("old", sorted(OLD_PATHS))
def test_an_old_path_offers_the_objects_of_the_rooms(old: str) -> None:
    """Every name in the old path's ``__all__`` is the very object its room's module defines."""
    module = importlib.import_module(old)
    rooms = [importlib.import_module(name) for name in OLD_PATHS[old]]
    assert module.__all__
    for name in module.__all__:
        assert any(getattr(room, name, None) is getattr(module, name) for room in rooms), name


def test_the_modules_at_the_top_of_hardware_if_only_re_export() -> None:
    """A module beside the rooms is an old path: a docstring, imports from the rooms and ``__all__``."""
    tops = sorted(path for path in (ROOT / "hardware_if").glob("*.py") if path.stem != "__init__")
    assert {f"hardware_if.{path.stem}" for path in tops} <= set(OLD_PATHS)
    for path in tops:
        docstring, *rest = ast.parse(path.read_text(encoding="utf-8")).body
        assert isinstance(docstring, ast.Expr) and "kept for user scripts" in ast.literal_eval(docstring.value)
        for node in rest:
            if isinstance(node, ast.ImportFrom):
                assert node.module in OLD_PATHS[f"hardware_if.{path.stem}"], f"{path.name}: {node.module}"
            else:
                assert isinstance(node, ast.Assign), f"{path.name}: line {node.lineno}"
                assert [ast.unparse(target) for target in node.targets] == ["__all__"]
