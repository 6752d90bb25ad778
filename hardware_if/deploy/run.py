"""Deploying a policy through the control chain, to the simulation or to a dVRK over ROS 2.

The data flow is the simulation's: each policy step turns the 5-D action into a
:class:`~psm_control.commands.CartesianDelta`, gives it to :class:`safety.chain.ControlChain` once, then
ticks the chain at the control rate and sends each verified joint command to the backend. For
``target="sim"`` the backend is the task environment's (:func:`sim.evaluation.run_episode`); for
``target="dvrk"`` it is :class:`~hardware_if.client.psm_client.PsmClient` (the same chain, unchanged) and the
observation comes from :class:`~hardware_if.client.remote_task.RemoteTask`.

A dry run (``dry_run=True``, dVRK only) listens to the live arm and computes, logs and records every
command, but the client has no command publishers at all: nothing goes out on a motion topic. Its
report counts the commands it would have sent, the chain's safety interventions and the predicted
force (measured force plus the chain's conservative stiffness prior times how far the command would
pull the grasped tool from where it is).

One fault path, the same for the simulation, the dVRK and a dry run: a policy that raises (anything,
``SystemExit`` included) or returns something other than 5 finite numbers, a policy step slower than its
budget (default one policy period), malformed or non-finite data on any subscribed topic, an arm not
ENABLED, homed and idle when an episode starts (waited for up to ``wait_s``), a stale or vanished arm, a
tracking error (the deadman, :mod:`hardware_if.client.deadman`), another commander or console of the arm
(:mod:`hardware_if.common.commander_watch`, checked before anything reaches a console and while it runs), an arm
not at the episode's start in a dry run or after the move back, a tracking divergence
(:mod:`hardware_if.client.arm_pose`), a recording that cannot be written (:mod:`hardware_if.recording.checked_file`), or
any other error while the arm is commanded all end the same way: nothing new is commanded (the arm keeps
the last verified command), the fault is recorded as a ``hold`` event with its reason and data, the report
says ``HOLD: <reason>`` and the exit status is :data:`EXIT_HOLD`. SIGINT, SIGTERM and SIGHUP stop between
two control ticks, close the recording and exit with 128 + the signal number (130, 143, 129). Every run is
recorded (:mod:`hardware_if.recording.recorder`).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import sim.envs
from hardware_if.client.arm_pose import TrackingWatch, return_to_start, start_offset
from hardware_if.client.perceived_env import camera_task
from hardware_if.client.readiness import describe_operating_state, dry_run_wait_hint, is_ready_state
from hardware_if.client.registration import console_base_frame
from hardware_if.client.registration_checks import check_registration
from hardware_if.client.task_estimate import TaskEstimate, as_point, format_point
from hardware_if.common.commander_watch import DISCOVERY_S, console_kind, served_by
from hardware_if.common.errors import DvrkError, HoldError
from hardware_if.common.gc_pauses import freeze_startup_heap
from hardware_if.common.session import ros_session
from hardware_if.common.task_topics import DEFAULT_RIG, camera_topics
from hardware_if.recording.checked_file import RecordingError
from hardware_if.recording.recorder import Recorder
from hardware_if.wrench.calibration import WrenchCalibration
from policies.resolve import resolve_policy
from policies.shipped import CAMERA, PRETRAINED, pretrained_path, variant_of
from psm_control.commands import CartesianDelta, ControlOutput, JointCommand, MeasuredState
from psm_control.errors import ConfigurationError
from safety.chain import ControlChain
from safety.config import SafetyConfig
from safety.force_bound import sensing_warning
from safety.force_watch import FORCE_LIMIT_STALL, ForceLimitWatch
from sim.evaluation import PolicyError, run_episode
from sim.force_sensing import error_bound_n, sensing_params, with_sensing
from sim.randomization import DEFAULT_RANGES
from sim.scene import PhysicsParams
from sim.scene3d import PsmScene
from sim.scene_stream import LiveScene, SceneStream, StreamScene
from sim.success_interval import describe_success
from sim.sweep.stopping import handling
from sim.tissue import SITE_NAMES, TissueParams

__all__ = ["EXIT_HOLD", "EXIT_INTERRUPTED", "STOP_SIGNALS", "DeployOptions", "DeployReport", "Interrupted", "deploy"]

#: Exit status of a deploy that stopped because the deadman held the arm.
EXIT_HOLD = 4
#: Longest wait for the console's first operating_state after its first measured_js [s] (a dVRK publishes
#: the state on change with history, sim-dvrk also every 0.1 s).
OPERATING_STATE_WAIT_S = 2.0
#: Exit status of a deploy stopped with Ctrl-C (SIGINT); SIGTERM gives 143 and SIGHUP 129 (128 + signal).
EXIT_INTERRUPTED = 130
#: Signals that stop a deploy between two ticks, as Ctrl-C does.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Interrupted(KeyboardInterrupt):
    """A stop signal arrived (SIGINT, SIGTERM or SIGHUP): stop commanding between two ticks.

    Attributes:
        signum: The signal's number.
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(signal.Signals(signum).name)


class _Stopper:
    """Turns stop signals into :class:`Interrupted`, never in the middle of a control tick.

    Outside a tick the signal raises at once (a wait for the arm is cut short); inside one
    (``with stopper.tick():``) it is noted and raised when the tick has been sent and recorded.
    """

    def __init__(self) -> None:
        self.signum = 0
        self._in_tick = False

    def _handle(self, signum: int, _frame: Any) -> None:
        self.signum = self.signum or signum
        if not self._in_tick:
            raise Interrupted(self.signum)

    @contextlib.contextmanager
    def installed(self) -> Iterator[_Stopper]:
        with handling(STOP_SIGNALS, self._handle):
            yield self

    @contextlib.contextmanager
    def tick(self) -> Iterator[None]:
        self._in_tick = True
        try:
            yield
        finally:
            self._in_tick = False
        if self.signum:
            raise Interrupted(self.signum)


@dataclass(frozen=True)
class DeployOptions:
    """Settings of one deploy.

    Attributes:
        policy: ``scripted``, ``random``, ``module:callable`` or a checkpoint path.
        target: ``sim`` or ``dvrk``.
        task: Task id (the policy's task; for ``dvrk`` the task topics' meaning).
        arm: Arm name (dVRK).
        rate_hz: Control rate of the chain [Hz]; None: the simulation's (sim) or the dVRK's 100 Hz.
        dry_run: Listen and compute only (dVRK).
        safety_config: Chain limits; None: :class:`SafetyConfig` defaults.
        record: MCAP output file.
        episodes: Number of episodes.
        seed: Seed of the first episode.
        wait_s: How long to wait for the arm's first measurement, the task topics, and for the arm to be
            ENABLED, homed and idle at each episode start [s]; running out is a hold.
        policy_budget_s: Longest a policy step may take [s]; None: one policy period. Slower is a hold.
        live: Serve the 3-D scene for the Foxglove app on ws://127.0.0.1 at this port (0 picks one);
            None serves nothing. The recording holds the same scene either way.
        site: The registered grasp site [m] in ``<arm>_base`` (dVRK): the task state then comes from it,
            the goal and the jaw (:class:`~hardware_if.client.remote_task.RegisteredSite`), not from the task
            topics. None: the ``/<arm>/task/*`` topics.
        goal: Where the site must go [m] in ``<arm>_base``, with ``site``; None: the task's nominal goal
            about the site (:func:`sim.envs.nominal_goal`).
        force_sensing: What the simulation's chain and policy sense of the force (sim; :mod:`sim.force_sensing`).
        force_sensing_error_n: The robot's force-sensing error bound [N] (dVRK); None: the ``dvrk`` model's
            bound for the console's uncompensated ``measured_cf``.
        force_sensing_source: What that bound is from, for the run-start warning (dVRK).
        wrench_calibration: The force-sensing calibration to take the force with (dVRK); None: ``measured_cf``.
        perception: ``camera[:MODEL]``: the site from the endoscope's images (:mod:`hardware_if.client.perceived_env`).
        texture: The flap's texture image file (sim).
        image_timeout_s: With ``perception`` on a dVRK: endoscope images older than this hold the arm [s].
        endoscope_rig: With ``perception`` on a dVRK: the stereo rig's name (``/<rig>/left/image_raw`` ...).
        camera_site: With ``perception`` on a dVRK: which of the flap's named sites (``centre``, ``left``,
            ``right``) the episodes grasp; the camera sees all three (MultiSite varies it per episode).
    """

    policy: str
    target: str
    record: Path
    task: str = "lift"
    arm: str = "PSM1"
    rate_hz: float | None = None
    dry_run: bool = False
    safety_config: SafetyConfig | None = None
    episodes: int = 1
    seed: int = 0
    wait_s: float = 30.0
    policy_budget_s: float | None = None
    live: int | None = None
    site: tuple[float, float, float] | None = None
    goal: tuple[float, float, float] | None = None
    force_sensing: str = "ideal"
    force_sensing_error_n: float | None = None
    force_sensing_source: str = "dvrk measured_cf, uncompensated"
    wrench_calibration: WrenchCalibration | None = None
    perception: str | None = None
    texture: str | None = None
    image_timeout_s: float = 0.5
    endoscope_rig: str = DEFAULT_RIG
    camera_site: str = "centre"

    def __post_init__(self) -> None:
        if self.site is not None and self.target != "dvrk":
            raise ConfigurationError("site", self.site, "--site with --target dvrk (the simulation sees its tissue)")
        if self.perception is not None and self.site is not None:
            raise ConfigurationError("perception", self.perception, "either --perception or --site/--registration")
        if self.camera_site not in SITE_NAMES:
            raise ConfigurationError("camera_site", self.camera_site, f"one of {', '.join(SITE_NAMES)}")
        if self.camera_site != "centre" and (self.perception is None or self.target != "dvrk"):
            raise ConfigurationError(
                "camera_site", self.camera_site, "--camera-site with --perception camera on --target dvrk"
            )
        if self.goal is not None and self.target != "dvrk":
            raise ConfigurationError("goal", self.goal, "--goal with --target dvrk (the simulation sets its own goal)")
        if self.goal is not None and self.site is None and self.perception is None:
            raise ConfigurationError(
                "goal", self.goal, "--goal with --site or --perception (the task topics bring their own goal)"
            )
        if self.site is not None:
            as_point(self.site, "site")
        if self.goal is not None:
            as_point(self.goal, "goal")
        if self.policy_budget_s is not None and not (np.isfinite(self.policy_budget_s) and self.policy_budget_s > 0):
            raise ConfigurationError("policy_budget_s", self.policy_budget_s, "a finite number of seconds > 0")
        if self.target not in ("sim", "dvrk"):
            raise ConfigurationError("target", self.target, "'sim' or 'dvrk'")
        if self.dry_run and self.target != "dvrk":
            raise ConfigurationError("dry_run", self.dry_run, "--dry-run with --target dvrk (live robot state)")
        if self.episodes < 1:
            raise ConfigurationError("episodes", self.episodes, "at least 1")


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
    force_limit_exceeded: int = 0
    force_over_limit_s: float = 0.0
    force_limit_stalls: int = 0

    @property
    def exit_code(self) -> int:
        """0 when every episode ran to its end, :data:`EXIT_HOLD` on a hold, 128 + signal on a stop signal."""
        if self.interrupted:
            return 128 + int(signal.Signals[self.signal or "SIGINT"])
        return EXIT_HOLD if self.fault else 0

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
        if self.force_limit_exceeded:
            out.append(
                f"  FORCE LIMIT {self.force_limit_n:g} N EXCEEDED {self.force_limit_exceeded} x, "
                f"{self.force_over_limit_s:.2f} s in all (events force_limit_exceeded in the recording)"
            )
        elif self.episodes:
            out.append(f"  force limit {self.force_limit_n:g} N: never exceeded")
        else:
            out.append(f"  force limit {self.force_limit_n:g} N: no episode ran")
        if self.force_limit_stalls:
            out.append(
                f"  the force limit stalled the retraction in {self.force_limit_stalls} episode(s) "
                "(force_limit_stall events in the recording; the warnings above say what holding the tissue cost)"
            )
        if self.dry_run:
            out.append(f"  predicted peak force {self.predicted_peak_force_n:.3f} N")
        if self.fault:
            out.append(f"  HOLD: {self.fault}")
        if self.interrupted:
            name = "Ctrl-C" if self.signal in ("", "SIGINT") else self.signal
            out.append(f"  interrupted ({name}): stopped commanding between two ticks")
        return out


def _measured_payload(measured: MeasuredState) -> dict[str, Any]:
    return {
        "q": measured.q,
        "qd": measured.qd,
        "jaw": measured.jaw,
        "force_n": measured.force_n,
        "stamp_s": measured.stamp_s,
    }


def _command_payload(output: ControlOutput, sent: bool, predicted_force_n: float | None = None) -> dict[str, Any]:
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
    return payload


def _account(report: DeployReport, recorder: Recorder, output: ControlOutput) -> None:
    report.commands += 1
    report.interventions.update(output.interventions)
    if output.safety_stop:
        report.safety_stops += 1
        recorder.write("/deploy/event", {"kind": "safety_stop", "text": output.reason})
    for event in output.events:  # the chain's warnings: said at once, kept in the recording, counted
        recorder.write("/deploy/event", {**event, "episode": len(report.episodes)})
        print(f"WARNING: {event['text']}", file=sys.stderr, flush=True)
        report.force_limit_stalls += event["kind"] == FORCE_LIMIT_STALL


def _account_excursions(
    report: DeployReport, recorder: Recorder, excursions: list[dict[str, Any]], episode: int
) -> None:
    """Record each ``force_limit_exceeded`` event of an episode and count it in the report."""
    for event in excursions:
        recorder.write("/deploy/event", {**event, "episode": episode})
        report.force_limit_exceeded += 1
        report.force_over_limit_s += float(event["duration_s"])


def deploy(options: DeployOptions, *, echo: Any = print) -> DeployReport:
    """Run the deploy and record it; ``echo`` shows progress lines (default ``print``).

    A recording that cannot be written (at its start, during the run or at its end) is a hold like any other
    fault: ``recording failed: <path>: <os error>``, exit 4, recorded if the file still takes it.

    Raises:
        ConfigurationError: The policy or task cannot be set up (before the arm is commanded).
    """
    report = DeployReport(options.target, options.dry_run, options.record)
    report.force_limit_n = (options.safety_config or SafetyConfig()).effective_force_limit_n
    try:
        _deploy_recorded(options, report, echo)
    except RecordingError as e:  # at the recording's start or end; in between it is held where it happens
        if not report.fault:
            report.fault = str(e)
            report.holds += 1
    return report


def _deploy_recorded(options: DeployOptions, report: DeployReport, echo: Any) -> None:
    stopper = _Stopper()
    live_view = contextlib.nullcontext() if options.live is None else LiveScene(port=options.live)
    with live_view as live, stopper.installed(), Recorder(options.record, mirror=live) as recorder:
        if live is not None:
            echo(f"live: ws://127.0.0.1:{live.port} (open it in the Foxglove app)")
        meta = {
            k: (str(v) if isinstance(v, Path | SafetyConfig) else v) for k, v in dataclasses.asdict(options).items()
        }
        recorder.write("/deploy/meta", meta)
        try:
            try:
                if options.target == "sim":
                    _deploy_sim(options, report, recorder, echo, stopper)
                else:
                    _deploy_dvrk(options, report, recorder, echo, stopper)
            except HoldError as e:
                _hold(report, recorder, e)
            except PolicyError as e:
                # The episode runner wraps whatever the policy call raised; the checked policy's own
                # verdict (policy error, invalid action, overrun) is the hold, with its data.
                cause = e.__cause__
                _hold(report, recorder, cause if isinstance(cause, HoldError) else HoldError("policy error", str(e)))
            except (KeyboardInterrupt, ConfigurationError):
                raise
            except Exception as e:  # anything else while commanding is a hold too, never a traceback
                _hold(report, recorder, HoldError("fault", f"{type(e).__name__}: {e}"))
        except KeyboardInterrupt as e:
            report.interrupted = True
            report.signal = signal.Signals(e.signum).name if isinstance(e, Interrupted) else "SIGINT"
            text = "Ctrl-C" if report.signal == "SIGINT" else report.signal
            recorder.write("/deploy/event", {"kind": "interrupted", "text": text, "signal": report.signal})
        except ConfigurationError as e:
            recorder.write("/deploy/event", {"kind": "error", "text": str(e)})
            recorder.write("/deploy/report", report.to_dict())
            raise
        recorder.write("/deploy/report", report.to_dict())


def _hold(report: DeployReport, recorder: Recorder, fault: HoldError) -> None:
    """Record a hold (once): the reason in the report (exit 4) and the event with its data in the recording."""
    if fault.recorded:
        return
    fault.recorded = True
    report.fault = str(fault)
    report.holds += 1
    recorder.write("/deploy/event", {"kind": "hold", "text": str(fault), "fault": fault.kind, "data": fault.data})


def _to_start(
    client: Any, start_q: np.ndarray, start_jaw: float, options: DeployOptions, episode: int, echo: Any
) -> None:
    """Before an episode: the arm and jaw at the episode's start, sent back there if not (held in a dry run)."""
    reason = client.wait_ready(options.wait_s)  # where an arm is matters once it is ready to be commanded
    if reason:
        fault = _deadman_hold(reason)
        fault.data.update(episode=episode)
        raise fault
    measured = client.measure()
    offset = start_offset(measured.q, start_q, measured_jaw=measured.jaw, start_jaw=start_jaw)
    if not offset:
        return
    if options.dry_run:
        raise HoldError(
            "not at start",
            f"episode {episode}: {offset} (a dry run moves nothing: "
            f"tissue-retract ready-arm --arm {options.arm} moves it there)",
        )
    _require_exclusive(client, f"episode {episode}: before the move to its start")
    echo(f"episode {episode}: {offset}; moving the arm back (move_jp, jaw/move_jp)")
    try:
        reason = return_to_start(client, start_q, options.wait_s, start_jaw=start_jaw)
    except DvrkError as e:
        reason = str(e)
    if reason:
        raise HoldError("not at start", f"episode {episode}: {reason}")


def _check_calibration_console(options: DeployOptions, client: Any) -> None:
    """Hold before the first command when the calibration was fitted on another kind of console than the one
    serving the arm (a simulated console's efforts are not a real PSM's, nor the reverse)."""
    calibration = options.wrench_calibration
    if calibration is None or calibration.console == "unknown":
        return
    consoles = served_by(client, options.arm)
    serving = console_kind(consoles)
    if serving not in ("unknown", calibration.console):
        raise HoldError(
            "calibration",
            f"the wrench calibration was fitted on {calibration.origin}, and {options.arm} is served by a "
            f"{serving} console ({', '.join(consoles)}): a calibration fitted on the console it is used with "
            "(re-run tissue-retract calibrate-wrench against this one)",
            {"fitted_on": calibration.console, "served_by": consoles},
        )


def _require_exclusive(client: Any, when: str) -> None:
    """Hold, before anything reaches a console, when another commander or console of the arm is in the graph."""
    reason = client.exclusive()
    if reason:
        fault = _deadman_hold(reason)
        fault.data.update(checked=when)
        raise fault


def _deadman_hold(reason: str) -> HoldError:
    """The hold of a deadman verdict such as ``"stale: measured_js 0.4 s old"``."""
    kind, _, detail = reason.partition(": ")
    return HoldError(kind, detail or reason)


def _checked_policy(policy: Callable[[Any], Any], budget_s: float) -> Callable[[Any], np.ndarray]:
    """The policy, with its step checked: it must return 5 finite numbers within ``budget_s``.

    The run's first step is not timed: nothing moves before its action, and a network's first call
    loads and prepares its kernels (a torch policy's takes about 0.2 s).
    """
    calls = [0]

    def checked(observation: Any) -> np.ndarray:
        calls[0] += 1
        started = time.monotonic()
        try:
            raw = policy(observation)
        except KeyboardInterrupt:
            raise
        except BaseException as e:  # SystemExit included: a policy ends its episode, never the program
            raise HoldError("policy error", f"the policy raised {type(e).__name__}: {e}") from None
        elapsed = time.monotonic() - started
        try:
            action = np.asarray(raw, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise HoldError("invalid action", f"{str(raw)[:80]!r} is not numbers (allowed: 5 finite numbers)") from None
        if action.shape != (5,) or not np.all(np.isfinite(action)):
            raise HoldError(
                "invalid action",
                f"shape {action.shape} with {int(np.sum(~np.isfinite(action)))} non-finite value(s) "
                "(allowed: 5 finite numbers)",
                {"action": action},
            )
        if elapsed > budget_s and calls[0] > 1:
            raise HoldError(
                "policy overrun",
                f"the policy step took {elapsed:.3f} s, budget {budget_s:.3f} s",
                {"elapsed_s": elapsed, "budget_s": budget_s},
            )
        return action

    return checked


# -- simulation -------------------------------------------------------------------------------------
class _RecordingChain:
    """Forwards to the environment's control chain and records every tick (a stop signal waits for its end)."""

    def __init__(self, chain: Any, report: DeployReport, recorder: Recorder, stopper: _Stopper) -> None:
        self._chain, self._report, self._recorder, self._stopper = chain, report, recorder, stopper

    def __getattr__(self, name: str) -> Any:
        return getattr(self._chain, name)

    def tick(self, measured: MeasuredState) -> ControlOutput:
        with self._stopper.tick():
            output: ControlOutput = self._chain.tick(measured)
            self._recorder.write("/deploy/measured", _measured_payload(measured))
            self._recorder.write("/deploy/command", _command_payload(output, sent=True))
            _account(self._report, self._recorder, output)
            self._report.commands_sent += 1
            self._report.peak_force_n = max(self._report.peak_force_n, float(np.linalg.norm(measured.force_n)))
        return output


def _resolve_policy(options: DeployOptions, env: Any, echo: Any) -> tuple[Any, Any]:
    """The deploy's policy; for ``pretrained``, says which shipped file fits what the run observes."""
    resolved = resolve_policy(options.policy, env)
    if options.policy == PRETRAINED:
        path, variant = pretrained_path(env), variant_of(env)
        trained_on = "the camera's site" if variant == CAMERA else f"{variant} force sensing"
        echo(f"policy: the shipped one trained on {trained_on} ({path.parent.name}/{path.name})")
    return resolved


def _warn_sensing(config: SafetyConfig, source: str, recorder: Recorder, echo: Any) -> None:
    """Tell the user, and the recording, when the force limit is below what the sensing resolves."""
    warning = sensing_warning(config, source)
    if warning:
        echo(warning)
        recorder.write("/deploy/event", {"kind": "force_sensing_warning", "text": warning})


def _deploy_sim(options: DeployOptions, report: DeployReport, recorder: Recorder, echo: Any, stopper: _Stopper) -> None:

    overrides: dict[str, Any] = {
        "safety_config": options.safety_config,
        "force_sensing": options.force_sensing,
        "tissue": TissueParams(texture_path=options.texture),
    }
    if options.rate_hz is not None:
        overrides["physics"] = PhysicsParams(control_period_s=1.0 / options.rate_hz)
    # The scene on the recording's wall clock, played at the physics' speed when someone watches live.
    task_env = sim.envs.make(options.task, **overrides)
    if options.perception is not None:
        task_env = camera_task(task_env, options.perception.partition(":")[2] or None)
    env = StreamScene(task_env, [recorder], realtime=recorder.mirror is not None, clock=time.time)
    try:
        policy, reset = _resolve_policy(options, env, echo)
        env.reset(seed=options.seed)  # builds the chain once; wrap it so every tick is recorded
        unwrapped: Any = env.unwrapped
        _warn_sensing(unwrapped.safety_config, f"{options.force_sensing} force sensing", recorder, echo)
        unwrapped.controller = _RecordingChain(unwrapped.controller, report, recorder, stopper)
        budget = options.policy_budget_s or unwrapped.config.physics.step_s
        checked = _checked_policy(policy, budget)
        step = {"episode": 0, "n": 0}

        def recorded_policy(observation: dict[str, np.ndarray]) -> np.ndarray:
            try:
                action = checked(observation)
            except HoldError as e:
                e.data.update(episode=step["episode"], step=step["n"], observation=observation)
                raise
            recorder.write(
                "/deploy/action",
                {"episode": step["episode"], "step": step["n"], "action": action, "observation": observation},
            )
            step["n"] += 1
            return action

        for episode in range(options.episodes):
            seed = options.seed + episode
            step.update(episode=episode, n=0)
            recorder.write("/deploy/event", {"kind": "episode_start", "episode": episode, "seed": seed})
            echo(f"episode {episode}: started (seed {seed})")
            result = run_episode(env, recorded_policy, reset, seed)
            entry = {"episode": episode, **result.to_dict()}
            report.episodes.append(entry)
            report.invalid_actions += int(entry.get("invalid_actions", 0))
            report.force_limit_n = result.force_limit_n
            _account_excursions(report, recorder, result.force_limit_exceeded, episode)
            recorder.write("/deploy/event", {"kind": "episode_end", **entry})
            seen = "" if result.site_error_mm is None else f", site seen {result.site_error_mm:.1f} mm off"
            echo(f"episode {episode}: success={result.success} peak force {result.peak_force_n:.3f} N{seen}")
    finally:
        env.close()


# -- dVRK over ROS 2 ---------------------------------------------------------------------------------
def _deploy_dvrk(
    options: DeployOptions, report: DeployReport, recorder: Recorder, echo: Any, stopper: _Stopper
) -> None:
    # These import rclpy (the ros extra), which must come after the ROS environment is set.
    from hardware_if.client.psm_client import PsmClient
    from hardware_if.client.remote_task import RegisteredSite, RemoteTask, TaskListener

    rate_hz = options.rate_hz if options.rate_hz is not None else 100.0
    base = options.safety_config if options.safety_config is not None else SafetyConfig()
    config = dataclasses.replace(base, control_rate_hz=rate_hz)
    error_n = options.force_sensing_error_n
    if error_n is None:
        error_n = error_bound_n(sensing_params("dvrk"))
    config = with_sensing(config, error_n, DEFAULT_RANGES)  # the task flap's ranges: the tissue assumed
    # Said before anything reaches the arm: a limit the robot's force sensing cannot tell.
    _warn_sensing(config, options.force_sensing_source, recorder, echo)
    configured = "the default" if options.safety_config is None else "from the safety configuration"
    echo(
        f"deadman: the arm holds when measured_js is older than {config.deadman_timeout_s:g} s "
        f"(deadman_timeout_s, {configured})"
    )

    with ros_session(signal_handlers=False):
        # A name of this process's own: another deploy's nodes are then "another commander", never "us".
        client = PsmClient(
            options.arm,
            deadman_timeout_s=config.deadman_timeout_s,
            listen_only=options.dry_run,
            node_name=f"{options.arm.lower()}_deploy_{os.getpid()}",
        )
        client.set_wrench_calibration(options.wrench_calibration)
        client.start()
        listener: Any  # TaskListener, RegisteredSite or CameraSite: the task source interface
        if options.perception is not None:
            from hardware_if.client.camera_site import CameraSite  # rclpy, as above
            from policies.perception import load_site_estimator  # torch's network: only where the camera is used

            estimator = load_site_estimator(options.perception.partition(":")[2] or None)
            given = None if options.goal is None else np.asarray(options.goal, dtype=float)
            listener = CameraSite(
                options.task,
                estimator,
                client,
                rig=options.endoscope_rig,
                wait_s=options.wait_s,
                stale_after_s=options.image_timeout_s,
                goal=given,
                site=options.camera_site,
            )
            aim = "the task's nominal goal about the seen site" if given is None else format_point(given)
            echo(
                f"task state: the flap's {options.camera_site} site from the endoscope's images on /{listener.rig}/, "
                f"goal {aim} (no task topics)"
            )
        elif options.site is not None:
            site = np.asarray(options.site, dtype=float)
            goal = sim.envs.nominal_goal(options.task, site) if options.goal is None else np.asarray(options.goal)
            listener = RegisteredSite(TaskEstimate(site, goal), client)
            echo(f"task state: registered site {format_point(site)}, goal {format_point(goal)} (no task topics)")
        else:
            listener = TaskListener(options.arm, listen_only=options.dry_run)
        own = [listener.get_fully_qualified_name()] if isinstance(listener, TaskListener) else []
        sensed: tuple[str, ...] = ()
        if options.perception is not None:  # the images the site is seen in: one source, as the arm's state
            sensed = tuple(camera_topics(listener.rig).values())
        client.watch_commanders(*own, sensed=sensed)
        try:
            try:
                client.wait_for_measurement(options.wait_s)
            except DvrkError as e:
                reason = client.status.reason  # invalid data is said as the deadman says it, not as "not ready"
                invalid = reason.startswith("invalid data")
                raise (_deadman_hold(reason) if invalid else HoldError("not ready", str(e))) from None
            client.settle_graph(options.wait_s)  # the other programs on the domain, not only the console
            freeze_startup_heap()  # before the first command: short collector pauses from here on
            _require_exclusive(client, "before the first command")
            client.pin_sources()  # from here on, a sensed topic's publisher may not change
            _check_calibration_console(options, client)
            if options.site is not None:
                _check_registered_site(options, config, client, echo)
            # The state arrives on its own topic, possibly after the first measured_js: wait for it too.
            waited_s = min(options.wait_s, OPERATING_STATE_WAIT_S)
            state, homed, busy = client.wait_for_operating_state(waited_s)
            echo(f"{options.arm}: operating state {describe_operating_state(state, homed, busy, waited_s)}")
            if options.dry_run and not is_ready_state(state, homed):
                echo(dry_run_wait_hint(options.arm, state, homed, options.wait_s))
            view = RemoteTask(options.task, client, listener)
            policy, reset = _resolve_policy(options, view, echo)
            budget = options.policy_budget_s or view.config.physics.step_s
            checked = _checked_policy(policy, budget)
            if not options.dry_run and not is_ready_state(state, homed):
                echo(f"{options.arm}: enable and home")
                try:
                    client.enable(options.wait_s)
                    client.home(options.wait_s)
                except DvrkError as e:
                    raise HoldError("not ready", str(e)) from None
            chain = ControlChain(config)
            for episode in range(options.episodes):
                seed = options.seed + episode
                _require_exclusive(client, f"episode {episode}: before its first command")
                if episode > 0 and not options.dry_run:
                    try:
                        client.home(options.wait_s)  # back to the task's start joints
                    except DvrkError as e:
                        raise HoldError("not ready", f"episode {episode}: {e}") from None
                _to_start(client, view.model.home(), view.config.jaw_open_rad, options, episode, echo)
                if not listener.wait(options.wait_s):
                    awaited = f"task topics /{options.arm}/task/site and goal"
                    if options.perception is not None:
                        awaited = f"endoscope images on /{listener.rig}/"
                    raise HoldError("not ready", f"no {awaited} in {options.wait_s:g} s")
                after = float("-inf")
                if not options.dry_run and isinstance(listener, TaskListener) and listener.serves_resets():
                    # The simulated dVRK: a new scene, and only task and arm states of that scene from here on.
                    _require_exclusive(client, f"episode {episode}: before the task reset")
                    try:
                        after = listener.reset_and_wait(seed, options.wait_s)
                    except DvrkError as e:
                        raise HoldError("not ready", f"episode {episode}: {e}") from None
                    if not listener.wait(options.wait_s, after_s=after):
                        raise HoldError("not ready", f"no task state after the reset in {options.wait_s:g} s")
                listener.new_episode()
                seen = getattr(listener, "seen_site", None)
                if seen is not None:
                    choice = getattr(getattr(listener, "estimator", None), "last_choice", "")
                    echo(f"episode {episode}: site seen at {format_point(seen)}" + (f" by {choice}" if choice else ""))
                # The arm must be ENABLED, homed, idle and valid before the first command of an episode.
                reason = client.wait_ready(options.wait_s, after_s=after)
                measured, start_jaw = client.measure(), view.config.jaw_open_rad
                offset = reason or start_offset(
                    measured.q, view.model.home(), measured_jaw=measured.jaw, start_jaw=start_jaw
                )
                if offset:
                    fault = _deadman_hold(reason) if reason else HoldError("not at start", offset)
                    fault.data.update(episode=episode, seed=seed)
                    raise fault
                echo(f"episode {episode}: started (seed {seed})")
                entry = _dvrk_episode(
                    options, report, recorder, client, view, chain, checked, reset, episode, seed, stopper
                )
                report.episodes.append(entry)
                recorder.write("/deploy/event", {"kind": "episode_end", **entry})
                echo(
                    f"episode {episode}: success={entry['success']} steps {entry['steps']} "
                    f"peak force {entry['peak_force_n']:.3f} N"
                )
        except HoldError as e:
            # On disk before the ROS teardown below: a native crash in it must not lose the hold.
            _hold(report, recorder, e)
            raise
        finally:
            listener.close()
            client.close()


def _check_registered_site(options: DeployOptions, config: SafetyConfig, client: Any, echo: Any) -> None:
    """Warn about a ``--site``/``--registration`` far from the tissue; hold, before any command, on one unusable."""
    try:
        client.next_measurement(float("-inf"), options.wait_s)  # and the poses the base frame comes from
    except DvrkError as e:
        raise HoldError("not ready", str(e)) from None
    site = np.asarray(options.site, dtype=float)
    findings = check_registration(site, console_base_frame(client), config=config)
    for finding in findings:
        if not finding.refuse:
            echo(f"WARNING: registered site: {finding.text}")
    refusals = [finding.text for finding in findings if finding.refuse]
    if refusals:
        raise HoldError("registered site", "; ".join(refusals), {"site_m": site.tolist()})


def _dvrk_episode(
    options: DeployOptions,
    report: DeployReport,
    recorder: Recorder,
    client: Any,
    view: Any,
    chain: Any,
    policy: Callable[[Any], np.ndarray],
    reset: Any,
    episode: int,
    seed: int,
    stopper: _Stopper,
) -> dict[str, Any]:
    """One episode; a fault raises :class:`HoldError` after the tick that saw it was recorded."""
    cfg = view.config
    steps_total = sim.envs.MAX_EPISODE_STEPS
    ticks_per_step = max(1, round(cfg.physics.step_s / chain.control_period_s))
    stiffness = chain.config.stiffness_prior_n_per_m
    measured = client.measure()
    # The chain works about the RCM, as in the simulation (its workspace box is an RCM box): the policy's
    # base-frame step is rotated into the RCM's axes and given as a local delta.
    base_frame = view.base_frame()
    rotation_rcm_to_base = base_frame[:3, :3]
    # The arm as measured and where the chain sends it (in a dry run: where it would), 20 times a second.
    scene = SceneStream(PsmScene(view.model, f"{options.arm}_base", base_frame), [recorder], period_s=0.05)
    chain.reset(measured)
    tracking = TrackingWatch(chain.config.deadman_timeout_s + 2 * chain.control_period_s)
    tracking.reset(measured.q, time.monotonic())
    reset()
    recorder.write("/deploy/event", {"kind": "episode_start", "episode": episode, "seed": seed})
    report.force_limit_n = chain.config.effective_force_limit_n
    watch = ForceLimitWatch(report.force_limit_n, chain.control_period_s)
    started = time.monotonic()
    peak = 0.0
    steps = 0
    next_tick = time.monotonic()
    step_end = time.monotonic()
    try:
        for step in range(steps_total):
            if step and view.listener.state_each_period:  # the task state the arm's last commands produced
                view.listener.wait(4 * chain.control_period_s, after_s=step_end)  # (up to one period late)
            observation = view.observation()
            try:
                action = np.clip(policy(observation), -1.0, 1.0)
            except HoldError as e:
                e.data.update(episode=episode, step=step, observation=observation)
                raise
            recorder.write(
                "/deploy/action", {"episode": episode, "step": step, "action": action, "observation": observation}
            )
            jaw = cfg.jaw_closed_rad if action[4] < 0 else cfg.jaw_open_rad
            step_rcm = rotation_rcm_to_base.T @ (action[:3] * cfg.max_step_m)
            delta = CartesianDelta(step_rcm, float(action[3]) * cfg.max_yaw_rad, jaw, "local")
            chain.set_target(delta, client.measure())
            for _ in range(ticks_per_step):
                with stopper.tick():
                    measured = client.measure()
                    diverged = "" if options.dry_run else tracking.check(measured.q)
                    output = chain.tick(measured)
                    force = float(np.linalg.norm(measured.force_n))
                    if math.isfinite(force):  # a non-finite force is a sensing fault: the deadman holds on it
                        peak = max(peak, force)
                        ended = watch.update(measured.force_n, time.monotonic() - started)
                        if ended is not None:
                            _account_excursions(report, recorder, [ended.to_event()], episode)
                        report.peak_force_n = max(report.peak_force_n, force)
                    predicted = None
                    if options.dry_run:
                        predicted = _predicted_force(view, measured, output.command, stiffness)
                        report.predicted_peak_force_n = max(report.predicted_peak_force_n, predicted)
                    else:
                        client.servo_jp(output.command)
                        tracking.commanded(output.command.q, time.monotonic())
                    status = client.status
                    sent = not options.dry_run and not status.holding
                    recorder.write("/deploy/measured", _measured_payload(measured))
                    recorder.write("/deploy/command", _command_payload(output, sent, predicted))
                    _account(report, recorder, output)
                    report.commands_sent += int(sent)
                    scene.tick(
                        time.time(),
                        measured.q,
                        measured.jaw,
                        commanded_q=output.command.q,
                        commanded_jaw=output.command.jaw,
                        site=_task_point(view.listener, "site"),
                        goal=_task_point(view.listener, "goal"),
                        grasp=scene.scene.grasp_point(measured.q, measured.jaw),
                        force_n=measured.force_n,
                    )
                if diverged and status.ok:  # nothing more is sent; the cause, once discovery shows it, is named
                    status = status._replace(ok=False, reason=client.exclusive_within(DISCOVERY_S) or diverged)
                if not status.ok:  # the dry run holds as the deploy would: it rehearses the real thing
                    fault = _deadman_hold(status.reason)
                    fault.data.update(episode=episode, step=step, measured=_measured_payload(measured))
                    raise fault
                next_tick += chain.control_period_s
                delay = next_tick - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                else:
                    next_tick = time.monotonic()  # behind: tick again at once, do not burst to catch up
            steps += 1
            step_end = time.monotonic()
    finally:  # an excursion a hold interrupts is recorded too
        last = watch.finish()
        if last is not None:
            _account_excursions(report, recorder, [last.to_event()], episode)
    entry: dict[str, Any] = {
        "episode": episode,
        "seed": seed,
        "steps": steps,
        "peak_force_n": peak,
        "force_limit_exceeded": [e.to_event() for e in watch.excursions],
    }
    try:
        success, distance = view.success()
        entry.update(success=bool(success), goal_distance_m=distance, success_source=view.listener.success_source)
    except Exception as e:  # no task state: not a success, say why
        entry.update(success=False, note=str(e))
    if options.dry_run:
        entry["deadman"] = client.status.reason
    return entry


def _task_point(listener: Any, name: str) -> np.ndarray | None:
    """A task point for the scene, or None while there is none (the scene then leaves it out)."""
    try:
        return np.asarray(listener.point(name))
    except DvrkError:
        return None


def _predicted_force(view: Any, measured: MeasuredState, command: JointCommand, stiffness_n_per_m: float) -> float:
    """Measured force plus a linear spring (the chain's stiffness prior) pulled by the command, if grasped."""
    force = np.asarray(measured.force_n, dtype=float)
    if not view.holding:
        return float(np.linalg.norm(force))
    configuration = view._configuration
    configuration.update(measured.q, measured.jaw)
    tip_measured = configuration.measured_pose()[:3, 3]
    configuration.update(command.q, command.jaw)
    tip_command = configuration.measured_pose()[:3, 3]
    return float(np.linalg.norm(force + stiffness_n_per_m * (tip_command - tip_measured)))
