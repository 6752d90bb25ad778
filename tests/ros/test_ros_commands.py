"""Smoke runs of the ROS subcommands as a user types them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from domains import commander_domain_id


def _cli(env: dict[str, str], *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "tissue_retract", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_sim_dvrk_unknown_task_is_refused(ros_env: dict[str, str]) -> None:
    """sim-dvrk --task with an unknown task exits non-zero and names the task ids it knows."""
    result = _cli(ros_env, "sim-dvrk", "--task", "nosuch", "--domain-id", ros_env["ROS_DOMAIN_ID"])
    assert result.returncode != 0
    assert "nosuch" in result.stderr and "lift" in result.stderr, result.stderr


def test_bench_ros_prints_latency_and_drops(ros_env: dict[str, str], tmp_path: Path) -> None:
    """bench ros prints p50/p99 and drops per rate and writes them as JSON (numbers are not asserted)."""
    out = tmp_path / "bench.json"
    # Its /psm1_client must not outlive it on the worker's own domain; and a bench left to pick its own domain
    # (from its process id) can pick another worker's, where a fault's deploy would meet its arm.
    domain = str(commander_domain_id())
    command = ("bench", "ros", "--rates", "100", "--duration", "0.5", "--domain-id", domain, "--json", str(out))
    result = _cli({**ros_env, "ROS_DOMAIN_ID": domain}, *command)
    assert result.returncode == 0, result.stderr
    assert "p50" in result.stdout and "p99" in result.stdout and "drops" in result.stdout
    report = json.loads(out.read_text())
    (row,) = report["results"]
    assert row["rate_hz"] == 100.0 and row["commands"] == 50
    assert {"p50_ms", "p99_ms", "drops"} <= set(row)
