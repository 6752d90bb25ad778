"""Summarising and plotting a deploy or dry-run recording (:mod:`hardware_if.recording.recorder`).

Needs no ROS: a recording is plain MCAP with JSON channels.
"""

from __future__ import annotations

import collections
import math
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hardware_if.common.crtk import JOINT_NAMES
from hardware_if.recording.reader import RecordingFileError
from hardware_if.recording.schema import RecordingMessages, as_float
from safety.force_watch import FORCE_LIMIT_EXCEEDED, FORCE_LIMIT_STALL

__all__ = [
    "NOT_RECORDED",
    "TICK_GAP_S",
    "Recording",
    "RecordingSummary",
    "answers",
    "load_recording",
    "sensing_text",
    "summarize_recording",
]

#: Consecutive measurements further apart than this are not one tick and the next (a gap between episodes) [s].
TICK_GAP_S = 0.5
#: The sensing line of a recording from before the meta named its sensing.
NOT_RECORDED = "not recorded (a recording from before deploys recorded their sensing)"


@dataclass
class Recording:
    """A recording's channels as arrays (times [s] from the first message; ``*_stamp_s``: the arm's or the
    simulation's own clock, as stamped on each measurement and command)."""

    meta: dict[str, Any] = field(default_factory=dict)
    report: dict[str, Any] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    measured_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_q: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    force_n: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    command_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command_q: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    command_sent: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    safety_stop: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    predicted_force_n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_stamp_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    measured_jaw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command_stamp_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command_jaw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    intervened: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: The chain's bound on the true force from the grasp point's travel, per command [N]; nan where it was not
    #: in force or not recorded (recordings from before it).
    travel_bound_n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    actions: int = 0
    #: The file lacked its footer (the run was killed): this is what its complete chunks kept.
    truncated: bool = False


@dataclass
class RecordingSummary:
    """What :func:`summarize_recording` reports."""

    duration_s: float
    commands: int
    commands_sent: int
    safety_stop_ticks: int
    holds: list[str]
    peak_force_n: float
    tracking_error_max: np.ndarray
    episodes: list[dict[str, Any]]
    dry_run: bool
    target: str
    sensing: str = NOT_RECORDED
    truncated: bool = False
    invalid_actions: int = 0
    force_limit_exceeded: list[dict[str, Any]] = field(default_factory=list)
    force_limit_stalls: list[dict[str, Any]] = field(default_factory=list)

    def lines(self) -> list[str]:
        """The printed summary."""
        kind = "dry run" if self.dry_run else "deploy"
        out = (
            ["truncated recording (no footer: the run did not finish); summarising what it kept"]
            if self.truncated
            else []
        )
        out += [
            f"{kind} to {self.target or '?'}: {self.duration_s:.2f} s, {len(self.episodes)} episode(s)",
            f"force sensing: {self.sensing}",
            f"commands: {self.commands} computed, {self.commands_sent} sent",
            f"safety stop ticks: {self.safety_stop_ticks}; holds: {len(self.holds)}"
            + "".join(f"\n  hold: {h}" for h in self.holds),
            f"peak force: {_newtons(self.peak_force_n)}",
            f"invalid actions: {self.invalid_actions}",
            f"force limit exceeded: {len(self.force_limit_exceeded)} x"
            + "".join(
                f"\n  episode {e.get('episode', '?')}: {_newtons(e.get('peak_n'))} against {e['limit_n']:g} N "
                f"for {e['duration_s']:.3f} s"
                for e in self.force_limit_exceeded
            ),
            f"force limit stalled the retraction: {len(self.force_limit_stalls)} x"
            + "".join(
                f"\n  episode {e.get('episode', '?')}: held to {1000 * e['speed_m_s']:.0f} mm/s, holding the "
                f"tissue cost {e['static_load_n']:.3f} N against {e['limit_n']:g} N"
                for e in self.force_limit_stalls
            ),
            ("command-to-arm distance max (dry run: nothing was sent) " if self.dry_run else "tracking error max ")
            + "|command(t-1) - measured(t)|: "
            + ", ".join(
                f"{n} {v:.4g} {'m' if n == 'insertion' else 'rad'}"
                for n, v in zip(JOINT_NAMES, self.tracking_error_max, strict=True)
            ),
        ]
        for e in self.episodes:
            out.append(
                f"episode {e.get('episode')}: success={e.get('success')} steps={e.get('steps')} "
                f"peak force {_newtons(e.get('peak_force_n', 0.0))}"
            )
        return out


def sensing_text(meta: dict[str, Any]) -> str:
    """What the meta's ``sensing`` says (:mod:`hardware_if.deploy.meta`): the sensing, the calibration file with its
    digest and bounds, and the error bound the safety filter was given; :data:`NOT_RECORDED` without one."""
    sensing = meta.get("sensing")
    if not isinstance(sensing, dict) or not sensing.get("force_sensing"):
        return NOT_RECORDED

    def newtons(record: dict[str, Any], key: str) -> str:
        return _newtons(record[key]) if key in record else "?"

    text = str(sensing["force_sensing"])
    calibration = sensing.get("wrench_calibration")
    if isinstance(calibration, dict):
        text += (
            f", calibrated by {calibration.get('path') or '?'} (sha256 {calibration.get('sha256') or '?'}; error "
            f"bound {newtons(calibration, 'error_bound_n')}, "
            f"{newtons(calibration, 'error_bound_with_acceleration_n')} with the acceleration)"
        )
    elif meta.get("target") == "sim":
        text += " (simulated)"
    return f"{text}; the safety filter was given a sensing error of {newtons(sensing, 'force_sensing_error_n')}"


def _newtons(value: Any) -> str:
    """A force for the summary; a recording keeps a non-finite one as null, which reads ``not finite``."""
    if value is None or not math.isfinite(float(value)):
        return "not finite"
    return f"{float(value):.3f} N"


def load_recording(path: str | Path) -> Recording:
    """Read a recording into arrays, its messages checked as they are read (:mod:`hardware_if.recording.schema`).

    Raises:
        RecordingFileError: The file is missing, not a recording within the reader's limits
            (:mod:`hardware_if.recording.reader`), or a message is not what its channel holds (named).
    """
    messages = RecordingMessages(path)
    rec = Recording()
    times: dict[str, list[int]] = collections.defaultdict(list)  # log times [ns] per channel
    floats: dict[str, array] = collections.defaultdict(lambda: array("d"))
    flags: dict[str, list[bool]] = collections.defaultdict(list)
    events: list[dict[str, Any]] = []
    start: int | None = None  # the first log time [ns]
    for topic, _, t_ns, payload in messages:
        start = t_ns if start is None else min(start, t_ns)
        if topic == "/deploy/meta":
            rec.meta = payload
        elif topic == "/deploy/report":
            rec.report = payload
        elif topic == "/deploy/event":
            events.append({**payload, "t": t_ns})
        elif topic == "/deploy/measured":
            times["measured"].append(t_ns)
            floats["mq"].extend(as_float(v) for v in payload["q"])
            floats["f"].extend(as_float(v) for v in payload["force_n"])
            floats["ms"].append(as_float(payload.get("stamp_s")))
            floats["mj"].append(as_float(payload.get("jaw")))
        elif topic == "/deploy/command":
            times["command"].append(t_ns)
            floats["cq"].extend(as_float(v) for v in payload["q"])
            flags["sent"].append(payload["sent"])
            flags["stop"].append(payload["safety_stop"])
            floats["cs"].append(as_float(payload.get("stamp_s")))
            floats["cj"].append(as_float(payload.get("jaw")))
            flags["int"].append(bool(payload.get("interventions")))
            floats["pf"].append(as_float(payload.get("predicted_force_n")))
            floats["tb"].append(as_float(payload.get("travel_bound_n")))
        elif topic == "/deploy/action":
            rec.actions += 1
    rec.truncated = messages.truncated
    if start is None:
        raise RecordingFileError(
            path, "a recording written by tissue-retract deploy, with messages on /deploy/* channels; it has none"
        )
    # In log-time order, as the writer logged them (a chunk's messages are in order; a clock step is not).
    rec.events = sorted(({**e, "t": 1e-9 * (e["t"] - start)} for e in events), key=lambda e: e["t"])
    if times["measured"]:
        order = np.argsort(times["measured"], kind="stable")
        rec.measured_t = 1e-9 * (np.array(times["measured"])[order] - start)
        rec.measured_q = np.frombuffer(floats["mq"]).reshape(-1, 6)[order]
        rec.force_n = np.frombuffer(floats["f"]).reshape(-1, 3)[order]
        rec.measured_stamp_s, rec.measured_jaw = np.frombuffer(floats["ms"])[order], np.frombuffer(floats["mj"])[order]
    if times["command"]:
        order = np.argsort(times["command"], kind="stable")
        rec.command_t = 1e-9 * (np.array(times["command"])[order] - start)
        rec.command_q = np.frombuffer(floats["cq"]).reshape(-1, 6)[order]
        rec.command_sent, rec.safety_stop = np.array(flags["sent"])[order], np.array(flags["stop"])[order]
        rec.predicted_force_n = np.frombuffer(floats["pf"])[order]
        rec.command_stamp_s, rec.command_jaw = np.frombuffer(floats["cs"])[order], np.frombuffer(floats["cj"])[order]
        rec.intervened = np.array(flags["int"], dtype=bool)[order]
        rec.travel_bound_n = np.frombuffer(floats["tb"])[order]
    return rec


def answers(rec: Recording) -> np.ndarray:
    """Per measurement, whether it answers the command of the tick before (bool, shape of ``measured_t``).

    Measured at tick t answers the command of tick t-1, within one episode: not the first tick of a
    recording or of an episode, nor one after a gap (homing between episodes on a robot).
    """
    answer = np.zeros(len(rec.measured_t), dtype=bool)
    if len(rec.measured_t) < 2 or len(rec.command_q) != len(rec.measured_q):
        return answer
    answer[1:] = np.diff(rec.measured_t) < TICK_GAP_S
    for event in rec.events:
        first = int(np.searchsorted(rec.measured_t, event["t"]))
        if event.get("kind") == "episode_start" and first < len(answer):
            answer[first] = False
    return answer


def summarize_recording(rec: Recording) -> RecordingSummary:
    """Duration, commands, holds and safety stops, peak force and tracking error of a recording."""
    times = np.concatenate([rec.measured_t, rec.command_t, [e["t"] for e in rec.events]])
    duration = float(times.max() - times.min()) if times.size else 0.0
    force = float(np.linalg.norm(rec.force_n, axis=1).max()) if len(rec.force_n) else 0.0
    if len(rec.command_q) > 1 and len(rec.measured_q) == len(rec.command_q):
        error = np.abs(rec.command_q[:-1] - rec.measured_q[1:])[answers(rec)[1:]]
        tracking = error.max(axis=0) if len(error) else np.full(len(JOINT_NAMES), np.nan)
    else:
        tracking = np.full(len(JOINT_NAMES), np.nan)
    holds = [str(e.get("text", "")) for e in rec.events if e.get("kind") in ("hold", "deadman", "interrupted")]
    invalid = sum(e.get("kind") == "invalid_action" for e in rec.events)
    exceeded = [e for e in rec.events if e.get("kind") == FORCE_LIMIT_EXCEEDED]
    stalls = [e for e in rec.events if e.get("kind") == FORCE_LIMIT_STALL]
    episodes = [e for e in rec.events if e.get("kind") == "episode_end"]
    return RecordingSummary(
        duration_s=duration,
        commands=len(rec.command_q),
        commands_sent=int(rec.command_sent.sum()),
        safety_stop_ticks=int(rec.safety_stop.sum()),
        holds=holds,
        peak_force_n=force,
        tracking_error_max=tracking,
        episodes=episodes,
        dry_run=bool(rec.meta.get("dry_run", False)),
        target=str(rec.meta.get("target", "")),
        sensing=sensing_text(rec.meta),
        truncated=rec.truncated,
        invalid_actions=int(invalid),
        force_limit_exceeded=exceeded,
        force_limit_stalls=stalls,
    )
