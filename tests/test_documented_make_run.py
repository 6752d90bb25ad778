"""What README and docs/getting-started.md show of ``make run`` is what the Makefile's command prints."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from tests.conftest import run_cli

ROOT = Path(__file__).resolve().parents[1]
PAGES = (ROOT / "README.md", ROOT / "docs" / "getting-started.md")
#: The summary lines of a run that a page shows whole (the per-episode lines are elided with "...").
SUMMARY = ("success: ", "commands: ", "safety: ", "holds: ", "peak measured force", "force limit ")


def _make_run_arguments() -> list[str]:
    """The arguments of ``tissue-retract`` in the Makefile's ``run`` target."""
    makefile = (ROOT / "Makefile").read_text().replace("\\\n", " ")
    line = re.search(r"^run:.*\n\t\$\(BIN\)/tissue-retract (.+)$", makefile, re.MULTILINE)
    assert line is not None, "the Makefile's run target"
    return shlex.split(line.group(1))


def _documented_block(page: Path) -> str:
    text = page.read_text()
    section = text[text.index("## What `make run` shows") :]
    block = re.search(r"```\n(deploy to sim: .*?)```", section, re.DOTALL)
    assert block is not None, f"{page.name}: the make run block"
    return block.group(1)


def _summary(text: str) -> list[str]:
    return [line.strip() for line in text.splitlines() if line.strip().startswith(SUMMARY)]


@pytest.mark.slow
def test_the_pages_show_what_make_run_prints(tmp_path: Path) -> None:
    """The Makefile's deploy, run now, prints the summary lines README and getting-started show."""
    blocks = {page.name: _documented_block(page) for page in PAGES}
    assert len(set(blocks.values())) == 1, "README and getting-started show different make run outputs"
    arguments = _make_run_arguments()
    arguments[arguments.index("--record") + 1] = str(tmp_path / "make-run.mcap")
    # The policy budget only decides whether a slow step holds; a loaded machine must not hold the run.
    done = run_cli(*arguments, "--policy-budget", "600")
    assert done.returncode == 0, done.stdout + done.stderr
    documented = _summary(next(iter(blocks.values())))
    assert len(documented) == len(SUMMARY), documented
    assert _summary(done.stdout) == documented, done.stdout
