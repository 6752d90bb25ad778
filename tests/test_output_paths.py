"""Every path a command writes, on a full disk: the error names the path and nothing is left behind.

The hostile targets of every writer (a FIFO, a device, a folder, a symlink to a FIFO, one of the command's
own inputs, an earlier recording) are rows of the one table of hostile files, ``tests/test_hostile_inputs.py``.
Here a full disk is met for real, in the commands themselves: a child with a small ``RLIMIT_FSIZE`` (SIGXFSZ
ignored), where every write past the limit fails with ``EFBIG`` as a full disk fails with ``ENOSPC``; and
``deploy --force`` replaces an earlier recording.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from hardware_if.recording.recorder import Recorder
from hardware_if.wrench.bag_writer import write_joint_bag
from hardware_if.wrench.joint_logs import JointLog
from psm_control.effort_model import EffortRegressor, independent_columns
from tests.ros.domains import worker_domain_id

#: A sweep's policy and task, run as briefly as it can be.
SWEEP = ("--policy", "scripted", "--task", "lift", "--jobs", "1", "--no-progress")
#: This worker's own ROS domain, should a live command get past its checks (it then waits and fails).
LIVE = ("--domain-id", str(worker_domain_id()), "--wait", "1")


#: Runs ``tissue-retract ARGV`` in this process with its file-size limit at LIMIT bytes: writes past it fail
#: with EFBIG, as on a full disk.
_LIMITED = textwrap.dedent(
    """
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[1]), resource.RLIM_INFINITY))
    from tissue_retract.cli import main
    sys.exit(main(sys.argv[2:]))
    """
)


def _on_a_full_disk(limit: int, cwd: Path, *argv: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", _LIMITED, str(limit), *map(str, argv)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        cwd=cwd,
    )


def _motion(frequencies_hz: np.ndarray, phase: float) -> tuple[np.ndarray, ...]:
    """8 s of a smooth excitation at 200 Hz, two sines per joint: times, positions, velocities, accelerations."""
    amplitude = np.array([0.5, 0.4, 0.05, 0.8, 0.6, 0.6])
    t = np.arange(1600) / 200.0
    w = 2 * np.pi * frequencies_hz
    a, b = np.outer(t, w) + phase, np.outer(t, 2.3 * w) + 2 * phase
    q = np.array([0, 0, 0.14, 0, 0, 0]) + amplitude * (0.7 * np.sin(a) + 0.3 * np.sin(b))
    qd = amplitude * (0.7 * w * np.cos(a) + 0.3 * 2.3 * w * np.cos(b))
    qdd = -amplitude * (0.7 * w**2 * np.sin(a) + 0.3 * (2.3 * w) ** 2 * np.sin(b))
    return t, q, qd, qdd


def test_calibrate_wrench_out_on_a_full_disk_names_the_path_and_leaves_no_file(tmp_path: Path) -> None:
    """calibrate-wrench --out on a full disk: exit 1 naming --out, its path and the reason; no empty file left."""
    regressor, rng = EffortRegressor(), np.random.default_rng(3)
    fit = _motion(np.array([0.31, 0.23, 0.41, 0.37, 0.29, 0.43]), 0.0)
    held = _motion(np.array([0.27, 0.35, 0.33, 0.45, 0.39, 0.25]), 1.0)
    columns = independent_columns(regressor.matrix(*fit[1:]).reshape(-1, regressor.columns))
    truth = np.zeros(regressor.columns)
    truth[columns] = rng.normal(scale=0.05, size=len(columns))
    bags = []
    for name, (t, q, qd, qdd) in (("fit", fit), ("held", held)):
        effort = regressor.matrix(q, qd, qdd) @ truth + rng.normal(scale=0.01, size=q.shape)  # a sensor's noise
        bags.append(write_joint_bag(tmp_path / name, "PSM1", [JointLog(name, "rosbag2", t, q, qd, effort)]))
    argv = ("calibrate-wrench", "--from", bags[0], "--held-out", bags[1], "--out", "cal.json")
    done = _on_a_full_disk(1000, tmp_path, *argv)
    text = done.stdout + done.stderr
    assert done.returncode == 1, text
    assert "could not write --out 'cal.json': File too large (EFBIG); nothing was written there" in done.stderr, text
    assert "Traceback" not in text
    assert sorted(os.listdir(tmp_path)) == ["fit", "held"]


def test_replay_plot_on_a_full_disk_names_the_path_and_leaves_nothing(tmp_path: Path) -> None:
    """replay --plot past the process's file-size limit: exit 1, the plot's path and reason, no traceback, no file."""
    recording = tmp_path / "run.mcap"
    with Recorder(recording) as recorder:
        recorder.write("/deploy/meta", {"target": "sim"})
    done = _on_a_full_disk(recording.stat().st_size + 8192, tmp_path, "replay", recording, "--plot", "plot.png")
    assert done.returncode == 1, done.stdout + done.stderr
    assert "could not write --plot 'plot.png': File too large (EFBIG)" in done.stderr
    assert "Traceback" not in done.stderr
    assert sorted(os.listdir(tmp_path)) == ["run.mcap"]


def test_calibrate_wrench_record_without_room_is_refused_before_the_arm_moves(tmp_path: Path) -> None:
    """calibrate-wrench --record without room for both excitations: refused naming the bag, before any ROS."""
    done = _on_a_full_disk(1_000_000, tmp_path, "calibrate-wrench", "--out", "cal.json", "--record", "bag", *LIVE)
    text = done.stdout + done.stderr
    assert done.returncode == 1, text
    assert "could not write --record 'bag': File too large (EFBIG); a bag of 4000 samples takes about" in text
    assert "excitation" not in text and "Traceback" not in text
    assert os.listdir(tmp_path) == []


def test_deploy_force_replaces_an_earlier_recording(tmp_path: Path) -> None:
    """deploy --record on an earlier recording with --force: the run goes ahead and the file is its recording."""
    record = tmp_path / "run.mcap"
    record.write_bytes(b"an earlier run's recording\n")
    argv = ("deploy", *SWEEP[:4], "--target", "sim", "--record", record, "--force")
    done = subprocess.run(
        [sys.executable, "-m", "tissue_retract", *map(str, argv)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert record.read_bytes().startswith(b"\x89MCAP0\r\n")
    assert sorted(os.listdir(tmp_path)) == ["run.mcap"]
