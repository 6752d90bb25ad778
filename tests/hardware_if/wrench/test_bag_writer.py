"""The excitation's bag: its room taken before the arm moves, written whole or not at all, failures named."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from hardware_if.wrench.bag_writer import reserve_bag_space, write_joint_bag
from hardware_if.wrench.joint_logs import JointLog, read_joint_log
from psm_control.errors import OutputFileError


def _log(samples: int) -> JointLog:
    rng = np.random.default_rng(0)
    return JointLog(
        "excitation", "live", np.arange(samples) / 100.0, *(rng.normal(size=(samples, 6)) for _ in range(3))
    )


def test_a_reserved_bag_is_written_in_place_with_nothing_beside_it(tmp_path: Path) -> None:
    """reserve_bag_space then write_joint_bag: the bag reads back whole; no hidden folder or reserve is left."""
    space = reserve_bag_space(tmp_path / "bag", 400)
    assert space.reserve.stat().st_size == space.reserved_bytes > 400 * 316
    bag = write_joint_bag(tmp_path / "bag", "PSM1", [_log(200), _log(200)], space=space)
    assert os.listdir(tmp_path) == ["bag"]
    assert len(read_joint_log(bag).t_s) == 400


def test_an_existing_bag_or_a_fifo_is_refused_before_anything_is_made(tmp_path: Path) -> None:
    """A bag path that exists (a folder, a FIFO) is refused naming --record; nothing appears beside it."""
    (tmp_path / "old").mkdir()
    os.mkfifo(tmp_path / "fifo")
    for name, words in (("old", "does not exist yet"), ("fifo", "FIFO")):
        with pytest.raises(OutputFileError, match=words):
            reserve_bag_space(tmp_path / name, 10)
    assert sorted(os.listdir(tmp_path)) == ["fifo", "old"]


def test_a_bag_that_fails_at_the_end_names_the_path_and_leaves_nothing(tmp_path: Path) -> None:
    """A bag the disk cannot take after its reserve (the file-size limit): named, nothing left at or beside it."""
    code = textwrap.dedent(
        """
        import resource, signal
        import numpy as np
        from hardware_if.wrench.bag_writer import reserve_bag_space, write_joint_bag
        from hardware_if.wrench.joint_logs import JointLog
        from psm_control.errors import OutputWriteError
        space = reserve_bag_space("bag", 10)  # a reserve for 10 samples: the disk fills before the bag is written
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (space.reserved_bytes, resource.RLIM_INFINITY))
        log = JointLog("x", "live", np.arange(4000) / 100.0, *(np.zeros((4000, 6)) for _ in range(3)))
        try:
            write_joint_bag("bag", "PSM1", [log], space=space)
        except OutputWriteError as e:
            print(e)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "could not write --record 'bag': File too large (EFBIG); nothing was written there"
    assert os.listdir(tmp_path) == []


def test_a_bag_names_the_console_that_served_the_arm(tmp_path: Path) -> None:
    """A bag written with its console keeps it in metadata.yaml, where bench sensing reads which console it was."""
    from tissue_retract.cli.bench_sensing import _log_console

    named = write_joint_bag(tmp_path / "named", "PSM1", [_log(200)], console="sim-dvrk")
    unnamed = write_joint_bag(tmp_path / "unnamed", "PSM1", [_log(200)])
    assert _log_console(named, "rosbag2")[0] == "sim-dvrk"
    assert _log_console(unnamed, "rosbag2")[0] == "unknown"
