"""Summarising and plotting a deploy or dry-run recording (:mod:`hardware_if.recording.recorder`).

Needs no ROS: a recording is plain MCAP with JSON channels.
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hardware_if.common.crtk import JOINT_NAMES
from hardware_if.recording.recorder import read_recording
from psm_control.errors import ConfigurationError
from safety.force_watch import FORCE_LIMIT_EXCEEDED, FORCE_LIMIT_STALL

__all__ = ["TICK_GAP_S", "Recording", "RecordingSummary", "answers", "load_recording", "summarize_recording"]

#: Consecutive measurements further apart than this are not one tick and the next (a gap between episodes) [s].
TICK_GAP_S = 0.5


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


def _newtons(value: Any) -> str:
    """A force for the summary; a recording keeps a non-finite one as null, which reads ``not finite``."""
    if value is None or not math.isfinite(float(value)):
        return "not finite"
    return f"{float(value):.3f} N"


def _number(payload: dict[str, Any], key: str) -> float:
    """A number of a message, nan when it is missing (older recordings) or null (non-finite when written)."""
    value = payload.get(key)
    return float(value) if value is not None else float("nan")


def load_recording(path: str | Path) -> Recording:
    """Read a recording into arrays.

    Raises:
        ConfigurationError: The file is missing or not a deploy recording.
    """
    if not Path(path).is_file():
        raise ConfigurationError("recording", str(path), "an existing .mcap file written by deploy")
    rec = Recording()
    rows: dict[str, list[Any]] = collections.defaultdict(list)
    try:
        read = read_recording(path)
        messages = read.messages
        rec.truncated = read.truncated
    except Exception as e:
        raise ConfigurationError("recording", str(path), "an MCAP file written by tissue-retract deploy") from e
    if not messages:
        raise ConfigurationError("recording", str(path), "a recording with messages")
    start = messages[0][1]
    for topic, t, payload in messages:
        if topic == "/deploy/meta":
            rec.meta = payload
        elif topic == "/deploy/report":
            rec.report = payload
        elif topic == "/deploy/event":
            rec.events.append({"t": t - start, **payload})
        elif topic == "/deploy/measured":
            rows["mt"].append(t - start)
            rows["mq"].append(payload["q"])
            rows["f"].append(payload["force_n"])
            rows["ms"].append(_number(payload, "stamp_s"))
            rows["mj"].append(_number(payload, "jaw"))
        elif topic == "/deploy/command":
            rows["ct"].append(t - start)
            rows["cq"].append(payload["q"])
            rows["sent"].append(bool(payload["sent"]))
            rows["stop"].append(bool(payload["safety_stop"]))
            rows["cs"].append(_number(payload, "stamp_s"))
            rows["cj"].append(_number(payload, "jaw"))
            rows["int"].append(bool(payload.get("interventions")))
            predicted = payload.get("predicted_force_n")
            rows["pf"].append(np.nan if predicted is None else float(predicted))
        elif topic == "/deploy/action":
            rec.actions += 1
    if rows["mt"]:
        rec.measured_t, rec.measured_q = np.array(rows["mt"]), np.array(rows["mq"], dtype=float)
        rec.force_n = np.array(rows["f"], dtype=float)
        rec.measured_stamp_s, rec.measured_jaw = np.array(rows["ms"]), np.array(rows["mj"])
    if rows["ct"]:
        rec.command_t, rec.command_q = np.array(rows["ct"]), np.array(rows["cq"], dtype=float)
        rec.command_sent, rec.safety_stop = np.array(rows["sent"]), np.array(rows["stop"])
        rec.predicted_force_n = np.array(rows["pf"], dtype=float)
        rec.command_stamp_s, rec.command_jaw = np.array(rows["cs"]), np.array(rows["cj"])
        rec.intervened = np.array(rows["int"], dtype=bool)
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
        truncated=rec.truncated,
        invalid_actions=int(invalid),
        force_limit_exceeded=exceeded,
        force_limit_stalls=stalls,
    )
