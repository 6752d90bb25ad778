"""Every path a command writes, against hostile targets: refused before any work, named, nothing touched.

One table (:data:`OUTPUTS`) holds every command option that writes a file or a folder; each row is run in a
fresh interpreter (``python -m tissue_retract ...``) against each hostile target that applies to it
(:data:`TARGETS`): a FIFO, a character device, a folder, a symlink to a FIFO, one of the command's own
inputs, and an existing recording without ``--force``. Each must exit non-zero with a message naming the
option and what is allowed, print no traceback, and leave the target as it was (its type, inode and
content) with nothing new beside it. A new writer is covered by adding a row.

A full disk is met for real, in the commands themselves: a child with a small ``RLIMIT_FSIZE`` (SIGXFSZ
ignored), where every write past the limit fails with ``EFBIG`` as a full disk fails with ``ENOSPC``.

Commands that need ROS or a console (``calibrate-wrench --record``, ``register --out``, ``sim-dvrk
--truth``) check their outputs before they connect, so they are run here too; a refused path never gets
that far.
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import textwrap
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hardware_if.recording.recorder import Recorder
from hardware_if.wrench.bag_writer import write_joint_bag
from hardware_if.wrench.joint_logs import JointLog
from policies.toy_env import TOY_TASK_ID
from psm_control.effort_model import EffortRegressor, independent_columns
from tests.ros.domains import worker_domain_id

#: A command run in the simulation as briefly as it can be (for a row whose check would let it run).
EVALUATE = ("evaluate", "--task", "lift", "--episodes", "1", "--seeds", "1", "--policy", "scripted")
SWEEP = ("--policy", "scripted", "--task", "lift", "--jobs", "1", "--no-progress")
TOY_TRAIN = ("train", "--task", TOY_TASK_ID, "--algo", "ddpgbc", "--demos", "2", "--episodes", "1")
TOY_TRAIN_TAIL = ("--eval-episodes", "1", "--no-progress", "--no-tensorboard", "--set", "hidden_sizes=[8]")
REPRODUCE = ("reproduce", "--budget", "1", "--tasks", "I", "--algos", "ddpg", "--seeds", "1")
#: This worker's own ROS domain, should a live command get past its checks (it then waits and fails).
LIVE = ("--domain-id", str(worker_domain_id()), "--wait", "1")


@dataclass(frozen=True)
class Inputs:
    """The input files a row's command reads, made fresh in each case's folder."""

    root: Path

    @property
    def safety(self) -> Path:
        """A valid safety configuration."""
        return self.root / "safety.yaml"

    @property
    def tuned(self) -> Path:
        """A folder whose ``recommended_safety.yaml`` is the safety configuration tune-safety reads."""
        return self.root / "tuned"

    @property
    def bag(self) -> Path:
        """A joint log named as a bag (never read: the output is checked first)."""
        return self.root / "bag.mcap"

    @property
    def calibration(self) -> Path:
        """A wrench calibration file."""
        return self.root / "calibration.json"

    @property
    def recording(self) -> Path:
        """A short deploy recording."""
        return self.root / "run.mcap"

    def make(self) -> Inputs:
        """Write the inputs."""
        self.root.mkdir(parents=True)
        self.safety.write_text("force_limit_n: 2.0\n")
        self.tuned.mkdir()
        (self.tuned / "recommended_safety.yaml").write_text("force_limit_n: 2.0\n")
        self.bag.write_bytes(b"a joint log\n")
        self.calibration.write_text(json.dumps({"kind": "wrench_calibration", "arm": "PSM1"}) + "\n")
        with Recorder(self.recording) as recorder:
            recorder.write("/deploy/meta", {"target": "sim"})
        return self


@dataclass(frozen=True)
class Output:
    """One command option that writes a path.

    Attributes:
        name: The row's name (the test's id).
        option: The option that names the path; the refusal must name it.
        argv: The command, given its inputs and the path to write.
        kind: ``file`` (a result, replaced when it is a regular file), ``folder`` (a folder of results),
            ``recording`` (refused when it exists, unless ``--force``) or ``bag`` (a new folder only).
        suffix: The path's suffix (some options require one).
        own_input: Which of the inputs the command reads, as a target it must not write; None when it reads
            none that the path could be.
    """

    name: str
    option: str
    argv: Callable[[Inputs, Path], tuple[str | Path, ...]]
    kind: str = "file"
    suffix: str = ".json"
    own_input: Callable[[Inputs], Path] | None = None


#: Every option of every command that writes a file or a folder.
OUTPUTS = (
    Output(
        "evaluate-json",
        "--json",
        lambda i, t: (*EVALUATE, "--safety-config", i.safety, "--json", t),
        own_input=lambda i: i.safety,
    ),
    Output("tissue-test-json", "--json", lambda i, t: ("tissue-test", "--json", t)),
    Output("demo-out", "--out", lambda i, t: ("demo", "--task", "lift", "--episodes", "1", "--out", t), suffix=".npz"),
    Output(
        "demo-video", "--video", lambda i, t: ("demo", "--task", "lift", "--episodes", "1", "--video", t), suffix=".gif"
    ),
    Output("train-out", "--out", lambda i, t: (*TOY_TRAIN, "--out", t, *TOY_TRAIN_TAIL), kind="folder", suffix=""),
    Output(
        "train-perception-out",
        "--out",
        lambda i, t: ("train-perception", "--task", "lift", "--budget-s", "60", "--heldout", "10", "--out", t),
        kind="folder",
        suffix="",
    ),
    Output(
        "deploy-record",
        "--record",
        lambda i, t: ("deploy", *SWEEP[:4], "--target", "sim", "--safety-config", i.safety, "--record", t),
        kind="recording",
        suffix=".mcap",
        own_input=lambda i: i.safety,
    ),
    Output(
        "robustness-out",
        "--out",
        lambda i, t: ("robustness", *SWEEP, "--vary", "stiffness=1", "--trials", "1", "--out", t),
        kind="folder",
        suffix="",
    ),
    Output(
        "tune-safety-out",
        "--out",
        lambda i, t: (
            "tune-safety",
            *SWEEP,
            "--grid",
            "force_limit_n=1:2",
            "--levels",
            "1",
            "--episodes",
            "1",
            "--safety-config",
            i.tuned / "recommended_safety.yaml",
            "--out",
            t,
        ),
        kind="folder",
        suffix="",
        own_input=lambda i: i.tuned,
    ),
    Output("reproduce-out", "--out", lambda i, t: (*REPRODUCE, "--out", t), kind="folder", suffix=""),
    Output(
        "reproduce-runs",
        "--runs",
        lambda i, t: (*REPRODUCE, "--out", i.root / "reproduce", "--runs", t),
        kind="folder",
        suffix="",
    ),
    Output(
        "calibrate-out",
        "--out",
        lambda i, t: ("calibrate-wrench", "--from", i.bag, "--out", t),
        own_input=lambda i: i.bag,
    ),
    Output(
        "calibrate-check-json",
        "--json",
        lambda i, t: ("calibrate-wrench", "--check", i.calibration, "--from", i.bag, "--json", t),
        own_input=lambda i: i.calibration,
    ),
    Output(
        "calibrate-record",
        "--record",
        lambda i, t: ("calibrate-wrench", "--out", i.root / "live.json", "--record", t, *LIVE),
        kind="bag",
        suffix="",
    ),
    Output("register-out", "--out", lambda i, t: ("register", "--out", t, *LIVE)),
    Output(
        "sim-dvrk-truth",
        "--truth",
        lambda i, t: ("sim-dvrk", "--task", "lift", "--truth", t, *LIVE[:2]),
        suffix=".jsonl",
    ),
    Output(
        "replay-plot",
        "--plot",
        lambda i, t: ("replay", i.recording, "--plot", t),
        suffix=".png",
        own_input=lambda i: i.recording,
    ),
    Output(
        "bench-json",
        "--json",
        lambda i, t: ("bench", "env", "--task", "lift", "--steps", "10", "--render-steps", "1", "--json", t),
    ),
    Output(
        "bench-sensing-json",
        "--json",
        lambda i, t: ("bench", "sensing", "--from", i.bag, "--json", t),
        own_input=lambda i: i.bag,
    ),
    Output(
        "bench-sensing-write-arm",
        "--write-arm",
        lambda i, t: ("bench", "sensing", "--from", i.bag, "--held-out", i.bag, "--write-arm", t),
        own_input=lambda i: i.bag,
    ),
    Output(
        "bench-faults-keep",
        "--keep",
        lambda i, t: ("bench", "faults", "--only", "no-such-fault", "--keep", t),
        kind="folder",
        suffix="",
    ),
    Output(
        "bench-train-out",
        "--out",
        lambda i, t: ("bench", "train", "--tasks", "lift", "--seeds", "1", "--out", t),
        kind="folder",
        suffix="",
    ),
)


def _fifo(path: Path, inputs: Inputs) -> Path:
    os.mkfifo(path)
    return path


def _device(path: Path, inputs: Inputs) -> Path:
    os.mknod(path, stat.S_IFCHR | 0o600, os.makedev(1, 3))  # /dev/null's numbers
    return path


def _folder(path: Path, inputs: Inputs) -> Path:
    path.mkdir()
    (path / "kept.txt").write_text("an earlier file\n")
    return path


def _symlink_to_fifo(path: Path, inputs: Inputs) -> Path:
    fifo = path.with_name("the-fifo")
    os.mkfifo(fifo)
    path.symlink_to(fifo)
    return path


def _recording(path: Path, inputs: Inputs) -> Path:
    path.write_bytes(b"an earlier run's recording\n")
    return path


def _bag(path: Path, inputs: Inputs) -> Path:
    path.mkdir()
    (path / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    return path


@dataclass(frozen=True)
class Target:
    """A hostile target: how it is made, which kinds of output it applies to, and the words its refusal says."""

    name: str
    make: Callable[[Path, Inputs], Path]
    kinds: tuple[str, ...]
    words: tuple[str, ...]


def _can_make_devices() -> bool:
    probe = Path(os.environ.get("TMPDIR", "/tmp")) / f"tr-mknod-probe-{os.getpid()}"
    try:
        os.mknod(probe, stat.S_IFCHR | 0o600, os.makedev(1, 3))
    except OSError:
        return False
    probe.unlink()
    return True


ALL = ("file", "folder", "recording", "bag")
#: The hostile targets; ``input`` and ``existing`` are made per row (its own input, an earlier recording).
TARGETS = (
    Target("fifo", _fifo, ALL, ("FIFO",)),
    Target("device", _device, ALL, ("character device",)),
    Target("folder", _folder, ("file", "recording"), ("folder",)),
    Target("symlink-to-fifo", _symlink_to_fifo, ALL, ("symlink to a FIFO",)),
    Target("input", lambda path, inputs: path, ALL, ("input",)),
    Target("existing-recording", _recording, ("recording",), ("--force",)),
    Target("existing-bag", _bag, ("bag",), ("does not exist yet",)),
)


def _state(path: Path) -> Any:
    """What must not change: the file's type, inode and content (a link's target, a folder's listing)."""
    info = os.lstat(path)
    state: list[Any] = [stat.S_IFMT(info.st_mode), info.st_ino]
    if stat.S_ISLNK(info.st_mode):
        state += [os.readlink(path), _state(path.resolve())]
    elif stat.S_ISREG(info.st_mode):
        state.append(path.read_bytes())
    elif stat.S_ISDIR(info.st_mode):
        state.append(sorted(os.listdir(path)))
    return state


def _tree(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def _case(tmp: Path, row: Output, target: Target) -> dict[str, Any]:
    """Make the target, run the row's command on it, and say what went wrong (an empty list: nothing)."""
    folder = tmp / f"{row.name}-{target.name}"
    inputs = Inputs(folder / "in").make()
    if target.name == "input":
        assert row.own_input is not None
        path = row.own_input(inputs)
    else:
        path = target.make(folder / f"out{row.suffix}", inputs)
    before, tree = _state(path), _tree(folder)
    argv = [str(a) for a in row.argv(inputs, path)]
    if target.name == "existing-recording":
        argv = [a for a in argv if a != "--force"]
    try:
        done = subprocess.run(
            [sys.executable, "-m", "tissue_retract", *argv],
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
            cwd=folder,
        )
        status, text = done.returncode, done.stdout + done.stderr
    except subprocess.TimeoutExpired as e:  # a writer that opened a FIFO blocks there: nothing refused it
        status, text = None, f"timed out: {e.stdout!r} {e.stderr!r}"
    words = (row.option, "not allowed: expected", *target.words)
    problems = []
    if status in (0, None):
        problems.append(f"exit {status}")
    if "Traceback" in text:
        problems.append("a traceback")
    problems += [f"no {word!r}" for word in words if word not in text]
    if _state(path) != before:
        problems.append("the target changed")
    if _tree(folder) != tree:
        problems.append(f"files appeared or went: {sorted(set(_tree(folder)) ^ set(tree))}")
    return {"case": f"{row.name} x {target.name}", "problems": problems, "text": text[-800:]}


def _targets(row: Output) -> list[Target]:
    return [t for t in TARGETS if row.kind in t.kinds and (t.name != "input" or row.own_input is not None)]


def test_the_table_covers_every_output_option() -> None:
    """Every command option that names a written path is a row; every row meets at least four hostile targets."""
    options = {(row.argv(Inputs(Path("i")), Path("t"))[0], row.option) for row in OUTPUTS}
    expected = {
        ("evaluate", "--json"),
        ("tissue-test", "--json"),
        ("demo", "--out"),
        ("demo", "--video"),
        ("train", "--out"),
        ("train-perception", "--out"),
        ("deploy", "--record"),
        ("robustness", "--out"),
        ("tune-safety", "--out"),
        ("reproduce", "--out"),
        ("reproduce", "--runs"),
        ("calibrate-wrench", "--out"),
        ("calibrate-wrench", "--json"),
        ("calibrate-wrench", "--record"),
        ("register", "--out"),
        ("sim-dvrk", "--truth"),
        ("replay", "--plot"),
        ("bench", "--json"),
        ("bench", "--write-arm"),
        ("bench", "--keep"),
        ("bench", "--out"),
    }
    assert options == expected
    assert len({row.name for row in OUTPUTS}) == len(OUTPUTS)
    assert all(len(_targets(row)) >= 3 for row in OUTPUTS)


def _run_row(tmp_path: Path, row: Output, targets: list[Target]) -> None:
    with ThreadPoolExecutor(max_workers=2) as pool:
        done = list(pool.map(lambda target: _case(tmp_path, row, target), targets))
    failures = [f"{d['case']}: {', '.join(d['problems'])}\n{d['text']}" for d in done if d["problems"]]
    print(f"\n{row.name}: {len(done)} hostile targets, {len(failures)} not refused cleanly")
    assert not failures, "\n\n".join(failures)


@pytest.mark.slow
@pytest.mark.timeout(1800)  # a few fresh interpreters per row on a loaded machine
@pytest.mark.parametrize("row", OUTPUTS, ids=lambda row: row.name)
def test_a_hostile_output_path_is_refused_and_left_as_it_was(tmp_path: Path, row: Output) -> None:
    """A FIFO, folder, symlink to a FIFO, input or earlier recording as output: named, refused, untouched."""
    _run_row(tmp_path, row, [t for t in _targets(row) if t.name != "device"])


@pytest.mark.slow
@pytest.mark.skipif(not _can_make_devices(), reason="making a character device (mknod) is not permitted here")
@pytest.mark.parametrize("row", OUTPUTS, ids=lambda row: row.name)
def test_a_device_as_output_path_is_refused_and_left_as_it_was(tmp_path: Path, row: Output) -> None:
    """A character device (/dev/null's numbers) as output: named, refused, still the same device."""
    _run_row(tmp_path, row, [t for t in _targets(row) if t.name == "device"])


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
