"""One episode on a dVRK: the policy's steps, the chain's ticks at the control rate, each tick recorded.

Every tick the deadman's verdict and the arm's tracking of the commands are checked: a fault raises a
hold after the tick that saw it was recorded. The chain's own deadman (a measurement stamped older than
the timeout by the chain's clock) is a hold too, not a safety stop the episode runs on after. A dry run
computes and records the same ticks and sends nothing; it predicts the force the commands would have
caused instead.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import sim.envs
from hardware_if.client.arm_pose import TrackingWatch
from hardware_if.common.commander_watch import DISCOVERY_S
from hardware_if.common.errors import DvrkError, HoldError
from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.report import DeployReport, account, account_excursions, command_payload, measured_payload
from hardware_if.deploy.stopping import Stopper
from hardware_if.recording.recorder import Recorder
from psm_control.commands import CartesianDelta, JointCommand, MeasuredState
from safety.chain import DEADMAN_STOP
from safety.force_watch import ForceLimitWatch
from sim.scene3d import PsmScene
from sim.scene_stream import SceneStream

__all__ = ["deadman_hold", "dvrk_episode"]


def dvrk_episode(
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
    stopper: Stopper,
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
    client.pin_clock()  # from the first tick on, a console clock that jumps is a data fault
    chain.reset(measured)
    tracking = TrackingWatch(chain.config.deadman_timeout_s + 2 * chain.control_period_s)
    tracking.reset(measured.q, time.monotonic())
    reset()
    recorder.write("/deploy/event", {"kind": "episode_start", "episode": episode, "seed": seed})
    report.force_limit_n = chain.config.effective_force_limit_n
    report.force_sensing_error_n = chain.config.force_sensing_error_n
    # The console's measured force, not the tissue's: an excursion counts where the error bound cannot explain it.
    watch = ForceLimitWatch(report.force_limit_n, chain.control_period_s, report.force_sensing_error_n)
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
                        ended = watch.update(
                            measured.force_n, time.monotonic() - started, chain.force_bound.tick_error_n
                        )
                        if ended is not None:
                            account_excursions(report, recorder, [ended.to_event()], episode)
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
                    recorder.write("/deploy/measured", measured_payload(measured, client.efforts()))
                    recorder.write(
                        "/deploy/command",
                        command_payload(output, sent, predicted, chain.force_bound.travel_bound_n),
                    )
                    account(report, recorder, output)
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
                if status.ok and output.safety_stop and output.reason.startswith(DEADMAN_STOP):
                    status = status._replace(ok=False, reason=f"stale: the chain's {output.reason}")
                if not status.ok:  # the dry run holds as the deploy would: it rehearses the real thing
                    fault = deadman_hold(client, status.reason)
                    fault.data.update(episode=episode, step=step, measured=measured_payload(measured))
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
            account_excursions(report, recorder, [last.to_event()], episode)
        bound = chain.force_bound
        if bound.regime is not None:  # the chain's count runs over the episodes: the report's is the total
            report.force_sensing_ticks_beyond = bound.ticks_outside_regime
            report.force_sensing_ticks_untrusted = bound.ticks_untrusted
            report.force_sensing_trusted_tip_speed_m_s = bound.regime.covered_tip_speed_m_s
            report.force_sensing_error_beyond_n = bound.regime.error_outside_n
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


def deadman_hold(client: Any, reason: str) -> HoldError:
    """The hold of a deadman verdict such as ``"stale: measured_js 0.4 s old"``, naming the other commander
    or console it is about once the graph has its name (:meth:`PsmClient.named`)."""
    reason = client.named(reason)
    kind, _, detail = reason.partition(": ")
    return HoldError(kind, detail or reason)


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
