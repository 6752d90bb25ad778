"""Shared fixtures."""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

# Under pytest-xdist (four workers on two cores) each worker and the commands it starts use one BLAS and OpenMP
# thread: OpenBLAS's two threads per process spin while they wait for a core that other processes hold. On the
# 2-core machine with other work on it, `bench sensing --write-arm`'s fit and comparison took 15.5 s of CPU with
# two threads and 4.5 s with one. Set before numpy is first imported (it reads them once); values already in the
# environment are kept.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _threads in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_threads, "1")

import numpy as np
import pytest

from psm_control.robot import PsmModel
from psm_control.spec import ARMS


def pytest_configure(config: pytest.Config) -> None:
    """Each pytest-xdist worker gets a temporary folder of its own, for itself and its child processes.

    ``tmp_path`` is per worker already; this covers what asks :mod:`tempfile` or ``$TMPDIR`` instead
    (Ray's session files, libraries' scratch files). The path is short: Ray puts Unix sockets under it.
    The ROS domain ids of the workers are kept apart in ``tests/ros/domains.py``.
    """
    if not config.pluginmanager.hasplugin("xdist"):  # -p no:xdist: its marker, which tests name, is still known
        config.addinivalue_line("markers", "xdist_group(name): tests pytest-xdist sends to one worker")
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker is None:
        return
    folder = tempfile.mkdtemp(prefix=f"tr-{worker}-")
    os.environ["TMPDIR"] = folder
    tempfile.tempdir = None  # forget the folder tempfile chose before
    config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))


#: When the run started (``time.perf_counter``) and the load average then, kept by the controller.
_STARTED = pytest.StashKey[tuple[float, float]]()


def pytest_sessionstart(session: pytest.Session) -> None:
    """The run's start and the machine's load then, for the summary line (not on pytest-xdist's workers)."""
    if not hasattr(session.config, "workerinput"):
        session.config.stash[_STARTED] = (time.perf_counter(), os.getloadavg()[0])


@pytest.hookimpl(trylast=True)  # after the slowest tests, the run's last line before pytest's own
def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter, config: pytest.Config) -> None:
    """One line a contributor can compare between runs and machines: the tests, the wall time of pytest, the
    cores and workers it ran on, the tests' own time summed (setup, call and teardown, as every worker reported
    it), the CPU time of pytest and all it started, and the load average at start and at end (other work on the
    machine slows a run down; the CPU time changes least with it).

    ``suite: 951 tests, 612.3 s of pytest on 2 cores (4 workers), 1830 s of test time, 1010 s of CPU; load
    average at start 0.4, at end 1.1``
    """
    if _STARTED not in config.stash:  # a worker: the controller sees every worker's reports
        return
    started_s, load_at_start = config.stash[_STARTED]
    wall_s = time.perf_counter() - started_s
    reports = [r for kind in terminalreporter.stats.values() for r in kind if isinstance(r, pytest.TestReport)]
    tests = len({r.nodeid for r in reports})
    test_s = sum(r.duration for r in reports)
    workers = config.getoption("numprocesses", default=None) or 0  # None without pytest-xdist, 0 with -n 0
    where = f"{workers} workers" if workers else "one process"
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    # pytest-xdist's workers have ended and been waited for by now: their CPU time is the children's.
    usage = [resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    cpu_s = sum(u.ru_utime + u.ru_stime for u in usage)
    terminalreporter.write_line(
        f"suite: {tests} tests, {wall_s:.1f} s of pytest on {cores} cores ({where}), {test_s:.0f} s of test time, "
        f"{cpu_s:.0f} s of CPU; load average at start {load_at_start:.1f}, at end {os.getloadavg()[0]:.1f}"
    )


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own, which names each item's group from its markers
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under pytest-xdist (``--dist loadgroup``), a module's tests that share a module-scoped fixture (a
    ``sim-dvrk`` started once, a deploy run once) go to one worker, so the fixture is built once, not on
    both. Tests already in a group (the Ray tests) keep theirs.

    Tests marked ``slow`` (and the groups they are in) are handed out first: a minute-long test started
    last would keep one worker busy after the others have finished.
    """
    for item in items:
        if item.get_closest_marker("xdist_group") is not None:
            continue
        definitions = getattr(item, "_fixtureinfo", None)
        scopes = [d.scope for defs in (definitions.name2fixturedefs.values() if definitions else ()) for d in defs]
        if "module" in scopes:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))
    slow_groups = {_group(item) for item in items if item.get_closest_marker("slow") is not None}
    items.sort(key=lambda item: _group(item) not in slow_groups)  # stable: the order within stays


def _group(item: pytest.Item) -> str:
    """The xdist group an item is sent with: its marker's, else the test itself."""
    marker = item.get_closest_marker("xdist_group")
    return str(marker.args[0]) if marker is not None and marker.args else item.nodeid


@pytest.fixture(params=ARMS)
def model(request: pytest.FixtureRequest) -> PsmModel:
    """The PSM model of each known arm variant."""
    return PsmModel.from_variant(request.param)


@pytest.fixture
def classic() -> PsmModel:
    """The default PSM: Classic arm, 400006 large needle driver."""
    return PsmModel.from_variant("classic")


def random_joints(model: PsmModel, rng: np.random.Generator, count: int) -> np.ndarray:
    """Uniform random joint vectors within the limits, shape (count, 6)."""
    return rng.uniform(model.lower, model.upper, size=(count, model.dof))


def run_cli(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    """Run ``tissue-retract ARGS`` as a user would, in a fresh interpreter, capturing its output."""
    return subprocess.run(
        [sys.executable, "-m", "tissue_retract", *args], capture_output=True, text=True, timeout=timeout, check=False
    )
