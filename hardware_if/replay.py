"""Summarising and plotting a deploy or dry-run recording (:mod:`hardware_if.recording`).

Needs no ROS: a recording is plain MCAP with JSON channels.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from hardware_if.crtk import JOINT_NAMES
from hardware_if.recording import read_recording
from psm_control.errors import ConfigurationError
from safety.force_watch import FORCE_LIMIT_EXCEEDED, FORCE_LIMIT_STALL

__all__ = ["Recording", "RecordingSummary", "load_recording", "plot_recording", "summarize_recording"]


@dataclass
class Recording:
    """A recording's channels as arrays (times [s] from the first message)."""

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
            f"peak force: {self.peak_force_n:.3f} N",
            f"invalid actions: {self.invalid_actions}",
            f"force limit exceeded: {len(self.force_limit_exceeded)} x"
            + "".join(
                f"\n  episode {e.get('episode', '?')}: {e['peak_n']:.3f} N against {e['limit_n']:g} N "
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
            + ", ".join(f"{n} {v:.4g}" for n, v in zip(JOINT_NAMES, self.tracking_error_max, strict=True)),
        ]
        for e in self.episodes:
            out.append(
                f"episode {e.get('episode')}: success={e.get('success')} steps={e.get('steps')} "
                f"peak force {float(e.get('peak_force_n', 0.0)):.3f} N"
            )
        return out


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
        elif topic == "/deploy/command":
            rows["ct"].append(t - start)
            rows["cq"].append(payload["q"])
            rows["sent"].append(bool(payload["sent"]))
            rows["stop"].append(bool(payload["safety_stop"]))
            predicted = payload.get("predicted_force_n")
            rows["pf"].append(np.nan if predicted is None else float(predicted))
        elif topic == "/deploy/action":
            rec.actions += 1
    if rows["mt"]:
        rec.measured_t, rec.measured_q = np.array(rows["mt"]), np.array(rows["mq"], dtype=float)
        rec.force_n = np.array(rows["f"], dtype=float)
    if rows["ct"]:
        rec.command_t, rec.command_q = np.array(rows["ct"]), np.array(rows["cq"], dtype=float)
        rec.command_sent, rec.safety_stop = np.array(rows["sent"]), np.array(rows["stop"])
        rec.predicted_force_n = np.array(rows["pf"], dtype=float)
    return rec


def summarize_recording(rec: Recording) -> RecordingSummary:
    """Duration, commands, holds and safety stops, peak force and tracking error of a recording."""
    times = np.concatenate([rec.measured_t, rec.command_t, [e["t"] for e in rec.events]])
    duration = float(times.max() - times.min()) if times.size else 0.0
    force = float(np.linalg.norm(rec.force_n, axis=1).max()) if len(rec.force_n) else 0.0
    if len(rec.command_q) > 1 and len(rec.measured_q) == len(rec.command_q):
        # Measured at tick t answers the command of tick t-1; pairs across a gap (homing between
        # episodes) are not tracking.
        consecutive = np.diff(rec.measured_t) < 0.5
        error = np.abs(rec.command_q[:-1] - rec.measured_q[1:])[consecutive]
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


def plot_recording(rec: Recording, out: str | Path) -> Path:
    """Joint commands against measurements, and the force, over time; written to ``out`` (PNG)."""
    figure = Figure(figsize=(12, 11))
    axes = figure.subplots(4, 2, sharex=True)
    for i, name in enumerate(JOINT_NAMES):
        ax = axes.flat[i]
        if len(rec.command_q):
            ax.plot(rec.command_t, rec.command_q[:, i], label="command", lw=1.0)
        if len(rec.measured_q):
            ax.plot(rec.measured_t, rec.measured_q[:, i], label="measured", lw=1.0, ls="--")
        ax.set_ylabel(f"{name} [{'m' if name == 'insertion' else 'rad'}]")
        ax.legend(loc="best", fontsize=7)
    ax = axes.flat[6]
    if len(rec.force_n):
        ax.plot(rec.measured_t, np.linalg.norm(rec.force_n, axis=1), label="|measured force|")
    if np.isfinite(rec.predicted_force_n).any():
        ax.plot(rec.command_t, rec.predicted_force_n, label="|predicted force| (dry run)")
    ax.set_ylabel("force [N]")
    ax.legend(loc="best", fontsize=7)
    ax = axes.flat[7]
    if len(rec.safety_stop):
        ax.plot(rec.command_t, rec.safety_stop.astype(float), label="safety stop")
        ax.plot(rec.command_t, rec.command_sent.astype(float) * 0.5, label="sent (0.5)")
    for e in rec.events:
        if e.get("kind") in ("hold", "deadman", "interrupted"):
            ax.axvline(e["t"], color="red", lw=1.0)
    ax.set_ylabel("flags")
    ax.legend(loc="best", fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    kind = "dry run" if rec.meta.get("dry_run") else "deploy"
    figure.suptitle(f"{rec.meta.get('target', '?')} {kind}: {rec.meta.get('policy', '')}")
    figure.tight_layout()
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=80)
    return path
