"""A stopped ``bench rehearsal`` leaves nothing behind: no console serving its domain, no process, no folder.

The bench is started as a user's shell starts a command, in a process group of its own; with SIGINT ignored
in the case of SIGINT, as a script's ``&`` job inherits it. It is signalled once its console serves the
domain (the console's first line of ground truth is in the bench's temporary folder: an event, not a
time), while the deploy runs. It must exit with 128 + the signal, saying what it stopped; every process it
started (found under /proc while it ran) must be gone, as must every process of its group and its
temporary folder; and a new ``sim-dvrk`` must serve the same domain, not be refused as "already served".
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from ros_process import start_sim_dvrk, stop

#: A failure guard for the bench's start-up and stop on a loaded machine [s], never a wait for a time.
GUARD_S = 600.0


def _stat(pid: int) -> tuple[int, int] | None:
    """The parent pid and process group of ``pid`` (None: no such process, or a zombie)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2 :].split()
    return None if fields[0] == "Z" else (int(fields[1]), int(fields[2]))


def _processes() -> dict[int, tuple[int, int]]:
    """Every live process: pid -> (parent pid, process group)."""
    found = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit() and (stat := _stat(int(entry))) is not None:
            found[int(entry)] = stat
    return found


def _descendants(pid: int) -> set[int]:
    """The live processes below ``pid``."""
    table = _processes()
    below: set[int] = set()
    frontier = {pid}
    while frontier:
        frontier = {child for child, (parent, _) in table.items() if parent in frontier} - below
        below |= frontier
    return below


def _first_truth_line(process: subprocess.Popen[str], temporary: Path) -> bool:
    """Wait until the bench's console has written a line of ground truth (it serves), or the bench ended."""
    while process.poll() is None:
        if any(p.stat().st_size > 0 for p in temporary.glob("rehearsal-*/truth-*.jsonl")):
            return True
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=0.1)  # waiting for the file, or for the bench to end; not for a time
    return False


@pytest.mark.timeout(2 * GUARD_S)
@pytest.mark.parametrize(("signum", "sigint_ignored"), [(signal.SIGTERM, False), (signal.SIGINT, True)])
def test_a_stopped_rehearsal_stops_its_console_and_deploy_and_removes_its_folder(
    ros_env: dict[str, str], tmp_path: Path, signum: signal.Signals, sigint_ignored: bool
) -> None:
    """SIGTERM, or SIGINT inherited ignored: exit 128 + signal, no child or group member left, no folder,
    and the domain free for a new sim-dvrk."""
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    env = {**ros_env, "TMPDIR": str(temporary), "PYTHONUNBUFFERED": "1"}
    command = [sys.executable, "-m", "tissue_retract", "bench", "rehearsal", "--tasks", "lift", "--modes", "topics"]
    command += ["--episodes", "2", "--domain-id", ros_env["ROS_DOMAIN_ID"], "--policy-budget", "600"]

    def as_a_background_job() -> None:  # what a shell does to the jobs a script starts with &
        if sigint_ignored:
            signal.signal(signal.SIGINT, signal.SIG_IGN)

    bench = subprocess.Popen(
        command,
        env=env,
        cwd=tmp_path,  # python -m imports from the working folder first: the installed code, not a checkout's
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        process_group=0,
        preexec_fn=as_a_background_job,
    )
    started: set[int] = set()
    try:
        assert _first_truth_line(bench, temporary), bench.communicate()
        started = _descendants(bench.pid)
        bench.send_signal(signum)
        stdout, stderr = bench.communicate(timeout=GUARD_S)
    finally:
        if bench.poll() is None:
            os.killpg(bench.pid, signal.SIGKILL)
            bench.wait()
        for pid in _descendants(bench.pid) | started:  # nothing may outlive the test, whatever it found
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    assert bench.returncode == 128 + signum, stdout + stderr
    assert len(started) >= 2, started  # the console and the deploy ran (and their own children, if any)
    assert f"bench rehearsal: {signum.name}: stopped deploy" in stderr and "sim-dvrk (pid" in stderr, stderr
    assert "removed " in stderr and "Traceback" not in stderr, stderr
    assert [pid for pid in started if _stat(pid) is not None] == [], started
    assert [pid for pid, (_, group) in _processes().items() if group == bench.pid] == []
    assert list(temporary.iterdir()) == []
    console = start_sim_dvrk(ros_env)
    serving = False
    assert console.stdout is not None
    for line in console.stdout:  # its start-up log line comes after the check for another console
        if "simulated PSM1 at" in line:
            serving = True
            break
    output = stop(console, timeout_s=60.0)
    assert serving and "already served" not in output, output
