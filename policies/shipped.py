"""The policies shipped with the package, one per task, with the claims made for them.

``policies/pretrained/<task id>.safetensors`` holds a deterministic actor written by this project's own
``tissue-retract train`` (the exact command is in the checkpoint's metadata and in the sidecar
``<task id>.json``, with the evaluation that backs the claimed success rate). ``--policy pretrained``
selects the shipped policy of the task being run.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from psm_control.errors import UnknownVariantError

__all__ = ["PRETRAINED", "ShippedClaim", "policy_file", "shipped_claim", "shipped_policy_path", "shipped_tasks"]

#: The policy name that selects the shipped policy of a task.
PRETRAINED = "pretrained"


def _directory() -> Path:
    return Path(str(resources.files("policies") / "pretrained"))


def shipped_tasks() -> tuple[str, ...]:
    """Task ids that have a shipped policy."""
    return tuple(sorted(path.stem for path in _directory().glob("*.safetensors")))


def shipped_policy_path(task_id: str) -> Path:
    """The shipped policy file of a task.

    Raises:
        UnknownVariantError: No policy is shipped for that task (the ones that are are listed).
    """
    path = _directory() / f"{task_id}.safetensors"
    if not path.exists():
        raise UnknownVariantError("pretrained policy for task", task_id, shipped_tasks())
    return path


def policy_file(policy: str, task_id: str) -> Path | None:
    """The file a ``--policy`` name loads: the shipped policy for ``pretrained``, else the path if it is a file.

    None for policies that are code (``scripted``, ``random``, ``module:callable``) or a missing shipped file.
    """
    if policy == PRETRAINED:
        path = _directory() / f"{task_id}.safetensors"
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


def shipped_claim(task_id: str) -> ShippedClaim:
    """The claim recorded beside a shipped policy."""
    data = json.loads(shipped_policy_path(task_id).with_suffix(".json").read_text())
    return ShippedClaim(
        task_id=task_id,
        train_command=str(data["train_command"]),
        evaluate_command=str(data["evaluate_command"]),
        episodes=int(data["episodes"]),
        success_rate=float(data["success_rate"]),
        ci95=(float(data["ci95"][0]), float(data["ci95"][1])),
    )
