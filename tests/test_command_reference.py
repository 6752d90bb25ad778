"""The command reference (docs/commands.md, generated from the parsers) reads as text on an 80-column page."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from tissue_retract.cli import main

HOOKS = Path(__file__).resolve().parents[1] / "docs" / "hooks" / "site.py"


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_site_hooks", HOOKS)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_reference_has_no_rest_markup_and_no_line_past_its_width() -> None:
    """Every command's help as the docs site shows it: no reST roles or literals, no line over 80 columns."""
    hooks = _hooks()
    reference = hooks.command_reference()
    assert "## `tissue-retract deploy`" in reference and "### `tissue-retract bench faults`" in reference
    left = sorted(set(re.findall(r":[a-z]+:`[^`]*`|(?<!`)``(?!`)[^`\n]+``", reference)))
    assert left == [], left[:10]
    long = [line for line in reference.splitlines() if len(line) > hooks.HELP_COLUMNS]
    assert long == [], long[:10]


def test_help_on_a_terminal_is_plain_text(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """``--help`` wraps the description to the terminal and shows ``:mod:`` roles as their names."""
    monkeypatch.setenv("COLUMNS", "60")
    with pytest.raises(SystemExit):
        main(["deploy", "--help"])
    printed = capsys.readouterr().out
    assert ":mod:" not in printed and "``" not in printed
    assert "hardware_if.client.task_estimate" in printed
    description = printed.split("\n\n", 1)[1].split("\noptions:", 1)[0]  # between the usage and the options
    assert max(len(line) for line in description.splitlines()) <= 60


def test_deploy_help_says_which_sensing_and_policy_each_target_takes(capsys: pytest.CaptureFixture[str]) -> None:
    """``ideal`` is the simulation's default; a dVRK senses its console's force and the shipped policy follows."""
    with pytest.raises(SystemExit):
        main(["deploy", "--help"])
    printed = " ".join(capsys.readouterr().out.split())
    assert "--target sim only: with --target dvrk the filter senses what the console measures" in printed
    assert "pretrained is the policy shipped for the task and the force sensing the run has" in printed
