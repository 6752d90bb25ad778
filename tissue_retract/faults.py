"""The deploy's fault matrix: faulty policies, fault injection over ROS 2, and a runner for each fault.

Each :class:`Fault` runs a real ``tissue-retract deploy`` (and, for the dVRK target, a real
``tissue-retract sim-dvrk`` on a loopback-only ROS domain of its own) as child processes and injects one
fault: a policy that raises, exits, returns garbage or overruns; a non-finite message on a subscribed
topic; a tracking error; an arm disabled mid-episode or never enabled; a console that dies; a console whose
clock on ``measured_js`` freezes, goes back or jumps (``sim-dvrk --stamp-fault``); a stop signal; a SIGKILL
of the deploy. :func:`run_fault` reports the exit status, the hold line and what the recording
kept. ``tissue-retract bench faults`` runs them all; the tests run them one by one, those that leave their
console as they found it on one :class:`SharedConsole`.

Nothing here is timed by sleeping: the faulty policies (:class:`FaultPolicy`) act at a chosen episode
and step and print a line there (``fault policy: episode E step S``), after that step's ticks; the
runner acts when it reads that line, and a gated policy waits for the runner's go (a file) before
returning, so an injection always lands mid-episode whatever the machine's load.

The policies are set with environment variables: ``TISSUE_RETRACT_FAULT_AT`` (``"episode:step"``,
default ``"0:3"``) and ``TISSUE_RETRACT_FAULT_GATE`` (the go file of :class:`Gate`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import queue
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hardware_if.common.errors import DvrkTimeoutError
from hardware_if.common.executor import make_executor
from hardware_if.common.network import local_ros_env
from hardware_if.recording.replay import load_recording, summarize_recording
from psm_control.errors import ConfigurationError
from psm_control.robot import PsmModel
from sim.expert import ScriptedExpert
from sim.sweep.stopping import end_with_parent
from tissue_retract.fault_setups import MOVED_OFFSET_RAD, move_arm_off_start, small_filesystem, wait_until_served

__all__ = [
    "FAULTS",
    "Exits",
    "Fault",
    "FaultPolicy",
    "FaultResult",
    "Gate",
    "Hang",
    "Raises",
    "ReturnsNan",
    "SharedConsole",
    "Slow",
    "WrongShape",
    "run_fault",
]

#: Environment variable: where the fault policies act, ``"episode:step"``.
AT_VARIABLE = "TISSUE_RETRACT_FAULT_AT"
#: Environment variable: the file whose creation lets a :class:`Gate` policy go on.
GATE_VARIABLE = "TISSUE_RETRACT_FAULT_GATE"
#: The line a fault policy prints when it acts.
MARK = "fault policy: episode"
#: Actions that act before the deploy's first step (no policy line to wait for).
_AT_START = ("early:", "calibration", "listener", "other-console")
#: Actions whose fault runs on a console of its own: the console killed, the arm disabled or commanded by
#: another node (the console then says so on ``error`` or ``warning``), a calibration interrupted with the arm
#: mid-excitation, an arm moved off its start with the jaw where the fault before left it, and a NaN that must
#: reach the deploy before any console serves the arm.
_OWN_CONSOLE = ("kill-console", "disable", "rogue", "second-deploy", "interrupt-calibration", "move-arm", "early:")
#: A refused or stopped run's files: none (the table's recording column).
NOTHING_WRITTEN = "nothing written"
#: Longest a gated or hanging policy waits before giving up (a guard; the runner acts long before) [s].
GUARD_S = 600.0


class FaultPolicy:
    """The scripted expert, with a fault at one step (``TISSUE_RETRACT_FAULT_AT``, default ``0:3``)."""

    def __init__(self, env: Any) -> None:
        self._expert = ScriptedExpert(env)
        at = os.environ.get(AT_VARIABLE, "0:3")
        try:
            episode, step = (int(v) for v in at.split(":"))
        except ValueError:
            raise ConfigurationError(AT_VARIABLE, at, "'episode:step', two integers") from None
        self._at = (episode, step)
        self._episode = -1
        self._step = 0

    def reset(self) -> None:
        self._expert.reset()
        self._episode += 1
        self._step = 0

    def __call__(self, observation: dict[str, np.ndarray]) -> Any:
        action = self._expert(observation)
        here = (self._episode, self._step)
        self._step += 1
        if here != self._at:
            return action
        print(f"{MARK} {here[0]} step {here[1]}", flush=True)
        return self.fault(action)

    def fault(self, action: np.ndarray) -> Any:
        """What the policy does at the fault step (the expert's action here)."""
        return action


class Raises(FaultPolicy):
    """Raises RuntimeError."""

    def fault(self, action: np.ndarray) -> Any:
        raise RuntimeError("injected policy failure")


class Exits(FaultPolicy):
    """Raises SystemExit(0), as a stray ``sys.exit()`` in a policy would."""

    def fault(self, action: np.ndarray) -> Any:
        raise SystemExit(0)


class ReturnsNan(FaultPolicy):
    """Returns five NaN."""

    def fault(self, action: np.ndarray) -> Any:
        return np.full(5, np.nan)


class WrongShape(FaultPolicy):
    """Returns three numbers instead of five."""

    def fault(self, action: np.ndarray) -> Any:
        return np.zeros(3)


class Slow(FaultPolicy):
    """Takes 2 s for one step (the policy's own delay is the fault)."""

    def fault(self, action: np.ndarray) -> Any:
        time.sleep(2.0)
        return action


class Hang(FaultPolicy):
    """Never returns (until a signal ends the deploy): a deploy caught mid-episode for a signal."""

    def fault(self, action: np.ndarray) -> Any:
        time.sleep(GUARD_S)
        return action


class Gate(FaultPolicy):
    """Waits at the fault step until the file ``TISSUE_RETRACT_FAULT_GATE`` exists, then goes on."""

    def fault(self, action: np.ndarray) -> Any:
        gate = Path(os.environ[GATE_VARIABLE])
        deadline = time.monotonic() + GUARD_S
        while not gate.exists() and time.monotonic() < deadline:
            time.sleep(0.005)  # polling the runner's go, not timing anything
        return action


# -- the matrix ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Fault:
    """One fault of the matrix.

    Attributes:
        name: Short name (the table's first column).
        target: ``dvrk`` (against a sim-dvrk child) or ``sim``.
        policy: The faulty policy (a class of this module).
        action: What the runner does when the policy's line appears: ``""`` (the policy is the fault),
            ``nan:<topic>``, ``early:<topic>`` (a NaN as the deploy starts), ``tracking``, ``disable``,
            ``kill-console``, ``signal:<NAME>``, ``kill-deploy``, ``calibration`` (a calibration file whose
            force overflows), ``second-force`` (another node publishes 0 N on the arm's force topics),
            ``second-camera`` (another node publishes the endoscope's images), ``dead-camera`` (the
            endoscope's render process killed, another node's images behind it), ``listener`` (a node that
            subscribes to the arm's topics, as a recorder does, from before the deploy starts),
            ``other-arm`` / ``exact-sensing`` / ``other-console`` (a calibration file made for PSM2, fitted
            on a console that reports the exact force, or fitted on a real dVRK and used on sim-dvrk),
            ``interrupt-calibration`` (``calibrate-wrench`` stopped by SIGINT during its first excitation,
            in place of a deploy), ``stamp-fault`` (the console's ``--stamp-fault`` given in ``console``, started
            with SIGUSR1 while the policy waits at the fault step; the gate opens once the deploy holds).
        status: Expected exit status (0: the deploy must not hold at all; 1: it refuses before it starts).
        reason: Text the hold (or interruption) reason must contain ("" with status 0).
        also: Other reasons that are as correct: a fault that trips two checks holds on whichever the deploy
            sees first.
        episodes: Episodes of the deploy.
        at: Where the policy acts (``"episode:step"``).
        extra: More deploy arguments.
        default_deadman: Keep the default deadman timeout (only the stale fault); others use a 1 s deadman
            so that a loaded machine's scheduling cannot trip it before the fault is injected.
        default_budget: Keep the default policy budget (the overrun fault); others allow 600 s, the gate's.
        console: More ``sim-dvrk`` arguments.
    """

    name: str
    target: str
    policy: str
    status: int
    reason: str
    action: str = ""
    episodes: int = 1
    at: str = "0:3"
    extra: tuple[str, ...] = ()
    default_deadman: bool = False
    default_budget: bool = False
    also: tuple[str, ...] = ()
    console: tuple[str, ...] = ()

    @property
    def shares_console(self) -> bool:
        """Whether the fault can run on a :class:`SharedConsole` (a default ``sim-dvrk --task lift``): one that
        leaves the console as it found it (see :data:`_OWN_CONSOLE`) and needs no arm as a console starts it
        (DISABLED). Its deploy resets the task scene before each episode; before a dry run, which resets none,
        the runner does."""
        return (
            self.target == "dvrk"
            and self.status != 1
            and not self.console
            and "--perception" not in self.extra
            and not self.action.startswith(_OWN_CONSOLE)
            and not self.reason.startswith("not ready")
        )

    @property
    def leaves_nothing(self) -> bool:
        """Whether the fault ends before anything is written (a refusal at start, an interrupted calibration)."""
        return self.status == 1 or self.action == "interrupt-calibration"

    def explains(self, hold: str) -> bool:
        """Whether a hold (or interruption) reason is one this fault should end with."""
        return any(reason in hold for reason in (self.reason, *self.also))


@dataclass
class FaultResult:
    """What one fault did: exit status, hold line, recording, and whether it was as expected."""

    fault: Fault
    status: int
    hold: str
    traceback: bool
    recording: str
    output: str
    episodes_kept: int = 0
    holds_recorded: list[str] = field(default_factory=list)
    truncated: bool = False

    @property
    def ok(self) -> bool:
        """Expected status and reason, no traceback, and the hold (or interruption) in the recording."""
        recorded = any(self.fault.explains(h) for h in self.holds_recorded)
        if self.fault.status == 0:  # nothing to hold on: the run ends as a run without the fault would
            return self.status == 0 and not self.hold and not self.holds_recorded and not self.traceback
        if self.fault.leaves_nothing:  # refused, or stopped before it wrote anything: no file is left behind
            recorded = self.recording == NOTHING_WRITTEN
        if self.fault.action == "kill-deploy":
            recorded = self.truncated and self.episodes_kept == self.fault.episodes - 1
        return self.status == self.fault.status and self.fault.explains(self.hold) and not self.traceback and recorded


_MODULE = __name__
#: The fault matrix (``tissue-retract bench faults`` runs it; ``tests/ros/test_faults.py`` tests it).
FAULTS: tuple[Fault, ...] = (
    Fault("policy raises", "dvrk", "Raises", 4, "policy error: the policy raised RuntimeError"),
    Fault("policy SystemExit(0)", "dvrk", "Exits", 4, "policy error: the policy raised SystemExit"),
    Fault("policy returns NaN", "dvrk", "ReturnsNan", 4, "invalid action"),
    Fault("policy wrong shape", "dvrk", "WrongShape", 4, "invalid action: shape (3,)"),
    Fault("policy overrun (2 s)", "dvrk", "Slow", 4, "policy overrun", default_budget=True),
    # Another node's NaN is also a second source of that sensor (of measured_js: a second console): the deploy
    # holds on whichever it sees first.
    *(
        Fault(
            f"NaN on {topic}",
            "dvrk",
            "Gate",
            4,
            f"invalid data: {topic}",
            action=f"nan:{topic}",
            # The injector is a second publisher of the topic: on measured_js the deadman's publisher count,
            # or the console check, may see it before the NaN arrives; each is a right hold.
            also=(
                f"another source: /PSM1/{topic} ",
                *(
                    ("another console: /PSM1", "publisher conflict: 2 publishers of measured_js")
                    if topic == "measured_js"
                    else ()
                ),
            ),
        )
        for topic in (
            "measured_js",
            "setpoint_js",
            "measured_cp",
            "local/measured_cp",
            "jaw/measured_js",
            "body/measured_cf",
        )
    ),
    Fault("NaN on measured_js at start-up", "dvrk", "Gate", 4, "invalid data: measured_js", action="early:measured_js"),
    # Another node's setpoint_js 0.5 rad off: a second source of the arm's state, held as such (or, if the
    # deploy reads one of its set-points first, as the tracking error it shows).
    Fault(
        "spoofed setpoint_js (tracking error)",
        "dvrk",
        "Gate",
        4,
        "another source: /PSM1/setpoint_js",
        action="tracking",
        also=("tracking error",),
    ),
    # Another node's `disable` both disables the arm and commands it: either hold is the right one.
    Fault(
        "arm disabled mid-episode",
        "dvrk",
        "Gate",
        4,
        "not ready",
        action="disable",
        also=("another commander: /fault_injector_",),
    ),
    Fault(
        "arm not ready at start (dry run)",
        "dvrk",
        "Gate",
        4,
        "not ready: operating state DISABLED",
        extra=("--dry-run", "--wait", "5"),
    ),
    Fault("console killed (stale)", "dvrk", "Gate", 4, "", action="kill-console", default_deadman=True),
    Fault("policy raises (dry run)", "dvrk", "Raises", 4, "policy error", extra=("--dry-run",)),
    Fault("SIGINT mid-episode", "dvrk", "Hang", 130, "Ctrl-C", action="signal:SIGINT"),
    Fault("SIGTERM mid-episode", "dvrk", "Hang", 143, "SIGTERM", action="signal:SIGTERM"),
    Fault("SIGHUP mid-episode", "dvrk", "Hang", 129, "SIGHUP", action="signal:SIGHUP"),
    Fault("policy raises (sim)", "sim", "Raises", 4, "policy error"),
    Fault("policy returns NaN (sim)", "sim", "ReturnsNan", 4, "invalid action"),
    Fault("SIGTERM mid-episode (sim)", "sim", "Hang", 143, "SIGTERM", action="signal:SIGTERM"),
    Fault("SIGKILL in episode 3 (sim)", "sim", "Hang", -9, "", action="kill-deploy", episodes=3, at="2:3"),
    # One commander per arm (docs/one-commander.md).
    Fault("another node streams servo_jp", "dvrk", "Gate", 4, "another commander: /fault_injector_", action="rogue"),
    Fault("second deploy mid-episode", "dvrk", "Gate", 4, "another commander: ", action="second-deploy"),
    Fault("second console at start", "dvrk", "Gate", 4, "another console: /PSM1 is served by 2", action="console"),
    Fault(
        "arm moved off its start (dry run)",
        "dvrk",
        "Gate",
        4,
        "(a dry run moves nothing: tissue-retract ready-arm --arm PSM1 moves it there)",
        action="move-arm",
        extra=("--dry-run",),
    ),
    # The arm's sensors have one source each, and a listener is no console (docs/one-commander.md).
    Fault(
        "calibration overflows (force not finite)", "dvrk", "Gate", 4, "invalid data: measured_js effort", "calibration"
    ),
    Fault("second force publisher", "dvrk", "Gate", 4, "another source: /PSM1/", action="second-force"),
    Fault(
        "second camera publisher",
        "dvrk",
        "Gate",
        4,
        "another source: /jhu_daVinci/",
        action="second-camera",
        extra=("--perception", "camera"),
    ),
    Fault(
        "camera dead, another publisher behind it",
        "dvrk",
        "Gate",
        4,
        "another source: /jhu_daVinci/",
        action="dead-camera",
        extra=("--perception", "camera"),
        also=("stale: endoscope images",),
    ),
    Fault("a node listens to the arm (a recorder)", "dvrk", "FaultPolicy", 0, "", action="listener"),
    Fault(
        "calibration for another arm",
        "dvrk",
        "FaultPolicy",
        1,
        "a calibration of PSM1 (this one is PSM2's)",
        "other-arm",
    ),
    Fault(
        "calibration fitted on exact forces",
        "dvrk",
        "FaultPolicy",
        1,
        "a calibration fitted on the console it is used with",
        action="exact-sensing",
    ),
    Fault(
        "calibration fitted on a real dVRK, used on sim-dvrk",
        "dvrk",
        "FaultPolicy",
        4,
        "calibration: the wrench calibration was fitted on PSM1 on dvrk",
        action="other-console",
    ),
    Fault(
        "calibrate-wrench interrupted (SIGINT)",
        "dvrk",
        "FaultPolicy",
        130,
        "stopped by SIGINT during excitation 1 of 2: no calibration written",
        action="interrupt-calibration",
    ),
    # The console's clock on measured_js (docs/dvrk.md, "The deadman's timeout"): a measurement is new only when
    # its stamp advanced, and a stamp that goes back or jumps is invalid data.
    Fault(
        "measured_js frozen (same stamp repeated)",
        "dvrk",
        "Gate",
        4,
        "stale: measured_js stamp has not advanced",
        action="stamp-fault",
        console=("--stamp-fault", "frozen"),
    ),
    Fault(
        "measured_js stamps 5 s in the past",
        "dvrk",
        "Gate",
        4,
        "invalid data: measured_js: stamp went back",
        action="stamp-fault",
        console=("--stamp-fault", "past"),
    ),
    Fault(
        "measured_js stamps jump +1 h, then frozen",
        "dvrk",
        "Gate",
        4,
        "invalid data: measured_js: stamp jumped",
        action="stamp-fault",
        console=("--stamp-fault", "jump"),
    ),
    Fault("disk full mid-episode", "dvrk", "FaultPolicy", 4, "recording failed", "disk-full", episodes=3, at="-1:0"),
    Fault("disk full (sim)", "sim", "FaultPolicy", 4, "recording failed", action="disk-full", episodes=40, at="-1:0"),
)
#: Seed of the Task I episodes (one the scripted expert completes).
SEED = 2
#: The small file system of the disk-full faults [bytes], and what the dVRK one leaves free at the start.
SMALL_FS_BYTES = 1024 * 1024
SMALL_FS_FREE_BYTES = 128 * 1024


def fault_named(name: str) -> Fault:
    """The fault of :data:`FAULTS` called ``name``."""
    for fault in FAULTS:
        if fault.name == name:
            return fault
    raise ConfigurationError("fault", name, "one of " + ", ".join(repr(f.name) for f in FAULTS))


class _Lines:
    """A child's merged output, read on a thread: wait for a line without blocking on the pipe."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        self.ended = False
        self._queue: queue.Queue[str | None] = queue.Queue()
        self._thread = threading.Thread(target=self._read, args=(process,), daemon=True)
        self._thread.start()

    def _read(self, process: subprocess.Popen[str]) -> None:
        for line in process.stdout or ():
            self._queue.put(line)
        self._queue.put(None)

    def wait_for(self, text: str | tuple[str, ...], timeout_s: float) -> bool:
        """Collect lines until one contains ``text`` (or one of them: True) or the output ends or the guard
        runs out."""
        texts = (text,) if isinstance(text, str) else text
        if any(t in line for line in self.lines for t in texts):
            return True
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                line = self._queue.get(timeout=remaining)
            except queue.Empty:
                return False
            if line is None:
                self.ended = True
                self._queue.put(None)
                return False
            self.lines.append(line)
            if any(t in line for t in texts):
                return True
        return False

    def arrived(self) -> list[str]:
        """Collect the lines that have arrived, without waiting; return those new since the last collection."""
        start = len(self.lines)
        while not self.ended:
            try:
                line = self._queue.get_nowait()
            except queue.Empty:
                break
            if line is None:
                self.ended = True
                self._queue.put(None)
            else:
                self.lines.append(line)
        return self.lines[start:]

    def rest(self, timeout_s: float) -> str:
        """Everything up to the end of the output."""
        self.wait_for("\0never\0", timeout_s)
        self._thread.join(timeout=1.0)
        return "".join(self.lines)


def _child_env(domain_id: int) -> dict[str, str]:
    env = local_ros_env(domain_id)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def _start(command: list[str], env: dict[str, str]) -> subprocess.Popen[str]:
    # In a process group of its own and bound to this process (sim.sweep.stopping): the runner stops it,
    # and a runner killed outright leaves no console serving the domain.
    return subprocess.Popen(
        command,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        process_group=0,
        preexec_fn=end_with_parent(),
    )


def _console_command(domain_id: int, *more: str) -> list[str]:
    """``sim-dvrk`` serving the faults' task scene on ``domain_id``, with ``more`` arguments."""
    server = [sys.executable, "-m", "tissue_retract", "sim-dvrk", "--domain-id", str(domain_id)]
    return [*server, "--task", "lift", "--seed", str(SEED), *more]


#: What a console logs when it says something on its ``warning`` or ``error`` topics (or fails).
_SAID = ("[WARN]", "[ERROR]", "[FATAL]", "Traceback")


class SharedConsole:
    """One ``sim-dvrk --task lift`` on ``domain_id`` for the faults that leave their console as they found it.

    Given to :func:`run_fault` for each such fault (:attr:`Fault.shares_console`) in turn, it serves the fault
    in place of a console of its own: the console's start-up, and the arm's enable and home by the deploy, are
    paid once. Faults run on it one at a time, each after every process of the one before has ended, so the
    deploy that joins the domain meets the console alone. A console that ended, or said anything on its
    ``warning`` or ``error`` topics (``error`` keeps its history for the next deploy), is stopped, and the next
    fault starts a fresh one; so is one whose domain another machine user's arm turned out to share.
    """

    def __init__(self, domain_id: int) -> None:
        self.domain_id = domain_id
        self._process: subprocess.Popen[str] | None = None
        self._output: _Lines | None = None

    def take(self) -> subprocess.Popen[str]:
        """The console, started if there is none or the last one may not serve another fault."""
        if self._process is not None and self._output is not None:
            said = [line for line in self._output.arrived() if any(level in line for level in _SAID)]
            if said or self._process.poll() is not None:
                self.close()
        if self._process is None:
            # The console's output is read all along: a full pipe would stop it mid-row.
            self._process = _start(_console_command(self.domain_id), _child_env(self.domain_id))
            self._output = _Lines(self._process)
        return self._process

    def close(self) -> None:
        """Stop the console (the next :meth:`take` starts a new one)."""
        if self._process is not None:
            _stop(self._process)
        self._process = self._output = None


def _stop(process: subprocess.Popen[str], timeout_s: float = 30.0) -> None:
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


class _Injector:
    """A ROS 2 node of its own context on the fault's domain: publishes the injected messages."""

    def __init__(self, domain_id: int, arm: str = "PSM1") -> None:
        import rclpy  # the ros extra
        from rclpy.context import Context

        self._rclpy = rclpy
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(f"fault_injector_{os.getpid()}", context=self.context)
        self.arm = arm
        self.closed = False

    def publisher(self, topic: str) -> tuple[Any, Any]:
        """A publisher on ``/<arm>/<topic>`` and the injected (non-finite) message for it."""
        from crtk_msgs.msg import StringStamped  # type: ignore[import-untyped]  # the ros extra
        from geometry_msgs.msg import PoseStamped, WrenchStamped  # type: ignore[import-untyped]
        from sensor_msgs.msg import JointState  # type: ignore[import-untyped]

        from hardware_if.common import convert
        from hardware_if.common.crtk import JAW_JOINT_NAME, JOINT_NAMES, ArmTopics, periodic_qos

        name = ArmTopics(self.arm).topic(topic)
        message: Any
        if topic == "state_command":
            message, kind = StringStamped(string="disable"), StringStamped
        elif topic.endswith("_js"):
            names = (JAW_JOINT_NAME,) if topic.startswith("jaw/") else JOINT_NAMES
            message, kind = convert.joint_state(names, [float("nan")] * len(names)), JointState
        elif topic.endswith("_cp"):
            message = convert.pose_stamped(np.eye(4), f"{self.arm}_base")
            message.pose.position.x = float("nan")
            kind = PoseStamped
        else:
            message = convert.wrench_stamped(np.array([float("nan"), 0.0, 0.0]), frame_id=f"{self.arm}_tip")
            kind = WrenchStamped
        # The simulated console subscribes to state_command volatile: the periodic QoS matches it.
        return self.node.create_publisher(kind, name, periodic_qos()), message

    def zero_force(self) -> list[tuple[Any, Any]]:
        """Publishers of 0 N on the arm's ``body/`` and ``spatial/measured_cf``, with their messages."""
        from geometry_msgs.msg import WrenchStamped  # the ros extra

        from hardware_if.common import convert
        from hardware_if.common.crtk import ArmTopics, periodic_qos

        out = []
        for topic, frame in (("body/measured_cf", f"{self.arm}_tip"), ("spatial/measured_cf", f"{self.arm}_base")):
            publisher = self.node.create_publisher(WrenchStamped, ArmTopics(self.arm).topic(topic), periodic_qos())
            out.append((publisher, convert.wrench_stamped(np.zeros(3), frame_id=frame)))
        return out

    def images(self, rig: str = "jhu_daVinci") -> list[tuple[Any, Any]]:
        """Publishers of grey stereo pairs on the endoscope's image topics, with their messages."""
        from sensor_msgs.msg import Image  # the ros extra

        from hardware_if.common.crtk import periodic_qos
        from hardware_if.common.task_topics import camera_topics

        out = []
        for side in ("left", "right"):
            image = Image()
            image.header.frame_id = f"{rig}_{side}"
            image.height, image.width, image.encoding, image.step = 8, 8, "rgb8", 24
            image.data = bytes(8 * 24)
            topic = camera_topics(rig)[f"{side}_image"]
            out.append((self.node.create_publisher(Image, topic, periodic_qos()), image))
        return out

    def listen(self) -> None:
        """Subscribe to every topic of the arm, ``state_command`` included, as ``ros2 bag record -a`` does."""
        from crtk_msgs.msg import OperatingState, StringStamped  # the ros extra
        from geometry_msgs.msg import PoseStamped, WrenchStamped
        from sensor_msgs.msg import JointState

        from hardware_if.common.crtk import ArmTopics, event_qos, periodic_qos

        t = ArmTopics(self.arm).topic
        for kind, names, qos in (
            (JointState, ("measured_js", "setpoint_js", "jaw/measured_js", "servo_jp", "jaw/servo_jp"), periodic_qos),
            (PoseStamped, ("measured_cp", "local/measured_cp", "setpoint_cp"), periodic_qos),
            (WrenchStamped, ("body/measured_cf",), periodic_qos),
            (StringStamped, ("state_command",), periodic_qos),
            (OperatingState, ("operating_state",), event_qos),
        ):
            for name in names:
                self.node.create_subscription(kind, t(name), lambda _message: None, qos())

    def moved_message(self) -> Any:
        """A ``servo_jp`` 0.25 rad off the task's start on yaw, as a teleoperation node left running sends."""
        from hardware_if.common import convert
        from hardware_if.common.crtk import JOINT_NAMES

        q = PsmModel.from_variant().home()
        q[0] += MOVED_OFFSET_RAD
        return convert.joint_state(JOINT_NAMES, q)

    def tracking_message(self) -> Any:
        """A ``setpoint_js`` 1 rad from anywhere the arm can be on outer_yaw (beyond the 0.5 rad trip)."""
        from hardware_if.common import convert
        from hardware_if.common.crtk import JOINT_NAMES

        return convert.joint_state(JOINT_NAMES, [3.0, 0.0, 0.1, 0.0, 0.0, 0.0])

    def flood(self, pairs: list[tuple[Any, Any]], lines: _Lines, text: str | tuple[str, ...], timeout_s: float) -> bool:
        """Publish every ``(publisher, message)`` that has a subscriber until the deploy's output shows ``text``
        or one of them (the client saw it)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not lines.ended:
            for publisher, message in pairs:
                if publisher.get_subscription_count() > 0:
                    publisher.publish(message)
            if lines.wait_for(text, 0.002):
                return True
        return False

    def reset_scene(self, seed: int, timeout_s: float) -> None:
        """Ask the console for the task scene's episode ``seed``, as a deploy does before each episode; return
        once its count of resets says the new scene is there."""
        from std_msgs.msg import Int64  # type: ignore[import-untyped]  # the ros extra

        from hardware_if.common.crtk import periodic_qos
        from hardware_if.common.task_topics import task_topic

        counts: list[int] = []

        def on_count(message: Any) -> None:
            counts.append(int(message.data))

        self.node.create_subscription(Int64, task_topic(self.arm, "resets"), on_count, periodic_qos())
        reset = self.node.create_publisher(Int64, task_topic(self.arm, "reset"), periodic_qos())
        executor = make_executor(self.context)
        executor.add_node(self.node)
        deadline = time.monotonic() + timeout_s

        def spin_until(done: Any, what: str) -> None:
            while not done():
                if time.monotonic() > deadline:
                    raise DvrkTimeoutError(what, timeout_s)
                executor.spin_once(timeout_sec=0.05)

        try:
            spin_until(lambda: counts and reset.get_subscription_count() > 0, f"{task_topic(self.arm, 'resets')}")
            before = counts[-1]
            reset.publish(Int64(data=seed))
            spin_until(lambda: counts[-1] != before, f"a reset of the task scene (seed {seed})")
        finally:
            executor.shutdown()

    def close(self) -> None:
        self.closed = True
        self.node.destroy_node()
        self._rclpy.shutdown(context=self.context)


def _recording_facts(record: Path) -> tuple[str, int, list[str], bool]:
    try:
        recording = load_recording(record)
    except Exception as e:  # the table says what the recording lacks
        return f"unreadable: {e}", 0, [], False
    summary = summarize_recording(recording)
    text = (
        f"{len(summary.episodes)} episode(s), {summary.commands} commands ({summary.commands_sent} sent), "
        f"{len(summary.holds)} hold(s)" + (", truncated" if summary.truncated else "")
    )
    return text, len(summary.episodes), summary.holds, summary.truncated


def run_fault(
    fault: Fault,
    workdir: Path,
    domain_id: int,
    *,
    guard_s: float = 300.0,
    retry_domains: Sequence[int] | None = None,
    console: SharedConsole | None = None,
) -> FaultResult:
    """Run one fault in ``workdir`` on ROS domain ``domain_id``; return what happened.

    ``guard_s`` only bounds a run that went wrong; a correct one ends as soon as its deploy does. When
    another machine user's arm shares the domain (the deploy holds on ``another console`` or a ``publisher
    conflict`` the fault does not explain), the fault runs again on ``retry_domains`` in turn (default: two
    others, 37 and 74 ids on). A caller that shares the machine's domains with other runs of its own (test
    workers) names domains only it uses.

    With ``console`` (serving ``domain_id``), a fault that :attr:`~Fault.shares_console` runs against it; a
    retry runs on a console of its own.

    Raises:
        ConfigurationError: ``console`` serves another domain, or the fault does not share a console.
    """
    if console is not None and (console.domain_id != domain_id or not fault.shares_console):
        why = f"a console of domain {domain_id}, for a fault that shares it"
        raise ConfigurationError("console", f"domain {console.domain_id} for {fault.name!r}", why)
    if retry_domains is None:
        retry_domains = [1 + (domain_id - 1 + 37 * attempt) % 100 for attempt in (1, 2)]
    for domain in (domain_id, *retry_domains):
        result = _run_fault(fault, workdir, domain, guard_s, console if domain == domain_id else None)
        shared = any(text in result.hold for text in ("publisher conflict", "another console"))
        if not shared or fault.explains(result.hold):
            break
        if console is not None:
            console.close()  # another user's arm is on its domain
    return result


def _run_fault(
    fault: Fault, workdir: Path, domain_id: int, guard_s: float, shared: SharedConsole | None
) -> FaultResult:
    workdir.mkdir(parents=True, exist_ok=True)
    env = _child_env(domain_id)
    env[AT_VARIABLE] = fault.at
    gate = workdir / "go"
    gate.unlink(missing_ok=True)
    env[GATE_VARIABLE] = str(gate)
    disk = (
        small_filesystem(workdir / "small", SMALL_FS_BYTES, None if fault.target == "sim" else SMALL_FS_FREE_BYTES)
        if fault.action == "disk-full"
        else contextlib.nullcontext(workdir)
    )
    with disk as folder:
        return _run_fault_in(fault, workdir, domain_id, guard_s, env, gate, folder / "run.mcap", shared)


def _run_fault_in(
    fault: Fault,
    workdir: Path,
    domain_id: int,
    guard_s: float,
    env: dict[str, str],
    gate: Path,
    record: Path,
    shared: SharedConsole | None,
) -> FaultResult:
    record.unlink(missing_ok=True)
    deploy = [sys.executable, "-m", "tissue_retract", "deploy", "--policy", f"{_MODULE}:{fault.policy}"]
    deploy += ["--target", fault.target, "--task", "lift", "--seed", str(SEED), "--record", str(record)]
    deploy += ["--episodes", str(fault.episodes), *fault.extra]
    if not fault.default_budget:
        deploy += ["--policy-budget", str(GUARD_S)]
    if fault.target == "dvrk":
        deploy += ["--domain-id", str(domain_id)]
        if "--wait" not in fault.extra:
            deploy += ["--wait", "60"]
        if not fault.default_deadman:
            config = workdir / "safety.toml"
            config.write_text("deadman_timeout_s = 1.0\n")
            deploy += ["--safety-config", str(config)]
    if fault.action in ("calibration", "other-arm", "exact-sensing", "other-console"):
        deploy += ["--wrench-calibration", str(_calibration_file(fault.action, workdir))]
    written = workdir / "wrench.out.json"  # what an interrupted calibrate-wrench must not leave
    written.unlink(missing_ok=True)
    if fault.action == "interrupt-calibration":
        deploy = [sys.executable, "-m", "tissue_retract", "calibrate-wrench", "--domain-id", str(domain_id)]
        deploy += ["--out", str(written), "--wait", "60"]
    console = injector = None
    lines: _Lines | None = None
    process: subprocess.Popen[str] | None = None
    try:
        if shared is not None:
            console = shared.take()
        elif fault.target == "dvrk" and fault.status != 1:  # a refusal at start reaches no console
            camera = ("--blind", "--endoscope") if "--perception" in fault.extra else ()  # the jaw tells the grasp
            console = _start(_console_command(domain_id, *camera, *fault.console), env)
        if console is not None:
            dry = "--dry-run" in fault.extra and "not ready" not in fault.reason
            if dry and shared is not None:
                _reset_scene(domain_id, guard_s)  # the scene as a fresh console's: a dry run resets none itself
            if dry or fault.action == "interrupt-calibration":
                _ready_arm(env, domain_id, guard_s)
        if fault.action.startswith(("nan:", "early:", "tracking", "disable", "rogue", "console", "second-", "dead-")):
            injector = _Injector(domain_id)
        if fault.action == "listener":
            injector = _Injector(domain_id)
            injector.listen()
            listening = make_executor()  # the listener takes its messages, as a recorder does
            listening.add_node(injector.node)
            threading.Thread(target=_spin_until_closed, args=(listening, injector), daemon=True).start()
        if fault.action == "console" and injector is not None:
            wait_until_served(domain_id, guard_s)  # a console starting now would see this one and refuse
            injector.publisher("measured_js")  # a second console's stream, discovered with the first
        if fault.action == "move-arm":
            move_arm_off_start(domain_id, guard_s)
        process = _start(deploy, env)
        lines = _Lines(process)
        if fault.action == "interrupt-calibration":
            lines.wait_for("excitation 1 of 2", guard_s)  # the arm is moving along the excitation
            process.send_signal(signal.SIGINT)
        elif fault.action and not fault.action.startswith(_AT_START) and fault.status != 1:
            lines.wait_for(MARK, guard_s)  # mid-episode: after the ticks of the steps before the fault step
        if fault.action.startswith(("nan:", "early:")) and injector is not None:
            topic = fault.action.split(":", 1)[1]
            publisher, message = injector.publisher(topic)
            injector.flood([(publisher, message)], lines, ("invalid data", *fault.also), guard_s)
        elif fault.action == "rogue" and injector is not None:
            publisher, _ = injector.publisher("servo_jp")
            injector.flood([(publisher, injector.moved_message())], lines, "another commander", guard_s)
        elif fault.action in ("second-force", "second-camera", "dead-camera") and injector is not None:
            if fault.action == "dead-camera" and console is not None:
                os.kill(_render_pid(console), signal.SIGKILL)
            pairs = injector.zero_force() if fault.action == "second-force" else injector.images()
            # The client holds as soon as it sees the second source (the policy waits at the gate meanwhile).
            injector.flood(pairs, lines, ("another source", *fault.also), guard_s)
        elif fault.action == "second-deploy":
            second = _start([*deploy[: deploy.index("--record")], "--record", str(workdir / "second.mcap")], env)
            second.wait(timeout=guard_s)
            lines.wait_for("another commander", min(guard_s, 60.0))  # the first saw it (it holds at the gate)
        elif fault.action == "tracking" and injector is not None:
            publisher, _ = injector.publisher("setpoint_js")
            held = tuple(f"holding, {reason}" for reason in (fault.reason, *fault.also))
            injector.flood([(publisher, injector.tracking_message())], lines, held, guard_s)
        elif fault.action == "disable" and injector is not None:
            publisher, message = injector.publisher("state_command")
            # The injector both disables and commands the arm: the deploy holds on whichever it sees first.
            held = tuple(f"holding, {reason}" for reason in (fault.reason, *fault.also))
            injector.flood([(publisher, message)], lines, held, guard_s)
        elif fault.action == "stamp-fault" and console is not None:
            console.send_signal(signal.SIGUSR1)  # the console's clock goes wrong while the policy waits
            lines.wait_for("holding, ", min(guard_s, 60.0))  # the deadman saw it (the gate then lets it tick)
        elif fault.action == "kill-console" and console is not None:
            console.kill()
            console.wait()
        elif fault.action.startswith("signal:"):
            process.send_signal(signal.Signals[fault.action.split(":", 1)[1]])
        elif fault.action == "kill-deploy":
            process.kill()
        gate.touch()
        status = process.wait(timeout=guard_s)
        output = lines.rest(guard_s)
    finally:
        if process is not None and process.poll() is None:
            process.kill()
            process.wait()
        if injector is not None:
            injector.close()
        if console is not None and shared is None:
            _stop(console)
    ends = ("HOLD:", "interrupted (", ": error: ", ": stopped by ")
    hold = next((line.strip() for line in output.splitlines() if any(end in line for end in ends)), "")
    if fault.leaves_nothing:
        left = [path.name for path in (record, written) if path.exists()]
        text = f"left behind: {', '.join(left)}" if left else NOTHING_WRITTEN
        return FaultResult(fault, status, hold, "Traceback" in output, text, output)
    text, kept, holds, truncated = _recording_facts(record)
    return FaultResult(fault, status, hold, "Traceback" in output, text, output, kept, holds, truncated)


def _spin_until_closed(executor: Any, injector: _Injector) -> None:
    """Spin the listener's node until the runner closes it (its context then ends the spin)."""
    while not injector.closed:
        try:
            executor.spin_once(timeout_sec=0.05)
        except Exception:  # the context was shut down from under the spin: the listener is done
            return


def _reset_scene(domain_id: int, guard_s: float) -> None:
    """A shared console's task scene back to the faults' first episode (seed :data:`SEED`), by a node that is
    gone before the deploy joins the domain."""
    injector = _Injector(domain_id)
    try:
        injector.reset_scene(SEED, guard_s)
    finally:
        injector.close()


def _calibration_file(action: str, workdir: Path) -> Path:
    """A calibration file a deploy must not trust: its force overflows (``calibration``: finite parameters,
    one of them 1e300, an effort offset), it is PSM2's (``other-arm``), it was fitted where the console
    reports the exact force (``exact-sensing``), or on a real dVRK (``other-console``)."""
    from hardware_if.wrench.calibration import EXACT_SENSING, WrenchCalibration
    from psm_control.effort_model import EffortRegressor

    path = workdir / "wrench.json"
    offset = EffortRegressor().friction_start + 3 * 2 + 2  # the insertion's effort offset
    calibration = WrenchCalibration("PSM1", (offset,), (0.05,), 1.0, 1.0, 1.0, 2.0, 0.1, 0.2, 1000)
    if action == "calibration":
        calibration = dataclasses.replace(calibration, parameters=(1e300,))
    elif action == "other-arm":
        calibration = dataclasses.replace(calibration, arm="PSM2")
    elif action == "exact-sensing":
        calibration = dataclasses.replace(calibration, parameters=(0.0,), sensing=EXACT_SENSING)
    elif action == "other-console":
        calibration = dataclasses.replace(calibration, console="dvrk")
    calibration.write(path)
    return path


def _render_pid(console: subprocess.Popen[str]) -> int:
    """The endoscope's render process of a ``sim-dvrk --endoscope``, from the line it printed at its start."""
    for line in console.stdout or ():
        if line.startswith("endoscope: ") and "render process " in line:
            return int(line.rsplit("render process ", 1)[1].rstrip(")\n "))
    raise RuntimeError("sim-dvrk --endoscope printed no render process")


def _ready_arm(env: dict[str, str], domain_id: int, guard_s: float) -> None:
    """Enable, home and move the simulated arm to the start with ``tissue-retract ready-arm`` (a dry run does not)."""
    command = [sys.executable, "-m", "tissue_retract", "ready-arm", "--domain-id", str(domain_id)]
    done = subprocess.run(
        [*command, "--wait", f"{guard_s:g}"],
        env=env,
        capture_output=True,
        text=True,
        timeout=guard_s,
        check=False,
        preexec_fn=end_with_parent(),
    )
    if done.returncode != 0:
        raise RuntimeError(f"ready-arm failed ({done.returncode}): {done.stderr.strip()}")


def scratch_dir() -> Path:
    """A fresh folder for a run's files."""
    return Path(tempfile.mkdtemp(prefix="tissue-retract-faults-"))
