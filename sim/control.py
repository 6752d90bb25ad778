"""The one place the simulation gets its controller from.

Actions reach the simulated joints only through a :class:`~psm_control.commands.Controller`. Until the
project's control chain (``safety.chain.ControlChain``) is available this returns the interim
differential-IK controller, which has no safety filter, and says so.
"""

from __future__ import annotations

import importlib.util
import warnings

from psm_control.commands import Controller
from psm_control.robot import PsmConfiguration

__all__ = ["make_controller"]


def make_controller(
    configuration: PsmConfiguration, *, safety: bool = True, control_period_s: float = 1 / 240
) -> tuple[Controller, str]:
    """Build the controller the environment drives the arm with.

    Args:
        configuration: Robot state object, with the RCM placed by its base frame.
        safety: Run the safety filter (False is an ablation).
        control_period_s: Tick period [s].

    Returns:
        The controller and a one-line description of what it is (recorded in ``info``).
    """
    from sim.interim_controller import InterimIkController

    if safety and importlib.util.find_spec("safety.chain") is None:
        warnings.warn(
            "safety.chain is not available: running the interim IK controller without a safety filter",
            RuntimeWarning,
            stacklevel=2,
        )
    return InterimIkController(configuration, control_period_s), "interim-dls-ik (no safety filter)"
