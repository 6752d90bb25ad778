"""Every file a command reads and every path it writes, against hostile files: refused, named, left as it was.

One table (:data:`ROWS`) holds every command option that names a file: the ones a command reads (logs, bags,
recordings, calibrations, configurations, textures, estimators, checkpoints, demonstrations, registrations)
and the ones it writes. Each row meets every hostile variant (:data:`VARIANTS`) that applies to its kind:

- a file it reads: missing, a folder, a FIFO (opening it would block), a symlink to ``/dev/zero`` (reading it
  never ends), an empty file, garbage bytes, and a sparse file one byte over the reader's size limit;
- a path it writes: a folder, a FIFO, a character device, a symlink to a FIFO, one of the command's own
  inputs, an existing recording without ``--force``, an existing bag.

Each case runs the real command line (:func:`tissue_retract.cli.main`) in a child forked from this process, so
that the modules are imported once: its output goes to a file, an exception escaping ``main`` is printed as the
interpreter would print it, its address space is bounded and it is killed after :data:`TIMEOUT_S` (a reader that
opened the FIFO, or reads ``/dev/zero``). It must exit non-zero with a message naming the option (a checkpoint's
refusal says ``checkpoint``), the path and what is allowed (a regular file, at most so many bytes, a path other than
the input, ...), print no traceback, and leave the hostile path and its folder exactly as they were (a device is still
that device, a FIFO still a FIFO, a file's bytes unchanged, nothing new beside it).

:func:`test_the_table_covers_every_file_option` reads the options off the argument parsers: a command that gains
an option taking a file or a path without a row here fails it. A new reader or writer is covered by adding a row.
A row a command does not yet pass is in :data:`KNOWN` with the reason, and fails strictly (xfail) until it does.

Content hostility that only one reader meets (a malformed recording, a decompression bomb, an insertion of
1e6 m in a joint log, an alias bomb in a configuration) stays with that reader's tests.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import resource
import signal
import stat
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hardware_if.recording.recorder import Recorder
from hardware_if.wrench.bag_writer import write_joint_bag
from hardware_if.wrench.joint_logs import JointLog
from policies.toy_env import TOY_TASK_ID
from tests.forked_cli import default_signals, end_as_the_interpreter, standard_streams
from tests.ros.domains import worker_domain_id

#: Longest a case may take [s]: a refusal takes well under a second; a command that got past its check runs,
#: or blocks on the FIFO, until then.
TIMEOUT_S = 60.0
#: Address space a case may add to this process's [bytes]: a reader of ``/dev/zero`` fails here, not the machine.
EXTRA_MEMORY_BYTES = 2 * 1024**3
#: Cases run at once (the machine has two cores).
PARALLEL = 2

EVALUATE = ("evaluate", "--task", "lift", "--episodes", "1", "--seeds", "1")
SWEEP = ("--task", "lift", "--jobs", "1", "--no-progress")
TOY_TRAIN = ("train", "--task", TOY_TASK_ID, "--algo", "ddpgbc", "--demos", "2", "--episodes", "1")
TOY_TRAIN_TAIL = ("--eval-episodes", "1", "--no-progress", "--no-tensorboard", "--set", "hidden_sizes=[8]")
REPRODUCE = ("reproduce", "--budget", "1", "--tasks", "I", "--algos", "ddpg", "--seeds", "1")
TUNE = ("tune-safety", "--policy", "scripted", *SWEEP, "--grid", "force_limit_n=1:2", "--levels", "1")
#: This worker's own ROS domain, should a live command get past its checks (it then waits and fails).
LIVE = ("--domain-id", str(worker_domain_id()), "--wait", "1")

# Readers' size limits [bytes], written out (a file one byte over is refused from its stat).
CONFIG_BYTES = 1_000_000  # psm_control.inputs.MAX_CONFIG_BYTES: safety configurations, registrations
CALIBRATION_BYTES = 1024 * 1024  # hardware_if.wrench.calibration.MAX_FILE_BYTES
LOG_BYTES = 512 * 1024 * 1024  # hardware_if.wrench.joint_logs.MAX_LOG_BYTES
RECORDING_BYTES = 4 * 1024**3  # hardware_if.recording.reader.MAX_FILE_BYTES
CHECKPOINT_BYTES = 4_000_000_000  # policies.checkpoint._MAX_FILE_BYTES
ESTIMATOR_BYTES = 64 * 1024 * 1024  # policies.perception.network._MAX_FILE_BYTES
TEXTURE_BYTES = 32 * 1024 * 1024  # tissue_retract.cli._camera._MAX_TEXTURE_BYTES
DEMOS_BYTES = 2_000_000_000  # policies.demos.MAX_DEMOS_FILE_BYTES


@dataclass(frozen=True)
class Inputs:
    """The valid files a row's command reads besides the hostile one, made fresh in each case's folder."""

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
    def log(self) -> Path:
        """A free-space joint log (a rosbag2 bag) of 8 s at 200 Hz."""
        return self.root / "log"

    @property
    def calibration(self) -> Path:
        """A wrench calibration file."""
        return self.root / "calibration.json"

    @property
    def recording(self) -> Path:
        """A short deploy recording."""
        return self.root / "run.mcap"

    def make(self, *, log: bool = False) -> Inputs:
        """Write the inputs (the joint log only when the row reads one: it takes a fraction of a second)."""
        self.root.mkdir(parents=True)
        self.safety.write_text("force_limit_n: 2.0\n")
        self.tuned.mkdir()
        (self.tuned / "recommended_safety.yaml").write_text("force_limit_n: 2.0\n")
        self.calibration.write_text(json.dumps({"kind": "wrench_calibration", "arm": "PSM1"}) + "\n")
        with Recorder(self.recording) as recorder:
            recorder.write("/deploy/meta", {"target": "sim"})
        if log:
            t = np.arange(1600) / 200.0
            w = 2 * np.pi * np.array([0.31, 0.23, 0.41, 0.37, 0.29, 0.43])
            q = np.array([0, 0, 0.14, 0, 0, 0]) + 0.1 * np.sin(np.outer(t, w))
            qd = 0.1 * w * np.cos(np.outer(t, w))
            write_joint_bag(self.log, "PSM1", [JointLog("log", "rosbag2", t, q, qd, 0.1 * q)])
        else:
            self.log.write_text("a joint log, never read: the hostile path is checked first\n")
        return self


@dataclass(frozen=True)
class Row:
    """One command option that names a file it reads or a path it writes.

    Attributes:
        command: The command (``("bench", "sensing")``).
        option: The option (``--from``), or the positional argument's metavar (``FILE``).
        kind: ``read``, or what it writes: ``file`` (a result, replaced when it is a regular file), ``folder``
            (a folder of results), ``recording`` (refused when it exists, unless ``--force``) or ``bag`` (a new
            folder only).
        argv: The arguments after the command, given its inputs and the hostile path.
        suffix: The hostile path's suffix (what the option asks for, so that the file's kind is what is refused).
        limit_bytes: A reader's size limit, when it has one.
        named: What the refusal names, when not ``option`` (``recording`` for replay's ``FILE``).
        own_input: For a writer, which of its inputs it must never write.
        log: Whether the row reads the valid joint log.
        empty_allowed: Whether an empty file is valid (a configuration that sets nothing: the defaults).
    """

    command: tuple[str, ...]
    option: str
    kind: str
    argv: Callable[[Inputs, Path], tuple[str | Path, ...]]
    suffix: str = ""
    limit_bytes: int | None = None
    named: str | None = None
    own_input: Callable[[Inputs], Path] | None = None
    log: bool = False
    empty_allowed: bool = False

    @property
    def name(self) -> str:
        """The row's test id: ``bench-sensing--from``."""
        return "-".join(self.command) + "-" + self.option.lstrip("-").lower()

    @property
    def reads(self) -> bool:
        """Whether the option names a file the command reads."""
        return self.kind == "read"


def _read(command: tuple[str, ...], option: str, argv: Callable[..., tuple[Any, ...]], **kw: Any) -> Row:
    return Row(command, option, "read", argv, **kw)


def _write(command: tuple[str, ...], option: str, argv: Callable[..., tuple[Any, ...]], **kw: Any) -> Row:
    kw.setdefault("suffix", ".json")
    return Row(command, option, kw.pop("kind", "file"), argv, **kw)


def _out(i: Inputs) -> Path:
    """Where a reader's command would write: nothing must appear there."""
    return i.root.parent / "out"


def _camera(path: Path) -> str:
    return f"camera:{path}"


# The commands that take each kind of file, as one argv builder per command (the hostile path is h).
def _safety_readers() -> list[Row]:
    cfg = {"suffix": ".yaml", "limit_bytes": CONFIG_BYTES, "empty_allowed": True}
    return [
        _read(("safety", "show"), "--safety-config", lambda i, h: ("--safety-config", h), **cfg),
        _read(("evaluate",), "--safety-config", lambda i, h: (*EVALUATE[1:], "--policy", "scripted",
              "--safety-config", h, "--json", _out(i) / "e.json"), **cfg),
        _read(("deploy",), "--safety-config", lambda i, h: ("--policy", "scripted", "--target", "sim",
              "--safety-config", h, "--record", _out(i) / "r.mcap"), **cfg),
        _read(("robustness",), "--safety-config", lambda i, h: ("--policy", "scripted", *SWEEP, "--vary",
              "stiffness=1", "--trials", "1", "--safety-config", h, "--out", _out(i)), **cfg),
        _read(("tune-safety",), "--safety-config", lambda i, h: (*TUNE[1:], "--episodes", "1", "--safety-config",
              h, "--out", _out(i)), **cfg),
        _read(("bench", "rehearsal"), "--safety-config", lambda i, h: ("--episodes", "1", "--safety-config", h,
              "--json", _out(i) / "b.json", "--domain-id", str(worker_domain_id())), **cfg),
    ]  # fmt: skip


def _model_readers() -> list[Row]:
    ck = {"suffix": ".safetensors", "limit_bytes": CHECKPOINT_BYTES, "named": "checkpoint"}
    est = {"suffix": ".safetensors", "limit_bytes": ESTIMATOR_BYTES, "named": "checkpoint"}
    return [
        _read(("evaluate",), "--policy", lambda i, h: (*EVALUATE[1:], "--policy", h, "--json", _out(i) / "e.json"),
              **ck),
        _read(("deploy",), "--policy", lambda i, h: ("--policy", h, "--target", "sim", "--record",
              _out(i) / "r.mcap"), **ck),
        _read(("robustness",), "--policy", lambda i, h: ("--policy", h, *SWEEP, "--vary", "stiffness=1",
              "--trials", "1", "--out", _out(i)), **ck),
        _read(("tune-safety",), "--policy", lambda i, h: ("--policy", h, *TUNE[3:], "--episodes", "1", "--out",
              _out(i)), **ck),
        _read(("evaluate",), "--perception", lambda i, h: (*EVALUATE[1:], "--policy", "scripted", "--perception",
              _camera(h), "--json", _out(i) / "e.json"), **est),
        _read(("deploy",), "--perception", lambda i, h: ("--policy", "scripted", "--target", "sim", "--perception",
              _camera(h), "--record", _out(i) / "r.mcap"), **est),
        _read(("robustness",), "--perception", lambda i, h: ("--policy", "scripted", *SWEEP, "--vary",
              "stiffness=1", "--trials", "1", "--perception", _camera(h), "--out", _out(i)), **est),
        _read(("train",), "--perception", lambda i, h: ("--task", "lift", "--algo", "ddpgbc", "--demos", "2",
              "--episodes", "1", "--perception", _camera(h), "--out", _out(i), *TOY_TRAIN_TAIL), **est),
        _read(("train",), "--demos-file", lambda i, h: (*TOY_TRAIN[1:], "--demos-file", h, "--out", _out(i),
              *TOY_TRAIN_TAIL), suffix=".npz", limit_bytes=DEMOS_BYTES),
    ]  # fmt: skip


def _texture_readers() -> list[Row]:
    tex = {"suffix": ".png", "limit_bytes": TEXTURE_BYTES}
    return [
        _read(("evaluate",), "--texture", lambda i, h: (*EVALUATE[1:], "--policy", "scripted", "--texture", h,
              "--json", _out(i) / "e.json"), **tex),
        _read(("demo",), "--texture", lambda i, h: ("--task", "lift", "--texture", h, "--out", _out(i) / "d.npz"),
              **tex),
        _read(("deploy",), "--texture", lambda i, h: ("--policy", "scripted", "--target", "sim", "--texture", h,
              "--record", _out(i) / "r.mcap"), **tex),
        _read(("robustness",), "--texture", lambda i, h: ("--policy", "scripted", *SWEEP, "--vary", "stiffness=1",
              "--trials", "1", "--texture", h, "--out", _out(i)), **tex),
        _read(("train-perception",), "--texture", lambda i, h: ("--task", "lift", "--budget-s", "60", "--heldout",
              "10", "--texture", h, "--out", _out(i)), **tex),
        _read(("sim-dvrk",), "--texture", lambda i, h: ("--task", "lift", "--texture", h, *LIVE[:2]), **tex),
    ]  # fmt: skip


def _sensing_readers() -> list[Row]:
    log = {"suffix": ".csv", "limit_bytes": LOG_BYTES, "log": True}
    cal = {"suffix": ".json", "limit_bytes": CALIBRATION_BYTES, "log": True}
    return [
        _read(("calibrate-wrench",), "--from", lambda i, h: ("--from", h, "--out", _out(i) / "c.json"), **log),
        _read(("calibrate-wrench",), "--held-out", lambda i, h: ("--from", i.log, "--held-out", h, "--out",
              _out(i) / "c.json"), **log),
        _read(("calibrate-wrench",), "--check", lambda i, h: ("--check", h, "--from", i.log), **cal),
        _read(("bench", "sensing"), "--from", lambda i, h: ("--draws", "1", "--from", h, "--json",
              _out(i) / "b.json"), **log),
        _read(("bench", "sensing"), "--held-out", lambda i, h: ("--from", i.log, "--held-out", h, "--write-arm",
              _out(i) / "a.json"), **log),
        _read(("bench", "sensing"), "--calibration", lambda i, h: ("--draws", "1", "--from", i.log,
              "--calibration", h), **cal),
        _read(("deploy",), "--wrench-calibration", lambda i, h: ("--policy", "scripted", "--target", "dvrk",
              "--wrench-calibration", h, "--record", _out(i) / "r.mcap", *LIVE), **cal),
        _read(("robustness",), "--wrench-calibration", lambda i, h: ("--policy", "scripted", *SWEEP, "--vary",
              "stiffness=1", "--trials", "1", "--wrench-calibration", h, "--out", _out(i)), **cal),
        _read(("tune-safety",), "--wrench-calibration", lambda i, h: (*TUNE[1:], "--episodes", "1",
              "--wrench-calibration", h, "--out", _out(i)), **cal),
        _read(("deploy",), "--registration", lambda i, h: ("--policy", "scripted", "--target", "dvrk",
              "--registration", h, "--record", _out(i) / "r.mcap", *LIVE), suffix=".json",
              limit_bytes=CONFIG_BYTES),
        _read(("replay",), "FILE", lambda i, h: (h, "--plot", _out(i) / "p.png"), suffix=".mcap",
              limit_bytes=RECORDING_BYTES, named="recording"),
    ]  # fmt: skip


def _writers() -> list[Row]:
    folder = {"kind": "folder", "suffix": ""}
    bench = [
        _write(("bench", name), "--json", lambda i, t, name=name: ("--json", t))
        for name in ("chain", "ros", "rehearsal", "faults", "safety", "train")
    ]
    return [
        _write(("evaluate",), "--json", lambda i, t: (*EVALUATE[1:], "--policy", "scripted", "--safety-config",
               i.safety, "--json", t), own_input=lambda i: i.safety),
        _write(("tissue-test",), "--json", lambda i, t: ("--json", t)),
        _write(("demo",), "--out", lambda i, t: ("--task", "lift", "--episodes", "1", "--out", t), suffix=".npz"),
        _write(("demo",), "--video", lambda i, t: ("--task", "lift", "--episodes", "1", "--video", t),
               suffix=".gif"),
        _write(("train",), "--out", lambda i, t: (*TOY_TRAIN[1:], "--out", t, *TOY_TRAIN_TAIL), **folder),
        _write(("train-perception",), "--out", lambda i, t: ("--task", "lift", "--budget-s", "60", "--heldout",
               "10", "--out", t), **folder),
        _write(("deploy",), "--record", lambda i, t: ("--policy", "scripted", "--task", "lift", "--target", "sim",
               "--safety-config", i.safety, "--record", t), kind="recording", suffix=".mcap",
               own_input=lambda i: i.safety),
        _write(("robustness",), "--out", lambda i, t: ("--policy", "scripted", *SWEEP, "--vary", "stiffness=1",
               "--trials", "1", "--out", t), **folder),
        _write(("tune-safety",), "--out", lambda i, t: (*TUNE[1:], "--episodes", "1", "--safety-config",
               i.tuned / "recommended_safety.yaml", "--out", t), own_input=lambda i: i.tuned, **folder),
        _write(("reproduce",), "--out", lambda i, t: (*REPRODUCE[1:], "--out", t), **folder),
        _write(("reproduce",), "--runs", lambda i, t: (*REPRODUCE[1:], "--out", i.root / "reproduce", "--runs", t),
               **folder),
        _write(("calibrate-wrench",), "--out", lambda i, t: ("--from", i.log, "--out", t),
               own_input=lambda i: i.log),
        _write(("calibrate-wrench",), "--json", lambda i, t: ("--check", i.calibration, "--from", i.log, "--json",
               t), own_input=lambda i: i.calibration),
        _write(("calibrate-wrench",), "--record", lambda i, t: ("--out", i.root / "live.json", "--record", t,
               *LIVE), kind="bag", suffix=""),
        _write(("register",), "--out", lambda i, t: ("--out", t, *LIVE)),
        _write(("sim-dvrk",), "--truth", lambda i, t: ("--task", "lift", "--truth", t, *LIVE[:2]), suffix=".jsonl"),
        _write(("replay",), "--plot", lambda i, t: (i.recording, "--plot", t), suffix=".png",
               own_input=lambda i: i.recording),
        _write(("bench", "env"), "--json", lambda i, t: ("--task", "lift", "--steps", "10", "--render-steps", "1",
               "--json", t)),
        _write(("bench", "sensing"), "--json", lambda i, t: ("--from", i.log, "--json", t),
               own_input=lambda i: i.log),
        _write(("bench", "sensing"), "--write-arm", lambda i, t: ("--from", i.log, "--held-out", i.log,
               "--write-arm", t), own_input=lambda i: i.log),
        _write(("bench", "faults"), "--keep", lambda i, t: ("--only", "no-such-fault", "--keep", t), **folder),
        _write(("bench", "train"), "--out", lambda i, t: ("--tasks", "lift", "--seeds", "1", "--out", t),
               **folder),
        *bench,
    ]  # fmt: skip


#: Every option of every command that names a file it reads or a path it writes.
ROWS = (*_safety_readers(), *_model_readers(), *_texture_readers(), *_sensing_readers(), *_writers())


#: Rows a command does not yet pass, and why (each fails until its command is fixed; then it is removed here).
KNOWN: dict[str, str] = {}


@dataclass(frozen=True)
class Variant:
    """A hostile file: how it is made at a path, which rows it applies to, and the words its refusal says."""

    name: str
    make: Callable[[Path, Inputs], Path]
    applies: Callable[[Row], bool]
    words: tuple[str, ...] = ()


def _missing(path: Path, inputs: Inputs) -> Path:
    return path


def _folder(path: Path, inputs: Inputs) -> Path:
    path.mkdir()
    (path / "kept.txt").write_text("an earlier file\n")
    return path


def _fifo(path: Path, inputs: Inputs) -> Path:
    os.mkfifo(path)
    return path


def _dev_zero(path: Path, inputs: Inputs) -> Path:
    path.symlink_to("/dev/zero")
    return path


def _device(path: Path, inputs: Inputs) -> Path:
    """A character device of /dev/null's numbers where mknod is permitted; else a symlink to /dev/full."""
    try:
        os.mknod(path, stat.S_IFCHR | 0o600, os.makedev(1, 3))
    except PermissionError:
        path.symlink_to("/dev/full")
    return path


def _empty(path: Path, inputs: Inputs) -> Path:
    path.write_bytes(b"")
    return path


def _garbage(path: Path, inputs: Inputs) -> Path:
    path.write_bytes(bytes(np.random.default_rng(7).integers(0, 256, 4096, dtype=np.uint8)))
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


def _reads(row: Row) -> bool:
    return row.reads


def _writes(*kinds: str) -> Callable[[Row], bool]:
    return lambda row: row.kind in kinds


ALL_WRITES = ("file", "folder", "recording", "bag")
#: The hostile variants; ``oversized`` is made per row (one byte over its limit), ``input`` is the row's own.
VARIANTS = (
    Variant("missing", _missing, _reads),
    Variant("folder", _folder, lambda row: row.reads or row.kind in ("file", "recording"), ("folder",)),
    Variant("fifo", _fifo, lambda row: True, ("FIFO",)),
    Variant("dev-zero", _dev_zero, _reads, ("device",)),
    Variant("device", _device, _writes(*ALL_WRITES), ("device",)),
    Variant("empty", _empty, lambda row: row.reads and not row.empty_allowed),
    Variant("garbage", _garbage, _reads),
    Variant("oversized", _missing, lambda row: row.limit_bytes is not None, ("at most",)),
    Variant("symlink-to-fifo", _symlink_to_fifo, _writes(*ALL_WRITES), ("symlink to a FIFO",)),
    Variant("input", _missing, lambda row: row.own_input is not None, ("input",)),
    Variant("existing-recording", _recording, _writes("recording"), ("--force",)),
    Variant("existing-bag", _bag, _writes("bag"), ("does not exist yet",)),
)


def _variants(row: Row) -> list[Variant]:
    return [v for v in VARIANTS if v.applies(row)]


def _state(path: Path) -> Any:
    """What must not change: the path's type, inode and content (a link's target, a folder's listing)."""
    if not os.path.lexists(path):
        return None
    info = os.lstat(path)
    state: list[Any] = [stat.S_IFMT(info.st_mode), info.st_ino, info.st_rdev]
    if stat.S_ISLNK(info.st_mode):
        state += [os.readlink(path), _state(path.resolve())]
    elif stat.S_ISREG(info.st_mode):
        state += [info.st_size, info.st_mtime_ns]
        if info.st_size <= 1 << 20:
            state.append(path.read_bytes())
    elif stat.S_ISDIR(info.st_mode):
        state.append(sorted(os.listdir(path)))
    return state


def _tree(folder: Path) -> list[str]:
    """The files under ``folder`` (an output's folder, made before the inputs are checked, may appear empty)."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_symlink() or not p.is_dir())


@dataclass
class Case:
    """One row against one variant, and what became of it."""

    row: Row
    variant: Variant
    folder: Path
    path: Path
    argv: list[str]
    before: Any
    tree: list[str]
    output: Path
    pid: int = 0
    started: float = 0.0
    status: int | None = None

    def problems(self) -> list[str]:
        """What went wrong (an empty list: refused cleanly)."""
        text = self.output.read_text(errors="replace")
        found = []
        if self.status in (0, None):
            found.append("timed out (blocked or read for ever)" if self.status is None else "exit 0")
        elif self.status < 0:
            found.append(f"killed by signal {-self.status}")
        if "Traceback" in text:
            found.append("a traceback")
        named = self.row.named or self.row.option
        found += [f"no {w!r}" for w in (named, str(self.path), *self.variant.words) if w not in text]
        if _state(self.path) != self.before:
            found.append("the hostile path changed")
        if _tree(self.folder) != self.tree:
            found.append(f"files appeared or went: {sorted(set(_tree(self.folder)) ^ set(self.tree))}")
        return found

    def report(self) -> str:
        """The case, its problems and the end of its output."""
        text = self.output.read_text(errors="replace")[-1200:]
        return f"{self.row.name} x {self.variant.name}: {', '.join(self.problems())}\n{text}"


def _prepare(tmp: Path, row: Row, variant: Variant) -> Case:
    folder = tmp / variant.name
    inputs = Inputs(folder / "in").make(log=row.log)
    if variant.name == "input":
        assert row.own_input is not None
        path = row.own_input(inputs)
    else:
        path = variant.make(folder / f"hostile{row.suffix}", inputs)
    if variant.name == "oversized":
        assert row.limit_bytes is not None
        with path.open("wb") as f:  # sparse: no disk taken
            f.truncate(row.limit_bytes + 1)
    argv = [*row.command, *(str(a) for a in row.argv(inputs, path))]
    if variant.name == "existing-recording":
        argv = [a for a in argv if a != "--force"]
    output = tmp / f"{variant.name}.out"
    return Case(row, variant, folder, path, argv, _state(path), _tree(folder), output)


def _child(case: Case) -> None:
    """In the forked child: run the command as ``python -m tissue_retract`` would, then leave at once."""

    def command() -> int | None:
        os.setpgid(0, 0)  # its own process group: what it starts is ended with it
        os.chdir(case.folder)
        fd = os.open(case.output, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        standard_streams(fd, fd)
        default_signals(signal.SIGINT, signal.SIGTERM, signal.SIGALRM)
        mapped = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # at least what is mapped
        size = int(Path("/proc/self/statm").read_text().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        limit = max(mapped, size) + EXTRA_MEMORY_BYTES
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        from tissue_retract.cli import main

        return main(case.argv)

    end_as_the_interpreter(command, exit_handlers=False)


def _run_all(cases: list[Case]) -> None:
    """Run the cases, :data:`PARALLEL` at a time, each in a child forked from this process."""
    pending, running = list(cases), {}
    sys.stdout.flush()
    sys.stderr.flush()
    while pending or running:
        while pending and len(running) < PARALLEL:
            case = pending.pop(0)
            case.started = time.monotonic()
            case.pid = os.fork()
            if case.pid == 0:
                _child(case)
            running[case.pid] = case
        pid, status = os.waitpid(-1, os.WNOHANG)
        if pid:
            running.pop(pid).status = os.waitstatus_to_exitcode(status)
            _end_group(pid)
            continue
        for case in list(running.values()):
            if time.monotonic() - case.started > TIMEOUT_S:
                _end_group(case.pid)
                os.waitpid(case.pid, 0)
                running.pop(case.pid).status = None
        time.sleep(0.01)


def _end_group(pid: int) -> None:
    """End a case's process group: the child, and what it started (a sim-dvrk, a pool's workers)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, signal.SIGKILL)


def _file_options(parser: argparse.ArgumentParser, command: tuple[str, ...]) -> set[tuple[tuple[str, ...], str]]:
    """The options of ``parser`` (and its subcommands) that name a file or a path, read off their metavar,
    type and help: a metavar of a file (``FILE``, ``F.json``, ``PATH``, ``DIR``, ``BAG``, ``PNG``, a
    ``MODEL``), the type :class:`~pathlib.Path`, or a help that names a checkpoint path."""
    found = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found |= _file_options(sub, (*command, name))
            continue
        if action.nargs == 0 or isinstance(action, argparse._HelpAction):
            continue
        metavar = " ".join(action.metavar) if isinstance(action.metavar, tuple) else str(action.metavar or "")
        words = ("FILE", "PATH", "DIR", "BAG", "PNG", "MODEL", ".json", ".mcap")
        if any(w in metavar for w in words) or action.type is Path or "checkpoint path" in (action.help or ""):
            option = max(action.option_strings, key=len, default=metavar) if action.option_strings else metavar
            found.add((command, option))
    return found


def _every_file_option() -> set[tuple[tuple[str, ...], str]]:
    from tissue_retract.cli import SUBCOMMANDS, build_parser
    from tissue_retract.cli.bench import TARGETS

    found = set()
    for command in SUBCOMMANDS:
        for argv in [[command]] if command != "bench" else [["bench", t] for t in TARGETS]:
            parser = build_parser(argv)
            for name in argv:  # down to the command's own parser
                sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
                parser = sub.choices[name]
            found |= _file_options(parser, tuple(argv))
    return found


def test_the_table_covers_every_file_option() -> None:
    """Every command option that names a file it reads or a path it writes is a row, each row once, and each
    row meets at least five hostile variants."""
    rows = [(row.command, row.option) for row in ROWS]
    assert len(rows) == len(set(rows))
    assert sorted(_every_file_option()) == sorted(rows)
    assert all(len(_variants(row)) >= (6 if row.reads else 3) for row in ROWS), [
        (row.name, len(_variants(row))) for row in ROWS
    ]


@pytest.mark.slow
@pytest.mark.timeout(1800)  # a hang guard for a loaded machine: each case is killed after TIMEOUT_S
@pytest.mark.parametrize(
    "row",
    [
        pytest.param(row, marks=pytest.mark.xfail(strict=True, reason=KNOWN[row.name])) if row.name in KNOWN else row
        for row in ROWS
    ],
    ids=lambda row: row.name,
)
def test_a_hostile_file_is_refused_by_name_and_left_as_it_was(tmp_path: Path, row: Row) -> None:
    """Each hostile variant: exit non-zero naming the option and what is allowed, no traceback, no hang, and the
    path and its folder left exactly as they were."""
    with tempfile.TemporaryDirectory(dir=tmp_path) as scratch:
        cases = [_prepare(Path(scratch), row, variant) for variant in _variants(row)]
        _run_all(cases)
        failures = [case.report() for case in cases if case.problems()]
    print(f"\n{row.name}: {len(cases)} hostile variants, {len(failures)} not refused cleanly")
    assert not failures, "\n\n".join(failures)
