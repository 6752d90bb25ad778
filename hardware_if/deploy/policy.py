"""The deploy's policy: resolved by name, and each of its steps checked before the chain acts on it."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from hardware_if.common.errors import HoldError
from hardware_if.deploy.options import DeployOptions
from policies.resolve import resolve_policy
from policies.shipped import CAMERA, PRETRAINED, pretrained_path, variant_of

__all__ = ["checked_policy", "policy_for"]


def policy_for(options: DeployOptions, env: Any, echo: Any) -> tuple[Any, Any]:
    """The deploy's policy; for ``pretrained``, says which shipped file fits what the run observes.

    A network policy runs on one thread: a step is one small forward pass, and torch's second thread only
    adds a hand-over that a busy core turns into a wait (on the 2-core machine with two busy processes, the
    shipped Lift policy's step p99/max: 4.1/17.6 ms on two threads, 0.09/4.3 ms on one).
    """
    resolved = resolve_policy(options.policy, env)
    torch = sys.modules.get("torch")  # imported by the resolver only for a network policy
    if torch is not None:
        torch.set_num_threads(1)
    if options.policy == PRETRAINED:
        path, variant = pretrained_path(env), variant_of(env)
        trained_on = "the camera's site" if variant == CAMERA else f"{variant} force sensing"
        echo(f"policy: the shipped one trained on {trained_on} ({path.parent.name}/{path.name})")
    return resolved


def checked_policy(policy: Callable[[Any], Any], budget_s: float) -> Callable[[Any], np.ndarray]:
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
