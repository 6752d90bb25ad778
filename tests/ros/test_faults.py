"""The deploy's fault matrix against a real ``sim-dvrk`` over loopback DDS (no mock of ROS).

Each fault of :data:`tissue_retract.faults.FAULTS` runs a real deploy child process (and a real sim-dvrk
on a domain of this run's) and injects its fault when the deploy's policy prints that it reached the fault
step: nothing is timed by sleeping. Every fault must end with its documented exit status (4 for a hold,
128 + signal for a stop signal, 0 where the deploy must not hold), its reason on the ``HOLD:`` line, no
traceback, and the hold in the recording; a SIGKILL in the third episode leaves a recording that ``replay``
summarises with the two finished episodes. The faults that leave their console as they found it run one
after another on one console (:class:`~tissue_retract.faults.SharedConsole`), the others on one of their own.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from domains import fault_domain_id

from tissue_retract.faults import FAULTS, NOTHING_WRITTEN, Fault, FaultResult, SharedConsole, run_fault

OWN_CONSOLE = [f for f in FAULTS if not f.shares_console]
ONE_CONSOLE = [f for f in FAULTS if f.shares_console]


def _run(fault: Fault, tmp_path: Path, console: SharedConsole | None = None) -> FaultResult:
    index = FAULTS.index(fault)
    domain = fault_domain_id(index) if console is None else console.domain_id
    # A retry stays in this worker's fault domains: one 37 ids on ran into another worker's fault.
    retries = [fault_domain_id(index + step) for step in (11, 22)]
    return run_fault(fault, tmp_path, domain, retry_domains=retries, console=console)


def _check(fault: Fault, result: FaultResult, tmp_path: Path) -> None:
    assert result.status == fault.status, result.output
    assert not result.traceback, result.output
    assert fault.explains(result.hold), result.output
    if fault.action == "kill-deploy":
        assert result.truncated and result.episodes_kept == 2, result.recording
        done = subprocess.run(
            [sys.executable, "-m", "tissue_retract", "replay", str(tmp_path / "run.mcap")],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 0, done.stderr
        assert "truncated recording" in done.stdout and "2 episode(s)" in done.stdout, done.stdout
        assert "episode 0: success=True" in done.stdout and "episode 1: success=True" in done.stdout
    elif fault.status == 0:  # the run must not hold: nothing recorded as one either
        assert result.hold == "" and result.holds_recorded == [], result.output
    elif fault.leaves_nothing:  # refused at start, or stopped before it wrote: no file left behind
        assert result.recording == NOTHING_WRITTEN, result.recording
    else:
        assert result.holds_recorded and any(fault.explains(h) for h in result.holds_recorded), result.recording
        if fault.status == 4:
            assert "HOLD:" in result.hold
            if fault.action == "kill-console":
                assert any(r in result.hold for r in ("stale", "publisher gone")), result.hold
    assert result.ok


@pytest.mark.slow
@pytest.mark.parametrize("fault", OWN_CONSOLE, ids=[f.name for f in OWN_CONSOLE])
def test_fault_ends_in_a_recorded_hold(fault: Fault, tmp_path: Path) -> None:
    """The fault ends with its exit status and reason, no traceback, and the hold in the recording."""
    _check(fault, _run(fault, tmp_path), tmp_path)


# One worker runs them all, in turn, while the class's console lives; it is stopped before any other test.
@pytest.mark.slow
@pytest.mark.xdist_group("fault matrix on one console")
class TestOnOneConsole:
    """The faults that leave their console as they found it, on one console."""

    @pytest.fixture(scope="class")
    def console(self) -> Iterator[SharedConsole]:
        """A console for the class's faults, on a fault domain of this worker's, stopped after the last."""
        shared = SharedConsole(fault_domain_id(0))
        yield shared
        shared.close()

    @pytest.mark.parametrize("fault", ONE_CONSOLE, ids=[f.name for f in ONE_CONSOLE])
    def test_fault_ends_in_a_recorded_hold(self, fault: Fault, console: SharedConsole, tmp_path: Path) -> None:
        """The fault ends with its exit status and reason, no traceback, and the hold in the recording."""
        _check(fault, _run(fault, tmp_path, console), tmp_path)
