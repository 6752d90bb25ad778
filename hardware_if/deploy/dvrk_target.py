"""The deploy's dVRK target: a :class:`~hardware_if.client.psm_client.PsmClient` over ROS 2, and a task source.

Before the first command the arm must be the run's alone (one commander, one console, one source per
sensor), measured, and fitted to the calibration and registered site it is given; before each episode it
is ENABLED, homed, idle and at the episode's start (sent back there, except in a dry run). The episodes
themselves run in :mod:`hardware_if.deploy.dvrk_episode`.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np

import sim.envs
from hardware_if.client.arm_pose import return_to_start, start_offset
from hardware_if.client.readiness import describe_operating_state, dry_run_wait_hint, is_ready_state
from hardware_if.client.registration import console_base_frame
from hardware_if.client.registration_checks import check_registration
from hardware_if.client.task_estimate import TaskEstimate, format_point
from hardware_if.common.commander_watch import console_kind, served_by
from hardware_if.common.errors import DvrkError, HoldError
from hardware_if.common.gc_pauses import freeze_startup_heap
from hardware_if.common.session import ros_session
from hardware_if.common.task_topics import camera_topics
from hardware_if.deploy.dvrk_episode import deadman_hold, dvrk_episode
from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.policy import checked_policy, policy_for
from hardware_if.deploy.report import DeployReport, record_hold, warn_sensing
from hardware_if.deploy.stopping import Stopper
from hardware_if.recording.recorder import Recorder
from safety.chain import ControlChain
from safety.config import SafetyConfig
from sim.force_sensing import error_bound_n, sensing_params, with_sensing
from sim.randomization import DEFAULT_RANGES

__all__ = ["OPERATING_STATE_WAIT_S", "deploy_dvrk"]

#: Longest wait for the console's first operating_state after its first measured_js [s] (a dVRK publishes
#: the state on change with history, sim-dvrk also every 0.1 s).
OPERATING_STATE_WAIT_S = 2.0


def deploy_dvrk(options: DeployOptions, report: DeployReport, recorder: Recorder, echo: Any, stopper: Stopper) -> None:
    """The episodes on a dVRK (or ``sim-dvrk``) over ROS 2; a fault raises :class:`HoldError`, recorded."""
    # These import rclpy (the ros extra), which must come after the ROS environment is set.
    from hardware_if.client.psm_client import PsmClient
    from hardware_if.client.remote_task import RegisteredSite, RemoteTask, TaskListener

    rate_hz = options.rate_hz if options.rate_hz is not None else 100.0
    base = options.safety_config if options.safety_config is not None else SafetyConfig()
    config = dataclasses.replace(base, control_rate_hz=rate_hz)
    error_n = options.force_sensing_error_n
    if error_n is None:
        error_n = error_bound_n(sensing_params("dvrk"))
    # The task flap's ranges, the tissue assumed where the configuration declares no bound of its own.
    config = with_sensing(config, error_n, DEFAULT_RANGES, tissue_known=False)
    # Said before anything reaches the arm: a limit the robot's force sensing cannot tell.
    warn_sensing(
        config,
        options.force_sensing_source,
        recorder,
        echo,
        calibrated=options.wrench_calibration is not None or options.force_sensor,
    )
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
        client.declare_force_sensor(options.force_sensor)
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
                raise (deadman_hold(client, reason) if invalid else HoldError("not ready", str(e))) from None
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
            policy, reset = policy_for(options, view, echo)
            budget = options.policy_budget_s or view.config.physics.step_s
            checked = checked_policy(policy, budget)
            if not options.dry_run and not is_ready_state(state, homed):
                echo(f"{options.arm}: enable and home")
                try:
                    client.enable(options.wait_s)
                    client.home(options.wait_s)
                except DvrkError as e:
                    raise HoldError("not ready", str(e)) from None
            chain = ControlChain(config)
            if options.wrench_calibration is not None:  # its bound holds within the accelerations it was fitted on
                chain.force_bound.regime = options.wrench_calibration.sensing_regime()
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
                    fault = deadman_hold(client, reason) if reason else HoldError("not at start", offset)
                    fault.data.update(episode=episode, seed=seed)
                    raise fault
                echo(f"episode {episode}: started (seed {seed})")
                entry = dvrk_episode(
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
            record_hold(report, recorder, e)
            raise
        finally:
            listener.close()
            client.close()


def _to_start(
    client: Any, start_q: np.ndarray, start_jaw: float, options: DeployOptions, episode: int, echo: Any
) -> None:
    """Before an episode: the arm and jaw at the episode's start, sent back there if not (held in a dry run)."""
    reason = client.wait_ready(options.wait_s)  # where an arm is matters once it is ready to be commanded
    if reason:
        fault = deadman_hold(client, reason)
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
        fault = deadman_hold(client, reason)
        fault.data.update(checked=when)
        raise fault


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
