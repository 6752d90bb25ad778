"""Stopping a sweep: a background-started ``robustness`` stops on SIGINT and SIGTERM, keeping what finished.

The sweep is started as a script's ``&`` job starts it, with SIGINT ignored, and is signalled once it has
written episodes (the test waits for them in its file, not for a time). It must stop with 128 + the
signal, keep every episode that finished (each a whole JSON line), leave no semaphore to the resource
tracker and no traceback.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from sim.sweep.memory import WARM_UP_TRIALS, WorkerMemory

SWEEP = ("robustness", "--policy", "scripted", "--task", "lift", "--trials", "400", "--jobs", "2", "--no-progress")


def _started_in_background(out: Path) -> subprocess.Popen[str]:
    def ignore_sigint() -> None:  # what a shell does to the jobs a script starts with &
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    env = dict(os.environ)
    command = [sys.executable, "-m", "tissue_retract", *SWEEP, "--vary", "stiffness=0.5:2x", "--out", str(out)]
    return subprocess.Popen(
        command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=ignore_sigint
    )


def _episodes(path: Path) -> list[dict]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines()]


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_background_sweep_stops_on_signal_keeping_finished_episodes(
    tmp_path: Path, signum: signal.Signals, status: int
) -> None:
    """SIGINT (inherited as ignored) and SIGTERM stop the sweep with 130 / 143, every finished episode kept."""
    process = _started_in_background(tmp_path)
    episodes = tmp_path / "episodes.jsonl"
    try:
        while len(_episodes(episodes)) < 4 and process.poll() is None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(timeout=0.2)  # waiting for the episodes to appear in the file, not for a time
        before = len(_episodes(episodes))
        process.send_signal(signum)
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == status, stderr
    kept = _episodes(episodes)  # every line whole: json.loads would fail on a torn one
    assert before >= 4 and len(kept) >= before
    assert len(kept) < 400  # it stopped, it did not finish
    assert len({r["index"] for r in kept}) == len(kept)
    assert "leaked semaphore" not in stderr and "Traceback" not in stderr, stderr
    assert "interrupted" in stderr


def test_worker_memory_reports_growth_after_warm_up() -> None:
    """The memory line compares each worker after its warm-up with its last trial, and strips the facts."""
    memory = WorkerMemory()
    for i in range(WARM_UP_TRIALS + 10):
        record = memory.take(
            {"index": i, "worker_pid": 7, "worker_rss_mb": 100.0 + (5.0 if i >= WARM_UP_TRIALS else 0)}
        )
        assert record == {"index": i}
    assert memory.growth_mb() == pytest.approx(5.0)
    assert "100.0 -> 105.0 MB over 30 episodes" in memory.line() and "+5.0 MB" in memory.line()


def test_a_bound_child_ends_when_its_parent_is_killed() -> None:
    """A child started through ChildProcesses ends when its command is killed with SIGKILL (no handler runs)."""
    parent_code = (
        "import subprocess, sys\n"
        "from sim.sweep.stopping import ChildProcesses\n"
        "with ChildProcesses('test') as children:\n"
        "    child = children.start('cat', ['cat'], stdin=subprocess.PIPE)\n"
        "    print(child.pid, flush=True)\n"
        "    sys.stdin.read()\n"
    )
    parent = subprocess.Popen(
        [sys.executable, "-c", parent_code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert parent.stdout is not None
        child = int(parent.stdout.readline())
        watch = os.pidfd_open(child)  # becomes readable when the child ends
        parent.kill()
        parent.wait()
        ended, _, _ = select.select([watch], [], [], 60.0)  # a failure guard, not a wait for a time
        os.close(watch)
    finally:
        if parent.poll() is None:
            parent.kill()
    assert ended, f"child {child} outlived its killed parent"
