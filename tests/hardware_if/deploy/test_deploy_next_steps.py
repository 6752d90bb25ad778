"""What a deploy says after it ends: what to change after a hold a busy machine causes, and the next step."""

from __future__ import annotations

from pathlib import Path

import pytest

from hardware_if.deploy.report import DeployReport
from tissue_retract.cli import main


@pytest.mark.parametrize(
    "reason",
    [
        "stale: measured_js 0.156 s old (timeout 0.150 s)",
        "stale: measured_js stamp has not advanced for 0.155 s (timeout 0.150 s; the console repeats its last "
        "measurement)",
        "stale: the chain's deadman: measurement 0.16 s old > 0.15 s",
    ],
)
def test_a_stale_hold_says_what_to_change_on_the_next_line(reason: str) -> None:
    """A stale hold keeps its reason and says on the line after it which setting a busy machine needs:
    deadman_timeout_s, in a --safety-config file, at most 1 s, and where the timeout is explained."""
    lines = DeployReport("dvrk", dry_run=False, record=Path("run.mcap"), fault=reason).lines()
    hold = lines.index(f"  HOLD: {reason}")
    advice = lines[hold + 1]
    assert "deadman_timeout_s" in advice and "--safety-config" in advice and "at most 1 s" in advice, advice
    assert "docs/dvrk.md#the-deadmans-timeout" in advice, advice


def test_a_policy_overrun_names_the_policy_budget_and_other_holds_say_nothing_more() -> None:
    """An overrun's hold names --policy-budget on the next line; a hold no setting should hide gets no advice."""
    overrun = "policy overrun: the policy step took 0.079 s, budget 0.050 s"
    lines = DeployReport("dvrk", dry_run=False, record=Path("run.mcap"), fault=overrun).lines()
    assert "--policy-budget" in lines[lines.index(f"  HOLD: {overrun}") + 1]
    tracking = "tracking error: yaw |measured - setpoint| = 3.016 > 0.5"
    lines = DeployReport("dvrk", dry_run=False, record=Path("run.mcap"), fault=tracking).lines()
    assert lines[-1] == f"  HOLD: {tracking}", lines


def test_a_deploy_that_ran_to_its_end_names_the_replay_of_its_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """deploy --target sim, run to its end: the last line names the replay of the run's own recording."""
    record = tmp_path / "lift.mcap"
    status = main(["deploy", "--policy", "scripted", "--target", "sim", "--task", "lift", "--record", str(record)])
    out = capsys.readouterr().out
    assert status == 0, out
    last = out.strip().splitlines()[-1]
    assert last.startswith(f"next: tissue-retract replay {record} --plot {record.with_suffix('.png')} "), out
