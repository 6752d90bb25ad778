"""Hostile joint logs and calibration files through the real command line: one table, one row per input.

Every row runs the real command line (``calibrate-wrench`` and ``bench sensing``, which share the log readers and
checks) as a careless or hostile user would type it: in a child forked from this process (:mod:`tests.forked_cli`:
what ``python -m tissue_retract ...`` would do, without importing scipy and the arm's model again for each row),
or, where the defect was memory, ``python -m tissue_retract ...`` in a fresh interpreter with its address space
bounded (``RLIMIT_AS``): a forked child's address space is the test's, not a command's. A refused row must exit
non-zero with a message that names what is wrong, print no traceback, and leave no calibration behind; a row that
must succeed (a long log, within its memory) must exit 0 and write it. The next check of a log's content is
covered by adding a row; a log that is not a regular file (a device, a FIFO), is missing, empty, garbage or too
large is a row of the one table of hostile files, ``tests/test_hostile_inputs.py``.
"""

from __future__ import annotations

import importlib
import json
import os
import resource
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from arm_logs import arm_bag, arm_csv

from tests.forked_cli import run_one

# What calibrate-wrench imports once it reads a log (the fit, and scipy.signal with it): imported here once, so a
# row's forked child starts with it as bench sensing's does (its command module imports the fit).
importlib.import_module("hardware_if.wrench.fit")

#: The address space of a row's child where the defect was memory (1.5 GiB): the interpreter with numpy, scipy,
#: Pinocchio and rosbags loaded maps about 1 GB of it, most of it not resident; the fit of the long log below ran
#: out of it (a 309 MiB regressor array) before its regressor was streamed.
MEMORY_BOUND_BYTES = 3 * 1024**3 // 2
#: Samples of the long log: 5 minutes at 100 Hz (an hour is 360,000).
LONG_SAMPLES = 30_000


@dataclass
class Row:
    """One hostile input: the arguments after ``tissue-retract`` (made in the row's folder), the words the
    message must contain, whether the command must succeed, and its memory bound."""

    name: str
    argv: Callable[[Path], list[str]]
    expect: tuple[str, ...]
    succeeds: bool = False
    memory_bytes: int | None = None
    timeout_s: float = 600.0
    outcome: dict[str, object] = field(default_factory=dict)


def _edited(edit: Callable[[np.ndarray, np.ndarray, np.ndarray], None], samples: int = 1500) -> Callable[[Path], Path]:
    """A bag of the arm's log with ``edit(q, qd, effort)`` applied."""
    return lambda folder: arm_bag(folder / "log", samples, 0.0, edit=edit)


def _zero_efforts(q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
    effort[:] = 0.0


def _insertion_1e6(q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
    q[:, 2] = 1e6


def _yaw_100_pitch_minus_50(q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
    q[:, 0], q[:, 1] = 100.0, -50.0


def _efforts_1e200(q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> None:
    effort *= 1e200


def _empty_csv(folder: Path) -> Path:
    path = folder / "empty.csv"
    path.write_bytes(b"")
    return path


def _good(folder: Path) -> Path:
    return arm_bag(folder / "good", 1500, 1.0)


def _zero_bound_file(folder: Path) -> Path:
    """A calibration as an exact console's log made it before: every bound and error 0 N."""
    path = folder / "zero.json"
    figures = ("error_bound_n", "error_bound_with_acceleration_n", "rms_before_n", "max_before_n", "rms_after_n")
    data = {"kind": "wrench_calibration", "arm": "PSM1", "columns": [320], "parameters": [0.0], "samples": 1000}
    data |= dict.fromkeys((*figures, "max_after_n"), 0.0) | {"sensing": "logs: rosbag2", "console": "unknown"}
    path.write_text(json.dumps(data))
    return path


def _calibrate(log: Callable[[Path], Path]) -> Callable[[Path], list[str]]:
    return lambda folder: ["calibrate-wrench", "--from", str(log(folder)), "--out", str(folder / "out.json")]


def _bench(log: Callable[[Path], Path], calibration: Callable[[Path], Path] | None = None) -> Callable[[Path], list]:
    def argv(folder: Path) -> list[str]:
        args = ["bench", "sensing", "--draws", "1", "--from", str(log(folder)), "--json", str(folder / "out.json")]
        return args + (["--calibration", str(calibration(folder))] if calibration is not None else [])

    return argv


ROWS = [
    # An exact console's log, or one no PSM gives: refused before anything is fitted, nothing written.
    Row("calibrate-zero-efforts", _calibrate(_edited(_zero_efforts)), ("every effort in this log is 0", "exact")),
    Row("calibrate-insertion-1e6", _calibrate(_edited(_insertion_1e6)), ("insertion is 1e+06 m", "range")),
    Row("calibrate-yaw-100-rad", _calibrate(_edited(_yaw_100_pitch_minus_50)), ("yaw is 100 rad", "range")),
    Row("calibrate-efforts-x1e200", _calibrate(_edited(_efforts_1e200)), ("efforts of at most 100", "yaw")),
    Row("calibrate-10-samples", _calibrate(_edited(lambda *_: None, 10)), ("samples to filter and fit", "has 10")),
    Row("calibrate-15-samples", _calibrate(_edited(lambda *_: None, 15)), ("samples to filter and fit", "has 15")),
    Row("calibrate-empty-csv", _calibrate(_empty_csv), ("a CSV log with rows", "this file has none")),
    # A calibration that says the force is exact: refused by a check as well as by a deploy.
    Row(
        "check-zero-bound-file",
        lambda folder: ["calibrate-wrench", "--check", str(_zero_bound_file(folder)), "--from", str(_good(folder))],
        ("error_bound_n of at least 0.5 N", "this file has 0 N"),
    ),
    # bench sensing shares the readers and the checks.
    Row("bench-sensing-10-samples", _bench(_edited(lambda *_: None, 10)), ("at least 60 samples",)),
    Row("bench-sensing-efforts-x1e200", _bench(_edited(_efforts_1e200)), ("efforts of at most 100",)),
    Row("bench-sensing-zero-bound-file", _bench(_good, _zero_bound_file), ("error_bound_n of at least 0.5 N",)),
    # A long log fits within a bounded memory: the regressor is streamed, not held.
    Row(
        "calibrate-long-log-bounded-memory",
        _calibrate(lambda folder: arm_bag(folder / "long", LONG_SAMPLES, 0.0)),
        ("written to",),
        succeeds=True,
        memory_bytes=MEMORY_BOUND_BYTES,
        timeout_s=1800.0,
    ),
    Row(
        "calibrate-csv-log",
        _calibrate(lambda folder: arm_csv(folder / "arm.csv", 3000, 0.0)),
        ("written to",),
        succeeds=True,
    ),
]


def _limit(memory_bytes: int | None) -> Callable[[], None] | None:
    if memory_bytes is None:
        return None
    return lambda: resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))


def _run_bounded(argv: list[str], row: Row) -> tuple[int | None, str]:
    """``python -m tissue_retract ARGV`` in a fresh interpreter within ``row.memory_bytes``: its exit status (None
    after the hang guard) and output."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")  # one BLAS thread: its buffers in the bound
    try:
        done = subprocess.run(
            [sys.executable, "-m", "tissue_retract", *argv],
            capture_output=True,
            text=True,
            timeout=row.timeout_s,
            env=env,
            preexec_fn=_limit(row.memory_bytes),
            check=False,
        )
    except subprocess.TimeoutExpired as e:
        return None, f"no answer in {row.timeout_s:g} s: {e.stdout!r} {e.stderr!r}"
    return done.returncode, done.stdout + done.stderr


def _run(row: Row, folder: Path) -> Row:
    folder.mkdir()
    argv = row.argv(folder)
    if row.memory_bytes is None:
        forked = run_one(*argv, timeout_s=row.timeout_s)
        text = forked.stdout + forked.stderr
        returncode = None if f"(killed after {row.timeout_s:g} s)" in forked.stderr else forked.returncode
    else:
        returncode, text = _run_bounded(argv, row)
    written = (folder / "out.json").exists()
    ok = returncode == 0 and written if row.succeeds else returncode not in (0, None) and not written
    row.outcome = {
        # A Python warning is no message for a user either (numpy's on an empty CSV was one).
        "ok": ok and "Traceback" not in text and "Warning" not in text and all(word in text for word in row.expect),
        "returncode": returncode,
        "written": written,
        "text": text[-2000:],
    }
    return row


@pytest.mark.slow
@pytest.mark.timeout(3600)  # a hang guard for a loaded machine
@pytest.mark.parametrize("row", ROWS, ids=[row.name for row in ROWS])
def test_a_hostile_log_or_calibration_gets_a_named_error_and_writes_nothing(tmp_path: Path, row: Row) -> None:
    """Each row: refused by name with a non-zero exit, no traceback and no file; or, a long log, fitted within its
    memory bound."""
    done = _run(row, tmp_path / row.name)
    assert done.outcome["ok"], (
        f"{row.name}: exit {done.outcome['returncode']}, wrote {done.outcome['written']}, expected "
        f"{'success' if row.succeeds else 'a named refusal'} with {row.expect}\n{done.outcome['text']}"
    )
