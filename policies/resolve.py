"""Loading a policy by name: the one resolver behind evaluate, deploy, sweeps and tuning.

A policy name is ``scripted`` (the rule-based expert), ``random``, ``pretrained`` (the shipped policy of the
environment's task, for its force sensing and where its site comes from), ``module:callable`` or a
checkpoint path.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from policies.shipped import PRETRAINED, pretrained_claim, pretrained_path
from psm_control.errors import ConfigurationError
from sim.evaluation import Policy

__all__ = ["POLICY_NAMES", "names_a_checkpoint", "resolve_policy"]

#: What ``--policy`` accepts, for help texts and error messages.
POLICY_NAMES = "scripted, random, pretrained, module:callable or a checkpoint path"

_CHECKPOINT_SUFFIXES = (".pt", ".safetensors", ".zip")


def _no_reset() -> None:
    """The per-episode reset of a stateless policy."""


def _reset_of(policy: Any) -> Callable[[], None]:
    reset = getattr(policy, "reset", None)
    return reset if callable(reset) else _no_reset


def names_a_checkpoint(spec: str) -> bool:
    """Whether ``--policy`` names a checkpoint file: not one of the policies by name nor ``module:callable``."""
    if spec in ("scripted", "random", PRETRAINED):
        return False
    return not (":" in spec and not spec.endswith(_CHECKPOINT_SUFFIXES))


def resolve_policy(spec: str, env: Any, *, allow_other_task: bool = False) -> tuple[Policy, Callable[[], None]]:
    """A policy and its per-episode reset from its name (see the module docstring).

    ``module:callable`` names a function of the observation dict, or a class built with the environment
    (``cls(env)``, as :class:`sim.pulling.AggressivePull`); a ``reset()`` method is called per episode.
    A checkpoint trained for another task is refused unless ``allow_other_task``.

    Raises:
        ConfigurationError: The policy cannot be found.
        CheckpointError: The checkpoint file is not a valid checkpoint or does not fit the environment.
    """
    if spec == "scripted":
        from sim.expert import ScriptedExpert  # the environments (PyBullet): not for a command's --help

        expert = ScriptedExpert(env)
        return expert, expert.reset
    if spec == "random":
        env.action_space.seed(0)  # gymnasium leaves it unseeded: the same episodes then draw the same actions
        return (lambda _obs: env.action_space.sample()), _no_reset
    if spec == PRETRAINED:
        # A shipped policy may have been trained on a task of the same spaces that includes this one's episodes.
        claim = pretrained_claim(env)
        allow_other_task = allow_other_task or claim.trained_on_task != claim.task_id
        spec = str(pretrained_path(env))
    if not names_a_checkpoint(spec):
        module_name, _, attribute = spec.partition(":")
        try:
            target = getattr(importlib.import_module(module_name), attribute)
        except KeyboardInterrupt:
            raise
        except BaseException as e:
            raise ConfigurationError(
                "--policy", spec, f"an importable module:callable ({type(e).__name__}: {e})"
            ) from e
        if isinstance(target, type):  # a policy class is built with the environment, as ScriptedExpert(env)
            try:
                target = target(env)
            except KeyboardInterrupt:
                raise
            except BaseException as e:
                raise ConfigurationError(
                    "--policy", spec, f"a class built as cls(env) ({type(e).__name__}: {e})"
                ) from e
        if not callable(target):
            raise ConfigurationError("--policy", spec, "a callable taking the observation dict")
        return target, _reset_of(target)
    # Imported here: torch takes about a second to import, which scripted and module:callable policies
    # (the fault matrix's, a user's) and every command's input errors need not wait for.
    from policies.checkpoint import load_policy

    policy = load_policy(spec, env, allow_other_task=allow_other_task)
    return policy, _reset_of(policy)
