"""Smoke runs of the command line, as a user would type it."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import run_cli
from tissue_retract.cli import SUBCOMMANDS
from tissue_retract.cli.bench import TARGETS

PROMISED = ("demo", "train", "evaluate", "deploy", "robustness", "tune-safety", "sim-dvrk", "replay", "bench", "safety")


def test_help_lists_every_subcommand() -> None:
    """--help lists every subcommand the interface promises."""
    result = run_cli("--help")
    assert result.returncode == 0
    for name in PROMISED:
        assert name in SUBCOMMANDS
        assert name in result.stdout
    listed = " ".join(result.stdout.split())  # argparse folds the help line
    assert all(target in listed for target in TARGETS), listed


def test_safety_show_takes_the_safety_config_option_every_command_takes(tmp_path) -> None:
    """``safety show --safety-config F`` shows F's limits (``--config`` is still taken)."""
    config = tmp_path / "limits.toml"
    config.write_text("force_limit_n = 1.5\n")
    for option in ("--safety-config", "--config"):
        result = run_cli("safety", "show", option, str(config))
        assert result.returncode == 0, result.stderr
        assert "force_limit_n" in result.stdout and "1.5 (explicit)" in result.stdout, result.stdout


def test_version() -> None:
    """--version prints the package version."""
    from psm_control import __version__

    result = run_cli("--version")
    assert result.returncode == 0
    assert __version__ in result.stdout


@pytest.mark.parametrize("command", [[name] for name in SUBCOMMANDS] + [["bench", t] for t in TARGETS], ids=" ".join)
def test_every_subcommand_has_help_without_extras(command: list[str]) -> None:
    """Every subcommand answers --help, with no ROS 2 or Ray imported to do so."""
    code = (
        "import sys; from tissue_retract.cli import main\n"
        f"try:\n    main({[*command, '--help']!r})\nexcept SystemExit as e:\n    assert e.code == 0, e.code\n"
        "assert 'rclpy' not in sys.modules and 'ray' not in sys.modules, 'imported an extra'"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=False)
    assert result.returncode == 0, result.stderr
    assert "usage: tissue-retract" in result.stdout


def test_kinematics_demo_agrees_three_ways() -> None:
    """The demo prints the tool-tip table and the three kinematics agree."""
    result = run_cli("demo", "--kinematics", "--arm", "si")
    assert result.returncode == 0, result.stderr
    assert "psm_si_420006" in result.stdout
    assert "largest disagreement" in result.stdout
    assert "x [mm]" in result.stdout and "DH err [m]" in result.stdout  # units are text, not rich markup


def test_evaluate_prints_every_length_with_its_unit() -> None:
    """evaluate's table names the unit of each length (rich would take "[mm]" for markup and drop it)."""
    result = run_cli("evaluate", "--policy", "scripted", "--task", "lift", "--episodes", "1", "--seeds", "1")
    assert result.returncode == 0, result.stderr
    for row in ("workspace violation [mm]", "min insertion margin [mm]", "peak force [N]"):
        assert row in result.stdout, result.stdout


def test_all_packages_import() -> None:
    """The five top-level packages import."""
    result = subprocess.run(
        [sys.executable, "-c", "import psm_control, sim, policies, safety, hardware_if"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stderr


def test_calibrate_wrench_help_names_the_command_that_readies_the_arm() -> None:
    """``calibrate-wrench --help`` says ``ready-arm`` enables and homes the arm it needs."""
    result = run_cli("calibrate-wrench", "--help")
    assert result.returncode == 0, result.stderr
    assert "tissue-retract ready-arm --arm PSM1` does that" in " ".join(result.stdout.split()), result.stdout
