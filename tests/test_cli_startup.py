"""A command given a bad option or value reports it without loading torch, PyBullet, Ray, ROS or matplotlib.

Each case runs the command line's ``main`` in a fresh interpreter, as ``tissue-retract`` would, and lists
the heavy packages it imported by the time the error was printed: those cost seconds of start-up that a
user who mistyped an option should not wait for (issue #66).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from tissue_retract.cli import SUBCOMMANDS
from tissue_retract.cli.bench import TARGETS

HEAVY = ("torch", "pybullet", "ray", "rclpy", "matplotlib")

_PROBE = f"""
import sys
from tissue_retract.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print(sorted(m for m in sys.modules if m.split('.')[0] in {set(HEAVY)!r}))
"""

COMMANDS = [*(c for c in SUBCOMMANDS if c != "bench"), *(f"bench {t}" for t in TARGETS)]

#: A bad value per command that only ``run`` can refuse (a file, a name), besides argparse's own checks.
BAD_VALUES: dict[str, list[str]] = {
    "reproduce": ["--tasks", "IV"],
    "replay": ["/nonexistent/recording.mcap"],
    "robustness": ["--policy", "scripted", "--task", "no-such-task"],
    "tune-safety": ["--policy", "scripted", "--task", "no-such-task", "--grid", "force_limit_n=1:2"],
    "train": ["--task", "lift", "--vary", "no-such-setting=1"],
    "train-perception": ["--task", "no-such-task", "--out", "/nonexistent/folder"],
    "demo": ["--task", "lift", "--video", "/nonexistent/demo.avi"],
    "evaluate": ["--policy", "scripted", "--safety-config", "/nonexistent/limits.toml"],
    "bench train": ["--tasks", "no-such-task"],
}


def _heavy_imports(*argv: str) -> tuple[list[str], str]:
    """The heavy packages ``tissue-retract ARGV`` imported, and what it wrote to stderr."""
    done = subprocess.run(
        [sys.executable, "-c", _PROBE, *argv],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=Path(__file__).resolve().parents[1],
    )
    assert done.returncode == 0, done.stderr
    return ast.literal_eval(done.stdout.strip().splitlines()[-1]), done.stderr


@pytest.mark.parametrize("command", COMMANDS)
def test_an_unknown_option_is_refused_without_heavy_imports(command: str) -> None:
    """``COMMAND --no-such-option`` prints its error before torch, PyBullet, Ray, rclpy or matplotlib load."""
    heavy, stderr = _heavy_imports(*command.split(), "--no-such-option")
    assert "error:" in stderr
    assert heavy == []


@pytest.mark.parametrize("command", list(BAD_VALUES))
def test_a_bad_value_is_refused_without_heavy_imports(command: str) -> None:
    """A bad file or name that the command checks itself is refused before the heavy packages load."""
    heavy, stderr = _heavy_imports(*command.split(), *BAD_VALUES[command])
    assert f"tissue-retract {command.split()[0]}: error:" in stderr
    assert heavy == []
