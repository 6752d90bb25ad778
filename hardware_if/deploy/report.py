"""What a deploy did: :class:`DeployReport`, and each tick, safety event and hold counted in it and recorded.

Every count the report keeps goes to the recording too, as the tick's ``/deploy/measured`` and
``/deploy/command`` or an ``/deploy/event`` (:mod:`hardware_if.recording.recorder`), so a replay finds
what the report says.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import signal
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hardware_if.common.errors import HoldError
from hardware_if.recording.recorder import Recorder
from psm_control.commands import ControlOutput, MeasuredState
from safety.config import SafetyConfig
from safety.force_bound import sensing_warning
from safety.force_watch import FORCE_LIMIT_STALL
from sim.success_interval import describe_success

__all__ = [
    "EXIT_FORCE_LIMIT",
    "EXIT_HOLD",
    "DeployReport",
    "account",
    "account_excursions",
    "command_payload",
    "hold_advice",
    "measured_payload",
    "record_hold",
    "warn_sensing",
]

#: Exit status of a deploy that stopped because the deadman held the arm.
EXIT_HOLD = 4
#: Exit status of a deploy in which the force on the tissue certainly exceeded the limit: the true force in the
#: simulation, a measured force beyond the limit plus the sensing's error bound on a dVRK. A run that also held
#: or was stopped ends with that status instead (4, 128 + signal), so that each fault keeps its own; the
#: report says the force either way.
EXIT_FORCE_LIMIT = 3


@dataclass
class DeployReport:
    """What a deploy did: per-episode results, commands, safety events, forces, and why it ended."""

    target: str
    dry_run: bool
    record: Path
    episodes: list[dict[str, Any]] = field(default_factory=list)
    commands: int = 0
    commands_sent: int = 0
    safety_stops: int = 0
    interventions: collections.Counter[str] = field(default_factory=collections.Counter)
    peak_force_n: float = 0.0
    predicted_peak_force_n: float = 0.0
    fault: str = ""
    interrupted: bool = False
    signal: str = ""
    holds: int = 0
    invalid_actions: int = 0
    force_limit_n: float = float("nan")
    force_sensing_error_n: float = 0.0
    force_limit_exceeded: int = 0
    force_over_limit_s: float = 0.0
    force_limit_stalls: int = 0
    force_sensing_error_beyond_n: float = 0.0
    force_sensing_ticks_beyond: int = 0
    force_sensing_ticks_untrusted: int = 0
    force_sensing_trusted_tip_speed_m_s: float | None = None

    @property
    def exit_code(self) -> int:
        """128 + signal on a stop signal, :data:`EXIT_HOLD` on a hold, else :data:`EXIT_FORCE_LIMIT` when the force
        limit was certainly exceeded, 0 when every episode ran to its end within it."""
        if self.interrupted:
            return 128 + int(signal.Signals[self.signal or "SIGINT"])
        if self.fault:
            return EXIT_HOLD
        return EXIT_FORCE_LIMIT if self.force_limit_exceeded else 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (the recording's ``/deploy/report``)."""
        data = dataclasses.asdict(self)
        data["record"] = str(self.record)
        data["interventions"] = dict(self.interventions)
        data["success_rate"] = float(np.mean([e["success"] for e in self.episodes])) if self.episodes else float("nan")
        return data

    def lines(self) -> list[str]:
        """The human report."""
        kind = "dry run (nothing published on motion topics)" if self.dry_run else "deploy"
        out = [f"{kind} to {self.target}: {len(self.episodes)} episode(s), recorded to {self.record}"]
        for e in self.episodes:
            out.append(
                f"  episode {e['episode']} seed {e['seed']}: {'success' if e['success'] else 'no success'}, "
                f"{e['steps']} steps, peak force {e['peak_force_n']:.3f} N"
                + (f", goal distance {1000 * e['goal_distance_m']:.1f} mm" if "goal_distance_m" in e else "")
            )
        if self.episodes and not self.dry_run:
            successes = sum(bool(e["success"]) for e in self.episodes)
            out.append(f"  success: {describe_success(successes, len(self.episodes))}")
        verb = "would have sent" if self.dry_run else "sent"
        out.append(
            f"  commands: {self.commands} computed, {verb} {self.commands_sent if not self.dry_run else self.commands}"
        )
        top = ", ".join(f"{k} x{v}" for k, v in self.interventions.most_common()) or "none"
        out.append(f"  safety: {self.safety_stops} stop tick(s); interventions: {top}")
        out.append(f"  holds: {self.holds}; invalid actions: {self.invalid_actions}")
        out.append(f"  peak measured force {self.peak_force_n:.3f} N")
        told = (
            f" beyond the force sensing's {self.force_sensing_error_n:.2f} N error bound (all the measured force "
            "can tell)"
            if self.force_sensing_error_n > 0
            else ""
        )
        if self.force_limit_exceeded:
            status = f"; exit status {EXIT_FORCE_LIMIT}" if self.exit_code == EXIT_FORCE_LIMIT else ""
            out.append(
                f"  FORCE LIMIT {self.force_limit_n:g} N EXCEEDED{told} {self.force_limit_exceeded} x, "
                f"{self.force_over_limit_s:.2f} s in all (events force_limit_exceeded in the recording{status})"
            )
        elif self.episodes:
            out.append(f"  force limit {self.force_limit_n:g} N: never exceeded{told}")
        else:
            out.append(f"  force limit {self.force_limit_n:g} N: no episode ran")
        if self.force_sensing_ticks_beyond:
            out.append(
                f"  force sensing: on {self.force_sensing_ticks_beyond} of {self.commands} ticks the commanded "
                "accelerations were beyond those the calibration was fitted on, or the tip moved faster than "
                "retraction speeds; the force was trusted there only to its error_bound_n "
                f"{self.force_sensing_error_beyond_n:.2f} N"
            )
        if self.force_sensing_ticks_untrusted:
            out.append(
                f"  force sensing: on {self.force_sensing_ticks_untrusted} of {self.commands} ticks the commanded tip "
                f"speed was above {self.force_sensing_trusted_tip_speed_m_s:.3g} m/s, the fastest the calibration's "
                "logs reached; the force was not trusted there (the travel bound kept the limit while the jaws "
                "could hold tissue)"
            )
        if self.force_limit_stalls:
            out.append(
                f"  the force limit stalled the retraction in {self.force_limit_stalls} episode(s) "
                "(force_limit_stall events in the recording; the warnings above say what holding the tissue cost)"
            )
        if self.dry_run:
            out.append(f"  predicted peak force {self.predicted_peak_force_n:.3f} N")
        if self.fault:
            out.append(f"  HOLD: {self.fault}")
            advice = hold_advice(self.fault)
            if advice:
                out.append(f"  {advice}")
        if self.interrupted:
            name = "Ctrl-C" if self.signal in ("", "SIGINT") else self.signal
            out.append(f"  interrupted ({name}): stopped commanding between two ticks")
        return out


def hold_advice(reason: str) -> str:
    """What a user can change after a hold that a busy machine can cause, or "" for any other hold.

    A stale ``measured_js`` (the client's deadman or the chain's) and a policy overrun are the holds a machine
    busy with other work causes in a rehearsal against ``sim-dvrk`` (docs/rehearsal-and-reports.md); on a robot
    they say that its measurements or the policy came late, which no setting should hide.
    """
    if reason.startswith("stale:"):
        return (
            "what to change: if this machine is busy with other work, raise deadman_timeout_s (at most 1 s) in a "
            "--safety-config TOML file (e.g. deadman_timeout_s = 0.3) for a rehearsal; on a robot, find what "
            "delays its measurements first (docs/dvrk.md#the-deadmans-timeout)"
        )
    if reason.startswith("policy overrun:"):
        return (
            "what to change: if this machine is busy with other work, give a rehearsal's policy longer with "
            "--policy-budget S (e.g. 0.2); on a robot, a policy step must end within its period"
        )
    return ""


def measured_payload(measured: MeasuredState, effort: np.ndarray | None = None) -> dict[str, Any]:
    """A tick's ``/deploy/measured`` record; a dVRK's with its joint efforts, so that a free-space deploy's
    recording is a log ``calibrate-wrench --from`` fits on."""
    payload = {
        "q": measured.q,
        "qd": measured.qd,
        "jaw": measured.jaw,
        "force_n": measured.force_n,
        "stamp_s": measured.stamp_s,
    }
    if effort is not None:
        payload["effort"] = effort
    return payload


def command_payload(
    output: ControlOutput, sent: bool, predicted_force_n: float | None = None, travel_bound_n: float = math.nan
) -> dict[str, Any]:
    """A tick's ``/deploy/command`` record: the chain's command, whether it was sent, and why it was changed.

    ``travel_bound_n`` is the chain's bound on the true force from the grasp point's travel at this tick
    (:attr:`safety.force_bound.ForceBound.travel_bound_n`) [N]; recorded only where it is in force (finite).
    """
    command = output.command
    payload = {
        "q": command.q,
        "qd": command.qd,
        "jaw": command.jaw,
        "stamp_s": command.stamp_s,
        "sent": sent,
        "safety_stop": output.safety_stop,
        "reason": output.reason,
        "interventions": list(output.interventions),
    }
    if predicted_force_n is not None:
        payload["predicted_force_n"] = predicted_force_n
    if math.isfinite(travel_bound_n):
        payload["travel_bound_n"] = travel_bound_n
    return payload


def account(report: DeployReport, recorder: Recorder, output: ControlOutput) -> None:
    """Count a tick's command, safety stop and interventions; record, say and count the chain's warnings."""
    report.commands += 1
    report.interventions.update(output.interventions)
    if output.safety_stop:
        report.safety_stops += 1
        recorder.write("/deploy/event", {"kind": "safety_stop", "text": output.reason})
    for event in output.events:  # the chain's warnings: said at once, kept in the recording, counted
        recorder.write("/deploy/event", {**event, "episode": len(report.episodes)})
        print(f"WARNING: {event['text']}", file=sys.stderr, flush=True)
        report.force_limit_stalls += event["kind"] == FORCE_LIMIT_STALL


def account_excursions(
    report: DeployReport, recorder: Recorder, excursions: list[dict[str, Any]], episode: int
) -> None:
    """Record each ``force_limit_exceeded`` event of an episode and count it in the report."""
    for event in excursions:
        recorder.write("/deploy/event", {**event, "episode": episode})
        report.force_limit_exceeded += 1
        report.force_over_limit_s += float(event["duration_s"])


def record_hold(report: DeployReport, recorder: Recorder, fault: HoldError) -> None:
    """Record a hold (once): the reason in the report (exit 4) and the event with its data in the recording."""
    if fault.recorded:
        return
    fault.recorded = True
    report.fault = str(fault)
    report.holds += 1
    recorder.write("/deploy/event", {"kind": "hold", "text": str(fault), "fault": fault.kind, "data": fault.data})


def warn_sensing(config: SafetyConfig, source: str, recorder: Recorder, echo: Any, *, calibrated: bool) -> None:
    """Tell the user, and the recording, when the force limit is below what the sensing resolves."""
    warning = sensing_warning(config, source, calibrated=calibrated)
    if warning:
        echo(warning)
        recorder.write("/deploy/event", {"kind": "force_sensing_warning", "text": warning})
