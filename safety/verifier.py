"""The last check before a command leaves the chain: hard limits, or hold the last safe command.

Defence in depth: whatever the stages before it did, every outgoing command is checked here against the
hard joint limits, the minimum insertion, the workspace box (with its tolerance) and the velocity and
acceleration limits. A command that fails any check is replaced by the last command that passed, at rest,
and the stop is recorded. Nothing here uses ``assert``: checks are plain comparisons that survive ``-O``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from psm_control.commands import JointCommand
from psm_control.frames import BaseTransform
from psm_control.reductions import all_of
from psm_control.robot import PsmConfiguration
from safety.config import SafetyConfig

__all__ = ["CommandVerifier", "Verdict"]

_NAMES = ("yaw", "pitch", "insertion", "roll", "wrist_pitch", "wrist_yaw")


class Verdict(NamedTuple):
    """The verifier's decision on one command.

    Attributes:
        command: What to send: the candidate, or the held last safe command.
        ok: Whether the candidate passed.
        reason: Which check failed, with the value and the bound ("" when it passed).
    """

    command: JointCommand
    ok: bool
    reason: str


class CommandVerifier:
    """Check commands against the hard limits and hold the last safe one.

    Args:
        config: The safety configuration (limits, workspace box and tolerance).
        configuration: The robot state whose model (and base frame) the verifier's own kinematics use.
        tolerance: Numerical slack on joint, velocity and acceleration checks.
    """

    def __init__(self, config: SafetyConfig, configuration: PsmConfiguration, tolerance: float = 1e-9) -> None:
        self.lower = config.spec.lower
        self.upper = config.spec.upper
        self.min_insertion_m = config.spec.rcm.min_insertion_m
        self.velocity = config.velocity * (1.0 + 1e-6) + tolerance
        self.acceleration = config.acceleration * (1.0 + 1e-6) + tolerance
        self.box_lower = np.asarray(config.workspace_min_m) - config.workspace_tolerance_m
        self.box_upper = np.asarray(config.workspace_max_m) + config.workspace_tolerance_m
        self.tolerance = tolerance
        self._model = configuration.model.model
        self._data = self._model.createData()
        self._q_full = np.zeros(self._model.nq)
        self._tip = configuration.model.frame_ids.tool_tip
        self._transform = BaseTransform(configuration.base_frame)
        self._box_center = (self.box_lower + self.box_upper) / 2.0
        self._box_half = (self.box_upper - self.box_lower) / 2.0
        self.last_safe: JointCommand | None = None
        self.stops = 0
        # One comparison checks every joint's position, velocity and acceleration (and finiteness: NaN
        # fails it); only a command that fails it goes through the per-check path that names the cause.
        lower = self.lower.copy()
        lower[2] = max(lower[2], self.min_insertion_m)
        self._center = np.concatenate([(lower + self.upper) / 2.0, np.zeros(2 * lower.size)])
        self._half_width = np.concatenate([(self.upper - lower) / 2.0 + tolerance, self.velocity, self.acceleration])
        self._joints = np.empty(self._center.size)

    def set_base_frame(self, transform_rcm_to_base: np.ndarray) -> None:
        """Use a new base frame (4x4 pose of the RCM) for the workspace check."""
        self._transform = BaseTransform(transform_rcm_to_base)

    def reset(self, command: JointCommand) -> None:
        """Accept ``command`` as the safe command to hold (the measured state at reset)."""
        self.last_safe = command

    def hold(self, stamp_s: float) -> JointCommand:
        """The last safe command, at rest, stamped for now."""
        if self.last_safe is None:
            raise RuntimeError("CommandVerifier.hold called before reset")
        zeros = np.zeros_like(self.last_safe.q)
        return JointCommand(self.last_safe.q.copy(), zeros, zeros.copy(), self.last_safe.jaw, stamp_s)

    def problem(self, command: JointCommand) -> str:
        """Return what is wrong with ``command`` ("" if nothing)."""
        q, qd, qdd = command.q, command.qd, command.qdd
        try:
            joints = self._joints
            np.concatenate((q, qd, qdd), out=joints)
            joints -= self._center
            np.abs(joints, out=joints)
            joints_ok = bool(all_of(joints <= self._half_width))
        except (ValueError, TypeError):  # wrong shapes or types: the detailed checks say which
            joints_ok = False
        try:
            jaw_ok = math.isfinite(command.jaw)
        except (TypeError, ValueError):
            jaw_ok = False
        if joints_ok and jaw_ok:
            return self._workspace_problem(q)
        for name, vector in (("q", q), ("qd", qd), ("qdd", qdd)):
            if vector.shape != self.lower.shape or not np.all(np.isfinite(vector)):
                return f"{name} is not a finite vector of {self.lower.size}"
        if not np.isfinite(command.jaw):
            return "jaw is not finite"
        low = q < self.lower - self.tolerance
        high = q > self.upper + self.tolerance
        if np.any(low | high):
            i = int(np.argmax(low | high))
            bound = self.lower[i] if low[i] else self.upper[i]
            return f"joint {_NAMES[i]} position {q[i]:.6g} beyond limit {bound:.6g}"
        if q[2] < self.min_insertion_m - self.tolerance:
            return f"insertion {q[2]:.6g} m below the RCM minimum {self.min_insertion_m} m"
        fast = np.abs(qd) > self.velocity
        if np.any(fast):
            i = int(np.argmax(fast))
            return f"joint {_NAMES[i]} velocity {qd[i]:.6g} beyond limit {self.velocity[i]:.6g}"
        hard = np.abs(qdd) > self.acceleration
        if np.any(hard):
            i = int(np.argmax(hard))
            return f"joint {_NAMES[i]} acceleration {qdd[i]:.6g} beyond limit {self.acceleration[i]:.6g}"
        return self._workspace_problem(q)

    def _workspace_problem(self, q: np.ndarray) -> str:
        self._q_full[: q.size] = q
        pin.forwardKinematics(self._model, self._data, self._q_full)
        tip = self._transform.point(pin.updateFramePlacement(self._model, self._data, self._tip).translation)
        offset = tip - self._box_center
        np.abs(offset, out=offset)
        if all_of(offset <= self._box_half):
            return ""
        outside = (tip < self.box_lower) | (tip > self.box_upper)
        if np.any(outside):
            i = int(np.argmax(outside))
            return f"tool tip {'xyz'[i]}={tip[i]:.6g} m outside the workspace box"
        return ""

    def verify(self, candidate: JointCommand) -> Verdict:
        """Pass ``candidate`` if it meets every hard limit, else hold the last safe command."""
        reason = self.problem(candidate)
        if not reason:
            self.last_safe = candidate
            return Verdict(candidate, True, "")
        self.stops += 1
        return Verdict(self.hold(candidate.stamp_s), False, "verifier: " + reason)
