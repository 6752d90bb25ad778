"""A deploy's exit status: a force on the tissue certainly above the limit has a status of its own."""

from __future__ import annotations

from pathlib import Path

import pytest

from hardware_if.deploy import report as deploy_report
from hardware_if.deploy.report import EXIT_HOLD, DeployReport
from tissue_retract.cli import main

#: A safety configuration that takes the tissue for 2 N/m where the task's flap pulls back with up to 110 N/m
#: (the default tissue_stiffness_bound_n_per_m): the filter lets the retraction pull the true force past the limit.
#: A limit the filter cannot foresee: its stiffness estimate may reach 2 N/m, the task flap pulls back at up to
#: 110.88 N/m, so the force overshoots 0.05 N (the tissue bounds are left to the run's own: a declared bound below
#: it is refused).
SOFT_TISSUE_TOML = """\
force_limit_n = 0.05
stiffness_prior_n_per_m = 2.0
stiffness_min_n_per_m = 1.0
stiffness_max_n_per_m = 2.0
"""


@pytest.mark.parametrize(
    ("changes", "status"),
    [
        ({}, 0),
        ({"fault": "stale: measured_js 0.2 s old"}, EXIT_HOLD),
        ({"interrupted": True, "signal": "SIGTERM"}, 143),
        ({"force_limit_exceeded": 17}, 3),
        ({"force_limit_exceeded": 1, "fault": "stale: measured_js 0.2 s old"}, EXIT_HOLD),
        ({"force_limit_exceeded": 2, "interrupted": True, "signal": "SIGINT"}, 130),
    ],
)
@pytest.mark.parametrize("target", ["dvrk", "sim"])
def test_a_force_certainly_over_the_limit_decides_the_exit_status(
    target: str, changes: dict[str, object], status: int
) -> None:
    """An excursion the report counts (beyond the sensing's error bound on a dVRK, the true force in the
    simulation) exits with EXIT_FORCE_LIMIT, 3, where it would have exited 0; a hold keeps its 4 and a stop
    signal its 128 + n."""
    report = DeployReport(target, False, Path("run.mcap"))
    for name, value in changes.items():
        setattr(report, name, value)
    assert report.exit_code == status


def test_sim_deploy_whose_true_force_passed_the_limit_exits_with_its_status(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """deploy --target sim, where the force is known exactly, exits 3 (not 0) when it went past the limit, and
    its report says so with the status."""
    config = tmp_path / "soft.toml"
    config.write_text(SOFT_TISSUE_TOML)
    arguments = ["deploy", "--policy", "scripted", "--target", "sim", "--task", "lift", "--episodes", "1"]
    arguments += ["--seed", "2", "--safety-config", str(config), "--record", str(tmp_path / "run.mcap")]
    status = main(arguments)
    out = capsys.readouterr().out
    assert status == 3, out
    assert "FORCE LIMIT 0.05 N EXCEEDED" in out and "exit status 3" in out, out
    assert deploy_report.EXIT_FORCE_LIMIT == 3
