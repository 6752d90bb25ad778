"""Smoke runs of the safety commands: ``safety show`` and ``bench chain --json``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "tissue_retract", *args], capture_output=True, text=True, timeout=300, check=False
    )


def test_safety_show_prints_the_effective_limits(tmp_path: Path) -> None:
    """`safety show` prints the joint table at the configured rate and the force limit, with or without a file."""
    done = _run("safety", "show")
    assert done.returncode == 0, done.stderr
    assert "joint limits at 100 Hz" in done.stdout and "force_limit_n" in done.stdout
    config = tmp_path / "s.toml"
    config.write_text("control_rate_hz = 20\ndeadman_timeout_s = 0.1\ntissue = 'liver'\n")
    done = _run("safety", "show", "--config", str(config))
    assert done.returncode == 0, done.stderr
    assert "joint limits at 20 Hz" in done.stdout and "1.75" in done.stdout


def test_safety_show_states_the_unit_of_every_joint_limit() -> None:
    """The joint table names each row's unit (rad, m for insertion) and the derivatives' time units."""
    done = _run("safety", "show")
    assert done.returncode == 0, done.stderr
    rows = {line.split()[1]: line.split()[3] for line in done.stdout.splitlines() if line.startswith("│ ")}
    assert rows["yaw"] == "rad" and rows["insertion"] == "m", rows
    assert "velocity (unit/s)" in done.stdout and "jerk (unit/s^3)" in done.stdout


def test_bench_chain_writes_the_json_keys(tmp_path: Path) -> None:
    """`bench chain --ticks 500 --repeats 2 --json F` writes every documented key (no assertion on the times)."""
    out = tmp_path / "bench.json"
    done = _run("bench", "chain", "--ticks", "500", "--repeats", "2", "--json", str(out))
    assert done.returncode == 0, done.stderr
    result = json.loads(out.read_text())
    for key in ("p50_us", "p99_us", "max_us", "naive_p50_us", "naive_p99_us", "speedup_p99"):
        assert isinstance(result[key], float) and result[key] > 0.0, key
    assert result["ticks"] == 500
    # The filter's answers are exact: no row left violated beyond 1e-9, and the count is printed too.
    assert result["worst_row_violation"] <= 1e-9 and result["ticks_over_tolerance"] == 0
    assert result["filter_ticks_solver"] > 0 and result["filter_solver"] == "DAQP"
    assert "0 of 500 ticks above 1e-09" in done.stdout
    # Each tick's least CPU time over the runs is at most the first run's, tick by tick.
    assert result["repeats"] == 2 and 0.0 < result["least_cpu_p99_us"] <= result["cpu_p99_us"]
