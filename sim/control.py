"""The one place the simulation gets its controller from: the project's control chain.

Actions reach the simulated joints only through :class:`safety.chain.ControlChain` (IK -> QP safety
filter -> Ruckig -> verifier), the same object the ROS 2 interface drives on the robot. ``safety=False``
skips the filter and the verifier's limits: an ablation, announced loudly on stderr.
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np

from psm_control.robot import PsmConfiguration
from safety.chain import ControlChain
from safety.config import SafetyConfig

__all__ = ["make_controller"]


def make_controller(
    configuration: PsmConfiguration,
    *,
    safety: bool = True,
    control_period_s: float,
    config: SafetyConfig | None = None,
) -> tuple[ControlChain, str]:
    """Build the control chain the environment drives the arm with.

    The chain works in the RCM frame (its workspace box and insertion rule are about the RCM): the
    scene's RCM is axis-aligned with the world, so base-frame deltas and forces keep their world meaning.

    Args:
        configuration: Robot state object of the arm (its base frame places the RCM in the world).
        safety: Run the safety filter and verifier (False is an ablation).
        control_period_s: Tick period [s]; it overrides ``config.control_rate_hz``, because the
            simulation ticks the chain between whole physics substeps.
        config: Safety configuration (limits, force limit); None: :class:`SafetyConfig` defaults.

    Returns:
        The chain and a one-line description of it (recorded in ``info["controller"]``).
    """
    spec = configuration.model.spec
    if not np.allclose(configuration.base_frame[:3, :3], np.eye(3)):
        raise ValueError("the scene's RCM frame must be axis-aligned with the world")
    base = config if config is not None else SafetyConfig(arm=spec.arm, tool=spec.tool)
    chain_config = dataclasses.replace(base, control_rate_hz=1.0 / control_period_s)
    if not safety:
        print(
            "ABLATION: simulation running WITHOUT the safety filter and verifier (safety=False); "
            "never a result to deploy",
            file=sys.stderr,
        )
    chain = ControlChain(chain_config, safety=safety)
    force = chain_config.effective_force_limit_n
    rate = chain_config.control_rate_hz
    if safety:
        return chain, f"ControlChain (safety filter on, {rate:g} Hz, force limit {force:g} N)"
    return chain, f"ControlChain (ABLATION: safety filter OFF, {rate:g} Hz)"
