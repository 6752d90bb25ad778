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


def test_bench_chain_writes_the_json_keys(tmp_path: Path) -> None:
    """`bench chain --ticks 500 --json F` writes every documented key (no assertion on the times)."""
    out = tmp_path / "bench.json"
    done = _run("bench", "chain", "--ticks", "500", "--json", str(out))
    assert done.returncode == 0, done.stderr
    result = json.loads(out.read_text())
    for key in ("p50_us", "p99_us", "max_us", "naive_p50_us", "naive_p99_us", "speedup_p99"):
        assert isinstance(result[key], float) and result[key] > 0.0, key
    assert result["ticks"] == 500
