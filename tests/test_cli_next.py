"""The next: line a command ends with on success (``tissue_retract.cli._next``)."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

import pytest

from tissue_retract.cli import main
from tissue_retract.cli._next import console_words, without_options


def test_a_dry_runs_next_command_is_itself_without_the_dry_run_and_its_recording() -> None:
    """The deploy a dry run names is its own command line without --dry-run, --force and --record (either form),
    every other word kept, quoted for a shell."""
    given = ["deploy", "--policy", "my policy.safetensors", "--target", "dvrk", "--dry-run", "--record", "dry.mcap"]
    line = shlex.join(["tissue-retract", *given, "--force", "--record=x.mcap", "--safety-config", "a.toml"])
    args = argparse.Namespace(command_line=line)
    words = without_options(args, ("--dry-run", "--force"), ("--record",))
    assert words == ["deploy", "--policy", "my policy.safetensors", "--target", "dvrk", "--safety-config", "a.toml"]


def test_the_console_options_carry_over_only_when_given() -> None:
    """--domain-id goes on to the next command when it was given (else the environment's applies), --network too."""
    given = argparse.Namespace(command_line="tissue-retract ready-arm --domain-id 7", domain_id=7, network=True)
    assert console_words(given) == ["--domain-id", "7", "--network"]
    left_out = argparse.Namespace(command_line="tissue-retract ready-arm", domain_id=0, network=False)
    assert console_words(left_out) == []


def test_evaluate_names_the_sweep_of_its_policy(capsys: pytest.CaptureFixture[str]) -> None:
    """evaluate, run to its end, names the robustness sweep of the same policy and task, then the rehearsal."""
    assert main(["evaluate", "--policy", "scripted", "--task", "lift", "--episodes", "1"]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    sweep = "robustness --policy scripted --task lift --trials 100 --vary stiffness=0.3:3x,size=0.8:1.2x"
    assert last.startswith(f"next: tissue-retract {sweep} "), last
    assert "tune-safety" in last and "docs/rehearsal-and-reports.md" in last, last


@pytest.mark.slow
def test_the_sweeps_name_the_force_limit_then_the_deploy_of_the_recommendation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """robustness names tune-safety for the same policy and task; tune-safety, with a recommendation, the deploy
    that loads its recommended_safety.yaml."""
    sweep = ["--policy", "scripted", "--task", "lift", "--jobs", "1"]
    vary = ["--trials", "2", "--vary", "stiffness=0.3:3x", "--out", str(tmp_path / "rob")]
    assert main(["robustness", *sweep, *vary]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("next: tissue-retract tune-safety --policy scripted --task lift --grid "), last
    grid = ["--grid", "force_limit_n=2:3", "--levels", "1", "--episodes", "1", "--out", str(tmp_path / "tune")]
    assert main(["tune-safety", *sweep, *grid]) == 0
    last = capsys.readouterr().out.strip().splitlines()[-1]
    config = tmp_path / "tune" / "recommended_safety.yaml"
    assert last.startswith(
        f"next: tissue-retract deploy --policy scripted --target sim --task lift --safety-config {config} "
    ), last
