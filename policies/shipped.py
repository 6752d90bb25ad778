"""The policies shipped with the package, one per task, with the claims made for them.

``policies/pretrained/<task id>.safetensors`` holds a deterministic actor written by this project's own
``tissue-retract train`` (the exact command is in the checkpoint's metadata and in the sidecar
``<task id>.json``, with the evaluation that backs the claimed success rate). ``--policy pretrained``
selects the shipped policy of the task being run.

The tissue force is part of a policy's observation, and a policy trained on the exact force fails on the
force a dVRK senses (its console's estimate is off by about a newton in free space: measured, 0 of 100
episodes). So a policy is shipped per force sensing (:mod:`sim.force_sensing`): the ones trained on the exact
force at the top of ``policies/pretrained/``, the ones trained on a preset's sensed force in
``policies/pretrained/<preset>/``. ``--policy pretrained`` takes the one of the run's force sensing.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from psm_control.errors import UnknownVariantError

__all__ = [
    "PRETRAINED",
    "ShippedClaim",
    "force_sensing_of",
    "policy_file",
    "pretrained_path",
    "shipped_claim",
    "shipped_policy_path",
    "shipped_tasks",
]

#: The policy name that selects the shipped policy of a task.
PRETRAINED = "pretrained"
#: The force sensing of the policies at the top of ``policies/pretrained/``.
EXACT_SENSING = "ideal"


def _directory(force_sensing: str = EXACT_SENSING) -> Path:
    top = Path(str(resources.files("policies") / "pretrained"))
    return top if force_sensing == EXACT_SENSING else top / force_sensing


def force_sensing_of(env: Any) -> str:
    """The force sensing an environment's observation carries (``ideal`` for one that does not say)."""
    return str(getattr(env.unwrapped, "force_sensing", EXACT_SENSING))


def shipped_tasks(force_sensing: str = EXACT_SENSING) -> tuple[str, ...]:
    """Task ids that have a shipped policy for a force sensing."""
    return tuple(sorted(path.stem for path in _directory(force_sensing).glob("*.safetensors")))


def shipped_policy_path(task_id: str, force_sensing: str = EXACT_SENSING) -> Path:
    """The shipped policy file of a task, trained on a force sensing's force.

    Raises:
        UnknownVariantError: No policy is shipped for that task and sensing (the ones that are are listed).
    """
    path = _directory(force_sensing) / f"{task_id}.safetensors"
    if not path.exists():
        sensing = "" if force_sensing == EXACT_SENSING else f" with {force_sensing} sensing"
        what = f"pretrained policy for task{sensing}"
        raise UnknownVariantError(what, task_id, shipped_tasks(force_sensing))
    return path


def pretrained_path(env: Any) -> Path:
    """The shipped policy ``--policy pretrained`` loads for an environment: its task's, for its force sensing.

    Raises:
        UnknownVariantError: No policy is shipped for that task and sensing.
    """
    task_id = env.spec.id if env.spec is not None else type(env.unwrapped).__name__
    return shipped_policy_path(task_id, force_sensing_of(env))


def policy_file(policy: str, task_id: str, force_sensing: str = EXACT_SENSING) -> Path | None:
    """The file a ``--policy`` name loads: the shipped policy for ``pretrained``, else the path if it is a file.

    None for policies that are code (``scripted``, ``random``, ``module:callable``) or a missing shipped file.
    """
    if policy == PRETRAINED:
        path = _directory(force_sensing) / f"{task_id}.safetensors"
        return path if path.is_file() else None
    return Path(policy) if Path(policy).is_file() else None


@dataclass(frozen=True)
class ShippedClaim:
    """What a shipped policy's evaluation showed.

    Attributes:
        task_id: The task.
        train_command: The command that produced the weights.
        evaluate_command: The command that measured the claim.
        episodes: Evaluation episodes.
        success_rate: Observed success rate.
        ci95: 95 % Wilson interval of the success rate.
    """

    task_id: str
    train_command: str
    evaluate_command: str
    episodes: int
    success_rate: float
    ci95: tuple[float, float]


def shipped_claim(task_id: str, force_sensing: str = EXACT_SENSING) -> ShippedClaim:
    """The claim recorded beside a shipped policy."""
    data = json.loads(shipped_policy_path(task_id, force_sensing).with_suffix(".json").read_text())
    return ShippedClaim(
        task_id=task_id,
        train_command=str(data["train_command"]),
        evaluate_command=str(data["evaluate_command"]),
        episodes=int(data["episodes"]),
        success_rate=float(data["success_rate"]),
        ci95=(float(data["ci95"][0]), float(data["ci95"][1])),
    )
