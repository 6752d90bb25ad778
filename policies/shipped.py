"""The policies shipped with the package, one per task and variant, with the claims made for them.

``policies/pretrained/<task id>.safetensors`` holds a deterministic actor written by this project's own
``tissue-retract train`` (the exact command is in the checkpoint's metadata and in the sidecar
``<task id>.json``, with the evaluation that backs the claimed success rate). ``--policy pretrained``
selects the shipped policy of the task being run, in the variant that fits what the run observes:

* **by force sensing.** The tissue force is part of a policy's observation, and a policy trained on the
  exact force fails on the force a dVRK senses (its console's estimate is off by newtons in free space, tens
  uncalibrated: measured, 0 of 20 Lift episodes with either dVRK preset). The policies trained on the exact
  force are at the top of ``policies/pretrained/``, the ones trained on a preset's sensed force
  (:mod:`sim.force_sensing`) in ``policies/pretrained/<preset>/``.
* **by where the site comes from.** A policy trained on the true site grasps where the site is; one
  trained on the endoscope's estimate of it (``train --perception camera``) learns to grasp where the jaws
  find the flap, a few millimetres from the estimate. With the exact force and the camera's site
  (``--perception camera``), ``--policy pretrained`` takes ``policies/pretrained/camera/``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from psm_control.errors import UnknownVariantError

__all__ = [
    "CAMERA",
    "PRETRAINED",
    "ShippedClaim",
    "force_sensing_of",
    "policy_file",
    "pretrained_claim",
    "pretrained_path",
    "shipped_claim",
    "shipped_policy_path",
    "shipped_tasks",
    "variant_for",
    "variant_of",
]

#: The policy name that selects the shipped policy of a task.
PRETRAINED = "pretrained"
#: The variant at the top of ``policies/pretrained/``: the exact force and the true site.
EXACT_SENSING = "ideal"
#: The variant trained on the exact force and the site estimator's site.
CAMERA = "camera"


def _directory(variant: str = EXACT_SENSING) -> Path:
    top = Path(str(resources.files("policies") / "pretrained"))
    return top if variant == EXACT_SENSING else top / variant


def force_sensing_of(env: Any) -> str:
    """The force sensing an environment's observation carries (``ideal`` for one that does not say)."""
    return str(getattr(env.unwrapped, "force_sensing", EXACT_SENSING))


def _sees_site_through_camera(env: Any) -> bool:
    """Some layer of the environment takes the site from the endoscope (``PerceivedTask.site_from_camera``)."""
    layer = env
    while layer is not None:
        if getattr(type(layer), "site_from_camera", False):  # on the class: a wrapper forwards nothing
            return True
        layer = vars(layer).get("env")
    return False


def variant_for(force_sensing: str, site_from_camera: bool) -> str:
    """The shipped variant for a run's force sensing and where its site comes from."""
    return CAMERA if force_sensing == EXACT_SENSING and site_from_camera else force_sensing


def variant_of(env: Any) -> str:
    """The shipped variant for what an environment observes: its force sensing, or ``camera``."""
    return variant_for(force_sensing_of(env), _sees_site_through_camera(env))


def _shipped_file(task_id: str, variant: str) -> Path:
    """Where a task's shipped policy of a variant lives (whether or not it exists)."""
    return _directory(variant) / f"{task_id}.safetensors"


def shipped_tasks(variant: str = EXACT_SENSING) -> tuple[str, ...]:
    """Task ids that have a shipped policy in a variant."""
    return tuple(sorted(path.stem for path in _directory(variant).glob("*.safetensors")))


def shipped_policy_path(task_id: str, variant: str = EXACT_SENSING) -> Path:
    """The shipped policy file of a task in a variant (a force sensing, or ``camera``).

    Raises:
        UnknownVariantError: No policy is shipped for that task and variant (the ones that are are listed).
    """
    path = _shipped_file(task_id, variant)
    if not path.exists():
        suffix = "" if variant == EXACT_SENSING else f" ({variant})"
        raise UnknownVariantError(f"pretrained policy for task{suffix}", task_id, shipped_tasks(variant))
    return path


def pretrained_path(env: Any) -> Path:
    """The shipped policy ``--policy pretrained`` loads for an environment: its task's, in its variant.

    Raises:
        UnknownVariantError: No policy is shipped for that task and variant.
    """
    return shipped_policy_path(_task_id(env), variant_of(env))


def pretrained_claim(env: Any) -> ShippedClaim:
    """The claim beside the shipped policy ``--policy pretrained`` loads for an environment."""
    return shipped_claim(_task_id(env), variant_of(env))


def _task_id(env: Any) -> str:
    return str(env.spec.id if env.spec is not None else type(env.unwrapped).__name__)


def policy_file(policy: str, task_id: str, variant: str = EXACT_SENSING) -> Path | None:
    """The file a ``--policy`` name loads: the shipped policy for ``pretrained``, else the path if it is a file.

    None for policies that are code (``scripted``, ``random``, ``module:callable``) or a missing shipped file.
    """
    if policy == PRETRAINED:
        path = _shipped_file(task_id, variant)
        return path if path.is_file() else None
    return Path(policy) if Path(policy).is_file() else None


@dataclass(frozen=True)
class ShippedClaim:
    """What a shipped policy's evaluation showed.

    Attributes:
        task_id: The task.
        trained_on_task: The task whose episodes trained it: ``task_id``, or one with the same spaces whose
            episodes include this task's (Task III's three sites include Task II's centre one), where that
            policy did better (its sidecar's ``trained_on_task``).
        train_command: The command that produced the weights.
        evaluate_command: The command that measured the claim.
        episodes: Evaluation episodes.
        success_rate: Observed success rate.
        ci95: 95 % Wilson interval of the success rate.
    """

    task_id: str
    trained_on_task: str
    train_command: str
    evaluate_command: str
    episodes: int
    success_rate: float
    ci95: tuple[float, float]


def shipped_claim(task_id: str, variant: str = EXACT_SENSING) -> ShippedClaim:
    """The claim recorded beside a shipped policy."""
    data = json.loads(shipped_policy_path(task_id, variant).with_suffix(".json").read_text())
    return ShippedClaim(
        task_id=task_id,
        trained_on_task=str(data.get("trained_on_task", task_id)),
        train_command=str(data["train_command"]),
        evaluate_command=str(data["evaluate_command"]),
        episodes=int(data["episodes"]),
        success_rate=float(data["success_rate"]),
        ci95=(float(data["ci95"][0]), float(data["ci95"][1])),
    )
