"""Deploying a policy through the control chain, to the simulation or to a dVRK over ROS 2.

The data flow is the simulation's: each policy step turns the 5-D action into a
:class:`~psm_control.commands.CartesianDelta`, gives it to :class:`safety.chain.ControlChain` once, then
ticks the chain at the control rate and sends each verified joint command to the backend. For
``target="sim"`` the backend is the task environment's (:func:`sim.evaluation.run_episode`); for
``target="dvrk"`` it is :class:`~hardware_if.psm_client.PsmClient` (the same chain, unchanged) and the
observation comes from :class:`~hardware_if.remote_task.RemoteTask`.

A dry run (``dry_run=True``, dVRK only) listens to the live arm and computes, logs and records every
command, but the client has no command publishers at all: nothing goes out on a motion topic. Its
report counts the commands it would have sent, the chain's safety interventions and the predicted
force (measured force plus the chain's conservative stiffness prior times how far the command would
pull the grasped tool from where it is).

The deadman (:mod:`hardware_if.deadman`) turns a stale or vanished arm, an arm not ENABLED and homed,
or a tracking error into a hold; the deploy then stops, records the fault and returns
:data:`EXIT_HOLD`. Every run is recorded (:mod:`hardware_if.recording`).
"""

from __future__ import annotations

import collections
import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import sim.envs
from hardware_if.recording import Recorder
from hardware_if.session import ros_session
from policies.resolve import resolve_policy
from psm_control.commands import CartesianDelta, ControlOutput, JointCommand, MeasuredState
from psm_control.errors import ConfigurationError
from safety.chain import ControlChain
from safety.config import SafetyConfig
from sim.evaluation import run_episode
from sim.scene import PhysicsParams

__all__ = ["EXIT_HOLD", "DeployOptions", "DeployReport", "deploy"]

#: Exit status of a deploy that stopped because the deadman held the arm.
EXIT_HOLD = 4
#: Exit status of a deploy stopped with Ctrl-C.
EXIT_INTERRUPTED = 130


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
        wait_s: How long to wait for the arm's first measurement and the task topics [s].
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

    def __post_init__(self) -> None:
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
    force_limit_exceeded: int = 0
    max_force_excess_n: float = 0.0
    force_exceeded_s: float = 0.0
    fault: str = ""
    interrupted: bool = False

    @property
    def exit_code(self) -> int:
        """0 when every episode ran to its end, :data:`EXIT_HOLD` on a hold, 130 on Ctrl-C."""
        if self.interrupted:
            return EXIT_INTERRUPTED
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
            out.append(f"  success: {successes}/{len(self.episodes)} episodes")
        verb = "would have sent" if self.dry_run else "sent"
        out.append(
            f"  commands: {self.commands} computed, {verb} {self.commands_sent if not self.dry_run else self.commands}"
        )
        top = ", ".join(f"{k} x{v}" for k, v in self.interventions.most_common()) or "none"
        out.append(f"  safety: {self.safety_stops} stop tick(s); interventions: {top}")
        out.append(f"  peak measured force {self.peak_force_n:.3f} N")
        out.append(
            f"  force limit exceeded: {self.force_limit_exceeded} time(s), max excess {self.max_force_excess_n:.3f} N, "
            f"{self.force_exceeded_s:.2f} s"
        )
        if self.dry_run:
            out.append(f"  predicted peak force {self.predicted_peak_force_n:.3f} N")
        if self.fault:
            out.append(f"  HOLD: {self.fault}")
        if self.interrupted:
            out.append("  interrupted (Ctrl-C): stopped commanding")
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


def _account_force(report: DeployReport, recorder: Recorder, chain: Any) -> None:
    """Count the episode's force-limit exceedances (the chain's monitor) and record each as an event."""
    monitor = chain.force_monitor
    monitor.finish()
    for event in monitor.take():
        report.force_limit_exceeded += 1
        report.max_force_excess_n = max(report.max_force_excess_n, event.excess_n)
        report.force_exceeded_s += event.duration_s
        recorder.write("/deploy/event", {"kind": "force_limit_exceeded", **event.to_dict()})
    for warning in chain.force_warnings:
        recorder.write("/deploy/event", {"kind": "force_warning", "text": warning})
    chain.force_warnings.clear()


def _account_sim_force(report: DeployReport, recorder: Recorder, result: Any) -> None:
    """The same count from a simulated episode's result (the environment drained the chain's monitor)."""
    if result.force_limit_exceeded:
        report.force_limit_exceeded += result.force_limit_exceeded
        report.max_force_excess_n = max(report.max_force_excess_n, result.max_force_excess_n)
        report.force_exceeded_s += result.force_exceeded_s
        recorder.write(
            "/deploy/event",
            {
                "kind": "force_limit_exceeded",
                "count": result.force_limit_exceeded,
                "excess_n": result.max_force_excess_n,
                "duration_s": result.force_exceeded_s,
                "limit_n": result.force_limit_n,
            },
        )


def deploy(options: DeployOptions, *, echo: Any = print) -> DeployReport:
    """Run the deploy and record it; ``echo`` shows progress lines (default ``print``)."""
    report = DeployReport(options.target, options.dry_run, options.record)
    with Recorder(options.record) as recorder:
        meta = {
            k: (str(v) if isinstance(v, Path | SafetyConfig) else v) for k, v in dataclasses.asdict(options).items()
        }
        recorder.write("/deploy/meta", meta)
        try:
            if options.target == "sim":
                _deploy_sim(options, report, recorder, echo)
            else:
                _deploy_dvrk(options, report, recorder, echo)
        except KeyboardInterrupt:
            report.interrupted = True
            recorder.write("/deploy/event", {"kind": "interrupted", "text": "Ctrl-C"})
        recorder.write("/deploy/report", report.to_dict())
    return report


# -- simulation -------------------------------------------------------------------------------------
class _RecordingChain:
    """Forwards to the environment's control chain and records every tick."""

    def __init__(self, chain: Any, report: DeployReport, recorder: Recorder) -> None:
        self._chain, self._report, self._recorder = chain, report, recorder

    def __getattr__(self, name: str) -> Any:
        return getattr(self._chain, name)

    def tick(self, measured: MeasuredState) -> ControlOutput:
        output: ControlOutput = self._chain.tick(measured)
        self._recorder.write("/deploy/measured", _measured_payload(measured))
        self._recorder.write("/deploy/command", _command_payload(output, sent=True))
        _account(self._report, self._recorder, output)
        self._report.commands_sent += 1
        self._report.peak_force_n = max(self._report.peak_force_n, float(np.linalg.norm(measured.force_n)))
        return output


def _deploy_sim(options: DeployOptions, report: DeployReport, recorder: Recorder, echo: Any) -> None:

    overrides: dict[str, Any] = {"safety_config": options.safety_config}
    if options.rate_hz is not None:
        overrides["physics"] = PhysicsParams(control_period_s=1.0 / options.rate_hz)
    env = sim.envs.make(options.task, **overrides)
    try:
        policy, reset = resolve_policy(options.policy, env)
        env.reset(seed=options.seed)  # builds the chain once; wrap it so every tick is recorded
        unwrapped = env.unwrapped
        unwrapped.controller = _RecordingChain(unwrapped.controller, report, recorder)
        step = {"episode": 0, "n": 0}

        def recorded_policy(observation: dict[str, np.ndarray]) -> np.ndarray:
            action = np.asarray(policy(observation))
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
            result = run_episode(env, recorded_policy, reset, seed)
            entry = {"episode": episode, **result.to_dict()}
            report.episodes.append(entry)
            _account_sim_force(report, recorder, result)
            recorder.write("/deploy/event", {"kind": "episode_end", **entry})
            echo(f"episode {episode}: success={result.success} peak force {result.peak_force_n:.3f} N")
    finally:
        env.close()


# -- dVRK over ROS 2 ---------------------------------------------------------------------------------
def _deploy_dvrk(options: DeployOptions, report: DeployReport, recorder: Recorder, echo: Any) -> None:
    # These import rclpy (the ros extra), which must come after the ROS environment is set.
    from hardware_if.psm_client import PsmClient
    from hardware_if.remote_task import RemoteTask, TaskListener

    rate_hz = options.rate_hz if options.rate_hz is not None else 100.0
    base = options.safety_config if options.safety_config is not None else SafetyConfig()
    config = dataclasses.replace(base, control_rate_hz=rate_hz)
    faults: list[str] = []

    def on_fault(status: Any) -> None:
        faults.append(status.reason)

    with ros_session(signal_handlers=False):
        client = PsmClient(options.arm, on_fault=on_fault, listen_only=options.dry_run).start()
        listener = TaskListener(options.arm, listen_only=options.dry_run)
        try:
            client.wait_for_measurement(options.wait_s)
            state, homed, _ = client.operating_state()
            echo(f"{options.arm}: operating state {state or 'unknown'}, {'homed' if homed else 'not homed'}")
            if not options.dry_run and not (state == "ENABLED" and homed):
                echo(f"{options.arm}: enable and home")
                client.enable(options.wait_s)
                client.home(options.wait_s)
            view = RemoteTask(options.task, client, listener)
            policy, reset = resolve_policy(options.policy, view)
            chain = ControlChain(config)
            for episode in range(options.episodes):
                seed = options.seed + episode
                if episode > 0 and not options.dry_run:
                    client.home(options.wait_s)
                asked = time.monotonic()
                if listener.request_reset(seed) and not listener.wait(options.wait_s, after_s=asked + 0.05):
                    raise ConfigurationError("task", options.task, f"task topics under /{options.arm}/task/")
                if not listener.wait(options.wait_s):
                    raise ConfigurationError(
                        "task", options.task, f"task topics /{options.arm}/task/site and goal (none received)"
                    )
                time.sleep(0.1)  # let a reset scene's first state arrive everywhere
                echo(f"episode {episode}: started (seed {seed})")
                entry = _dvrk_episode(options, report, recorder, client, view, chain, policy, reset, episode, seed)
                report.episodes.append(entry)
                recorder.write("/deploy/event", {"kind": "episode_end", **entry})
                echo(
                    f"episode {episode}: success={entry['success']} steps {entry['steps']} "
                    f"peak force {entry['peak_force_n']:.3f} N"
                )
                if report.fault:
                    break
        finally:
            listener.close()
            client.close()


def _dvrk_episode(
    options: DeployOptions,
    report: DeployReport,
    recorder: Recorder,
    client: Any,
    view: Any,
    chain: Any,
    policy: Any,
    reset: Any,
    episode: int,
    seed: int,
) -> dict[str, Any]:

    cfg = view.config
    steps_total = sim.envs.MAX_EPISODE_STEPS
    ticks_per_step = max(1, round(cfg.physics.step_s / chain.control_period_s))
    stiffness = chain.config.stiffness_prior_n_per_m
    measured = client.measure()
    # The chain works about the RCM, as in the simulation (its workspace box is an RCM box): the policy's
    # base-frame step is rotated into the RCM's axes and given as a local delta.
    rotation_rcm_to_base = view.base_frame()[:3, :3]
    chain.reset(measured)
    reset()
    recorder.write("/deploy/event", {"kind": "episode_start", "episode": episode, "seed": seed})
    peak = 0.0
    steps = 0
    next_tick = time.monotonic()
    fault_reported = False
    step_end = time.monotonic()
    for step in range(steps_total):
        if step:  # the task state the arm's last commands produced, not an older one (up to one period late)
            view.listener.wait(4 * chain.control_period_s, after_s=step_end)
        observation = view.observation()
        action = np.clip(np.asarray(policy(observation), dtype=float).reshape(-1), -1.0, 1.0)
        recorder.write(
            "/deploy/action", {"episode": episode, "step": step, "action": action, "observation": observation}
        )
        jaw = cfg.jaw_closed_rad if action[4] < 0 else cfg.jaw_open_rad
        step_rcm = rotation_rcm_to_base.T @ (action[:3] * cfg.max_step_m)
        delta = CartesianDelta(step_rcm, float(action[3]) * cfg.max_yaw_rad, jaw, "local")
        chain.set_target(delta, client.measure())
        for _ in range(ticks_per_step):
            measured = client.measure()
            output = chain.tick(measured)
            force = float(np.linalg.norm(measured.force_n))
            peak = max(peak, force)
            report.peak_force_n = max(report.peak_force_n, force)
            predicted = None
            if options.dry_run:
                predicted = _predicted_force(view, measured, output.command, stiffness)
                report.predicted_peak_force_n = max(report.predicted_peak_force_n, predicted)
            else:
                client.servo_jp(output.command)
            status = client.status
            sent = not options.dry_run and not status.holding
            recorder.write("/deploy/measured", _measured_payload(measured))
            recorder.write("/deploy/command", _command_payload(output, sent, predicted))
            _account(report, recorder, output)
            report.commands_sent += int(sent)
            if status.holding and not options.dry_run:
                report.fault = status.reason
                recorder.write("/deploy/event", {"kind": "hold", "text": status.reason})
                fault_reported = True
                break
            if options.dry_run and not status.ok and not fault_reported:
                fault_reported = True
                recorder.write("/deploy/event", {"kind": "deadman", "text": status.reason})
            next_tick += chain.control_period_s
            delay = next_tick - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_tick = time.monotonic()  # behind: tick again at once, do not burst to catch up
        steps += 1
        step_end = time.monotonic()
        if report.fault:
            break
    entry: dict[str, Any] = {"episode": episode, "seed": seed, "steps": steps, "peak_force_n": peak}
    _account_force(report, recorder, chain)
    try:
        success, distance = view.success()
        entry.update(success=bool(success) and not report.fault, goal_distance_m=distance)
    except Exception as e:  # no task state after a fault: not a success, say why
        entry.update(success=False, note=str(e))
    if options.dry_run:
        entry["deadman"] = client.status.reason
    return entry


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
