"""Starting the simulated dVRK for the ROS tests: a real ``tissue-retract sim-dvrk`` child process."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable

SIM_BASE_XYZ = (0.1, -0.2, 0.3)


def start_sim_dvrk(env: dict[str, str], *extra: str) -> subprocess.Popen[str]:
    """Start ``sim-dvrk`` on this test run's domain (from ``env``) with a non-trivial base frame."""
    command = [sys.executable, "-m", "tissue_retract", "sim-dvrk", "--domain-id", env["ROS_DOMAIN_ID"]]
    command += ["--base-xyz", *(str(v) for v in SIM_BASE_XYZ), *extra]
    return subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def stop(process: subprocess.Popen[str], sig: int = signal.SIGINT, timeout_s: float = 10.0) -> str:
    """Signal the process, wait for it, return what it printed."""
    if process.poll() is None:
        process.send_signal(sig)
    try:
        output, _ = process.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        process.kill()
        output, _ = process.communicate()
    return output or ""


def wait_until(condition: Callable[[], bool], timeout_s: float = 5.0, period_s: float = 0.01) -> bool:
    """Poll ``condition`` until true or the timeout; return its last value."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(period_s)
    return condition()


__all__ = ["SIM_BASE_XYZ", "start_sim_dvrk", "stop", "wait_until"]
