"""Joint logs: bags written by rosbags' own writer read back, and bad logs get named errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bags import write_bag
from rosbags.rosbag2 import StoragePlugin

from hardware_if.wrench.bag_writer import write_joint_bag
from hardware_if.wrench.joint_logs import (
    LND_COUPLING,
    JointLog,
    LogLayoutError,
    MissingTopicError,
    NoEffortsError,
    NonFiniteLogError,
    TruncatedLogError,
    read_joint_log,
)


def _samples(n: int = 50) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) / 100.0
    q = np.column_stack([0.1 * np.sin(t + j) for j in range(6)])
    q[:, 2] += 0.12
    qd = np.column_stack([0.1 * np.cos(t + j) for j in range(6)])
    effort = np.column_stack([0.01 * (j + 1) * np.cos(2 * t) for j in range(6)])
    return q, qd, effort


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_a_bag_reads_back_what_the_writer_wrote(tmp_path: Path, storage: StoragePlugin) -> None:
    """Positions, velocities, efforts and stamps come back in the dVRK's joint order, from a folder or its file."""
    q, qd, effort = _samples()
    shuffled = ["wrist_yaw", "yaw", "roll", "insertion", "wrist_pitch", "pitch"]
    bag = write_bag(tmp_path / "bag", q, qd, effort, storage=storage, names=shuffled)
    for path in (bag, next(bag.glob("*.mcap" if storage == StoragePlugin.MCAP else "*.db3"))):
        log = read_joint_log(path)
        assert log.layout == "rosbag2"
        np.testing.assert_allclose(log.q, q)
        np.testing.assert_allclose(log.qd, qd)
        np.testing.assert_allclose(log.effort, effort)
        np.testing.assert_allclose(log.t_s, np.arange(len(q)) / 100.0, atol=1e-6)
        assert log.rate_hz == pytest.approx(100.0, rel=1e-4)


def test_the_arm_picks_the_namespace(tmp_path: Path) -> None:
    """--arm PSM2 reads /PSM2/measured_js; the default PSM1 is told which topics the bag has."""
    q, qd, effort = _samples()
    bag = write_bag(tmp_path / "bag", q, qd, effort, topic="/PSM2/measured_js")
    assert read_joint_log(bag, arm="PSM2").q.shape == (len(q), 6)
    with pytest.raises(MissingTopicError, match=r"/PSM1/measured_js.*/PSM2/measured_js"):
        read_joint_log(bag)


def test_joint_states_without_efforts_are_named(tmp_path: Path) -> None:
    """A bag whose joint states carry no efforts gets NoEffortsError."""
    q, qd, _ = _samples()
    bag = write_bag(tmp_path / "bag", q, qd, np.zeros((len(q), 0)))
    with pytest.raises(NoEffortsError, match="six efforts"):
        read_joint_log(bag)


def test_a_nan_is_named_with_its_joint_and_sample(tmp_path: Path) -> None:
    """A NaN effort gets NonFiniteLogError naming the joint and the sample."""
    q, qd, effort = _samples()
    effort[7, 2] = np.nan
    bag = write_bag(tmp_path / "bag", q, qd, effort)
    with pytest.raises(NonFiniteLogError, match="effort of joint insertion is nan at sample 7"):
        read_joint_log(bag)


def test_a_truncated_bag_is_named(tmp_path: Path) -> None:
    """A storage file cut short gets TruncatedLogError, not a traceback from the library."""
    q, qd, effort = _samples(400)
    bag = write_bag(tmp_path / "bag", q, qd, effort)
    storage = next(bag.glob("*.mcap"))
    data = storage.read_bytes()
    storage.write_bytes(data[: len(data) // 2])
    with pytest.raises(TruncatedLogError):
        read_joint_log(bag)


def test_other_files_are_named(tmp_path: Path) -> None:
    """A missing path, an unknown suffix and a CSV of the wrong width get LogLayoutError."""
    with pytest.raises(LogLayoutError, match="an existing"):
        read_joint_log(tmp_path / "missing.mcap")
    (tmp_path / "notes.txt").write_text("hello\n")
    with pytest.raises(LogLayoutError):
        read_joint_log(tmp_path / "notes.txt")
    (tmp_path / "wide.csv").write_text("\n".join(",".join(["0.1"] * 12) for _ in range(20)) + "\n")
    with pytest.raises(LogLayoutError, match="12 columns"):
        read_joint_log(tmp_path / "wide.csv")


def test_the_wpi_layout_undoes_the_instrument_coupling(tmp_path: Path) -> None:
    """A 21-column WPI log's wrist and jaw come back in joint space: C q_motor, C^-T tau_motor."""
    rng = np.random.default_rng(1)
    rows = rng.normal(size=(30, 21))
    np.savetxt(tmp_path / "one_results.csv", rows, delimiter=",")
    log = read_joint_log(tmp_path / "one_results.csv")
    assert log.layout == "wpi" and log.rate_hz == pytest.approx(200.0)
    np.testing.assert_allclose(log.q[:, :4], rows[:, :4])
    np.testing.assert_allclose(log.q[:, 4:6], (rows[:, 4:7] @ LND_COUPLING.T)[:, :2])
    # Virtual work is kept: tau_motor . qd_motor = tau_joint . qd_joint over the three coupled joints.
    joint_tau = np.linalg.solve(LND_COUPLING.T, rows[:, 14:21][:, 4:7].T).T
    np.testing.assert_allclose(log.effort[:, 4:6], joint_tau[:, :2])
    power_motor = np.sum(rows[:, 18:21] * rows[:, 11:14], axis=1)
    power_joint = np.sum(joint_tau * (rows[:, 11:14] @ LND_COUPLING.T), axis=1)
    np.testing.assert_allclose(power_motor, power_joint)


def test_a_radiang_folder_takes_its_time_column(tmp_path: Path) -> None:
    """A radiang folder whose torque file leads with the sample time (its Data_Pos layout) reads the joints after
    it, at that time; one without reads at the rate its name implies."""
    q, qd, effort = _samples(40)
    jaw = np.zeros((40, 1))
    t_s = 0.004 * np.arange(1, 41)
    for folder, timed in (("Data_Pos", True), ("Data250", False)):
        (tmp_path / folder).mkdir()
        torque = np.hstack([effort, jaw])
        np.savetxt(tmp_path / folder / "data_position.csv", np.hstack([q, jaw]), delimiter=",")
        np.savetxt(tmp_path / folder / "data_velocity.csv", np.hstack([qd, jaw]), delimiter=",")
        np.savetxt(
            tmp_path / folder / "data_torque.csv", np.hstack([t_s[:, None], torque]) if timed else torque, delimiter=","
        )
        log = read_joint_log(tmp_path / folder)
        assert log.layout == "radiang" and log.rate_hz == pytest.approx(250.0)
        np.testing.assert_allclose(log.effort, effort)
        np.testing.assert_allclose(log.q, q)
        if timed:
            np.testing.assert_allclose(log.t_s, t_s)


def test_a_written_joint_bag_reads_back_log_after_log(tmp_path: Path) -> None:
    """write_joint_bag keeps every sample of each log, in order, under /ARM/measured_js, one second apart."""
    q, qd, effort = _samples()
    first = JointLog("a", "live", np.arange(len(q)) / 100.0, q, qd, effort)
    second = JointLog("b", "live", np.arange(len(q)) / 100.0, q[::-1], qd[::-1], effort[::-1])
    bag = write_joint_bag(tmp_path / "bag", "PSM2", [first, second], start_s=1000.0)
    log = read_joint_log(bag, arm="PSM2")
    np.testing.assert_allclose(log.q, np.concatenate([q, q[::-1]]))
    np.testing.assert_allclose(log.effort, np.concatenate([effort, effort[::-1]]))
    gap = log.t_s[len(q)] - log.t_s[len(q) - 1]
    assert gap == pytest.approx(1.0, abs=1e-6)
