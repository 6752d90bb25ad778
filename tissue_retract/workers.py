"""Sweep workers: one trial of a policy in the simulation, for robustness sweeps and safety tuning.

A worker runs in a worker process of :func:`sim.sweep.run_trials` (named ``"module:function"``), keeps its
environment and policy between trials (one physics client per process), and returns one JSON-ready
outcome. They live here, above ``sim`` and ``policies``, because they compose both.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from hardware_if.client.perceived_env import camera_task
from policies.resolve import resolve_policy
from safety.config import SafetyConfig
from safety.force_bound import sensing_warning
from sim.disturbances import DisturbanceWrapper
from sim.envs import make
from sim.evaluation import check_start_inside_workspace, run_episode
from sim.force_sensing import SensingParams, calibrated_sensing
from sim.robustness import disturbances, episode_options
from sim.stiffness_fifths import STIFFNESS_KEY
from sim.tissue import TissueParams
from sim.tuning import integer_settings

__all__ = ["ROBUSTNESS_WORKER", "TUNING_WORKER", "check_sweep_policy", "robustness_episode", "tuning_episode"]

#: The names :func:`sim.sweep.run_trials` takes for the workers below.
ROBUSTNESS_WORKER = f"{__name__}:robustness_episode"
TUNING_WORKER = f"{__name__}:tuning_episode"

_CACHE: dict[tuple[Any, ...], Any] = {}


def _sensing(force_sensing: str, calibrated_error_n: float | None) -> str | SensingParams:
    """The preset, or with a calibration file's bound [N] a calibrated dVRK off by at most that much."""
    return force_sensing if calibrated_error_n is None else calibrated_sensing(calibrated_error_n)


def _environment(
    task: str,
    safety: bool,
    safety_config: Mapping[str, Any] | None,
    force_sensing: str = "ideal",
    tissue_ranges: Mapping[str, Any] | None = None,
    perception: str | None = None,
    texture: str | None = None,
    calibrated_error_n: float | None = None,
) -> Any:
    """The worker's environment; ``perception``: ``camera[:MODEL]``; ``texture``: the flap's image file;
    ``calibrated_error_n``: a calibration file's error bound [N] (the sensing is then a calibrated dVRK's)."""
    declared = {k: tuple(v) for k, v in (tissue_ranges or {}).items()}
    key = (
        "env",
        task,
        safety,
        json.dumps(dict(safety_config or {}), sort_keys=True),
        force_sensing,
        str(declared),
        perception,
        texture,
        calibrated_error_n,
    )
    if key not in _CACHE:
        kwargs: dict[str, Any] = {
            "safety": safety,
            "force_sensing": _sensing(force_sensing, calibrated_error_n),
            "randomization": declared,
            "tissue": TissueParams(texture_path=texture),
        }
        if safety_config:
            kwargs["safety_config"] = SafetyConfig.from_mapping(safety_config)
        for old in [k for k in _CACHE if k[0] == "env"]:
            _CACHE.pop(old).close()  # one environment (one physics client) per worker process
        env = make(task, **kwargs)
        _CACHE[key] = env if perception is None else camera_task(env, perception.partition(":")[2] or None)
    return _CACHE[key]


def check_sweep_policy(
    policy: str,
    task: str,
    safety_config: Mapping[str, Any] | None,
    *,
    allow_other_task: bool = False,
    force_sensing: str = "ideal",
    tissue_ranges: Mapping[str, Any] | None = None,
    calibrated_error_n: float | None = None,
    sensing_label: str | None = None,
    force_limits_n: list[float] | None = None,
) -> str:
    """Before a sweep starts: the policy loads for the task and the start pose lies inside the workspace box.

    ``calibrated_error_n`` is a calibration file's error bound [N] (the sensing a calibrated dVRK's),
    ``sensing_label`` what the warning calls the sensing (default: the preset's name), ``force_limits_n`` the
    force limits a grid sweeps (the warning names those, not the configuration's).

    Raises:
        ConfigurationError: The policy cannot be found or the workspace excludes the start pose.
        CheckpointError: The checkpoint is invalid or was trained for another task.

    Returns:
        The sweep's force-sensing warning ('' when its limit is one the sensing resolves).
    """
    env = _environment(task, True, safety_config, force_sensing, tissue_ranges, calibrated_error_n=calibrated_error_n)
    resolve_policy(policy, env, allow_other_task=allow_other_task)
    _, info = env.reset(seed=0)
    check_start_inside_workspace(env, float(info["workspace_violation_m"]))
    warning = sensing_warning(
        env.unwrapped.safety_config,
        sensing_label or f"{force_sensing} force sensing",
        calibrated=force_sensing == "dvrk-calibrated",
        limits_n=force_limits_n,
    )
    for key in [k for k in _CACHE if k[0] == "env"]:
        _CACHE.pop(key).close()
    return warning


def robustness_episode(
    trial: Mapping[str, Any],
    *,
    policy: str,
    task: str,
    relative: Mapping[str, bool],
    safety: bool = True,
    safety_config: Mapping[str, Any] | None = None,
    allow_other_task: bool = False,
    force_sensing: str = "ideal",
    tissue_ranges: Mapping[str, Any] | None = None,
    perception: str | None = None,
    texture: str | None = None,
    calibrated_error_n: float | None = None,
) -> dict[str, Any]:
    """Run one trial of a sweep and return its outcome.

    Args:
        trial: ``{"index", "seed", "params"}``.
        policy: A policy name, as :func:`policies.resolve.resolve_policy` takes.
        task: Task id.
        relative: Which parameters are multipliers of their nominal value.
        safety: Run the safety filter (False only for ablations).
        safety_config: Keyword overrides of :class:`safety.config.SafetyConfig` for this sweep.
        allow_other_task: Run a checkpoint trained for another task (with the same spaces).
        force_sensing: The force-sensing preset (:mod:`sim.force_sensing`).
        tissue_ranges: The tissue ranges the sweep declares (:func:`sim.robustness.sweep_ranges`).
        perception: ``camera[:MODEL]``: the site from the endoscope's images (``evaluate --perception``).
        texture: The flap's texture image file.
        calibrated_error_n: A calibration file's error bound [N]: the sensing is a calibrated dVRK whose force is
            off by at most that much (:func:`sim.force_sensing.calibrated_sensing`); None: the preset's.
    """
    params = {str(k): float(v) for k, v in trial["params"].items()}
    env = _environment(
        task, safety, safety_config, force_sensing, tissue_ranges, perception, texture, calibrated_error_n
    )
    policy_key = ("policy", policy, id(env))
    if policy_key not in _CACHE:
        _CACHE[policy_key] = resolve_policy(policy, env, allow_other_task=allow_other_task)
    policy_fn, policy_reset = _CACHE[policy_key]
    observation_disturbances, action_disturbances = disturbances(params)
    wrapped = DisturbanceWrapper(env, observation=observation_disturbances, action=action_disturbances)
    options = episode_options(params, relative)
    result = run_episode(wrapped, policy_fn, policy_reset, int(trial["seed"]), options=options)
    outcome = result.to_dict()
    outcome.pop("seed", None)
    outcome["interventions"] = {"total": int(result.interventions), **outcome.pop("intervention_kinds")}
    outcome["options"] = options
    # The flap's stiffness as drawn, swept or not: the report's table by fifth of it (sim.stiffness_fifths).
    outcome[STIFFNESS_KEY] = float(env.unwrapped.values[STIFFNESS_KEY])
    # What the filter trusted the force to (the preset's bound, or a calibration file's).
    outcome["force_sensing_error_n"] = float(env.unwrapped.safety_config.force_sensing_error_n)
    return outcome


def tuning_episode(
    trial: Mapping[str, Any],
    *,
    policy: str,
    task: str,
    base_config: Mapping[str, Any] | None = None,
    allow_other_task: bool = False,
    force_sensing: str = "ideal",
    calibrated_error_n: float | None = None,
) -> dict[str, Any]:
    """One episode of the policy under the trial's safety settings (``calibrated_error_n``: as
    :func:`robustness_episode`)."""
    overrides = {**dict(base_config or {}), **integer_settings(trial["params"])}
    return robustness_episode(
        {**trial, "params": {}},
        policy=policy,
        task=task,
        relative={},
        safety_config=overrides,
        allow_other_task=allow_other_task,
        force_sensing=force_sensing,
        calibrated_error_n=calibrated_error_n,
    )
