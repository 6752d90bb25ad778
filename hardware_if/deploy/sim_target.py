"""The deploy's simulation target: the task environment's own chain and physics, every tick recorded."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

import sim.envs
from hardware_if.client.perceived_env import camera_task
from hardware_if.common.errors import HoldError
from hardware_if.deploy.options import DeployOptions
from hardware_if.deploy.policy import checked_policy, policy_for
from hardware_if.deploy.report import (
    DeployReport,
    account,
    account_excursions,
    command_payload,
    measured_payload,
    warn_sensing,
)
from hardware_if.deploy.stopping import Stopper
from hardware_if.recording.recorder import Recorder
from psm_control.commands import ControlOutput, MeasuredState
from sim.evaluation import run_episode
from sim.scene import PhysicsParams
from sim.scene_stream import StreamScene
from sim.tissue import TissueParams

__all__ = ["deploy_sim"]


class _RecordingChain:
    """Forwards to the environment's control chain and records every tick (a stop signal waits for its end)."""

    def __init__(self, chain: Any, report: DeployReport, recorder: Recorder, stopper: Stopper) -> None:
        self._chain, self._report, self._recorder, self._stopper = chain, report, recorder, stopper

    def __getattr__(self, name: str) -> Any:
        return getattr(self._chain, name)

    def tick(self, measured: MeasuredState) -> ControlOutput:
        with self._stopper.tick():
            output: ControlOutput = self._chain.tick(measured)
            self._recorder.write("/deploy/measured", measured_payload(measured))
            travel_bound_n = self._chain.force_bound.travel_bound_n
            self._recorder.write("/deploy/command", command_payload(output, sent=True, travel_bound_n=travel_bound_n))
            account(self._report, self._recorder, output)
            self._report.commands_sent += 1
            self._report.peak_force_n = max(self._report.peak_force_n, float(np.linalg.norm(measured.force_n)))
        return output


def deploy_sim(options: DeployOptions, report: DeployReport, recorder: Recorder, echo: Any, stopper: Stopper) -> None:
    """The episodes in the simulation: the task environment ticks its own chain, each tick recorded."""
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
        policy, reset = policy_for(options, env, echo)
        env.reset(seed=options.seed)  # builds the chain once; wrap it so every tick is recorded
        unwrapped: Any = env.unwrapped
        calibrated = options.force_sensing == "dvrk-calibrated"
        warn_sensing(
            unwrapped.safety_config, f"{options.force_sensing} force sensing", recorder, echo, calibrated=calibrated
        )
        unwrapped.controller = _RecordingChain(unwrapped.controller, report, recorder, stopper)
        budget = options.policy_budget_s or unwrapped.config.physics.step_s
        checked = checked_policy(policy, budget)
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
            account_excursions(report, recorder, result.force_limit_exceeded, episode)
            recorder.write("/deploy/event", {"kind": "episode_end", **entry})
            seen = "" if result.site_error_mm is None else f", site seen {result.site_error_mm:.1f} mm off"
            echo(f"episode {episode}: success={result.success} peak force {result.peak_force_n:.3f} N{seen}")
    finally:
        env.close()
