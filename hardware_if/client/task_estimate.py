"""The task state without a camera: a registered site, a goal, and a grasp sensed by the jaw.

A policy reads the grasp site, the goal, the achieved goal and whether the jaw holds the tissue. On a
robot with no perception stack these follow from one registration and the console's own topics:

- the site: where the operator held the tool on it once (``tissue-retract register``, or ``--site``);
- the goal: given (``--goal``), or the task's nominal goal relative to the site
  (:func:`sim.envs.nominal_goal`);
- grasped: a jaw closing on tissue stalls open. While the set-point asks for a closed jaw (below
  :attr:`JawGraspSensing.closing_below_rad`) the measured angle stays at least ``margin_rad`` above the
  set-point and the jaw has stopped (slower than ``still_rad_per_s``). A jaw that closed on nothing
  reaches its set-point; tissue slipping out lets it close, which ends the grasp;
- the achieved goal and the site while grasped: the held tissue point moves with the jaws, so both are the
  registered site plus how far the grasp point (midway along the jaws, by kinematics) moved since the grasp
  began. When the jaw opens the flap recoils and the site is the registered one again.

:class:`TaskEstimate` is plain NumPy, fed one :class:`JawReading` and grasp point per policy step, so the
same estimator runs over ROS (:class:`hardware_if.client.remote_task.RemoteTask`) and in the simulation
(:class:`hardware_if.client.registered_env.RegisteredTask`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from psm_control.errors import ConfigurationError

__all__ = ["JawGraspSensing", "JawReading", "TaskEstimate", "as_point", "format_point"]


class JawReading(NamedTuple):
    """The jaw as the console reports it.

    Attributes:
        measured_rad: ``jaw/measured_js`` position [rad].
        velocity_rad_per_s: ``jaw/measured_js`` velocity [rad/s].
        setpoint_rad: ``jaw/setpoint_js`` position [rad].
    """

    measured_rad: float
    velocity_rad_per_s: float
    setpoint_rad: float


@dataclass(frozen=True)
class JawGraspSensing:
    """When a jaw reading means "holding tissue".

    Attributes:
        closing_below_rad: The set-point asks for a closed jaw below this angle [rad] (the simulation's
            grasp closes below 0.15 rad).
        margin_rad: The measured angle stays at least this far above the set-point: something is between
            the jaws [rad]. Above the position noise of a jaw servo, below the stall on a 1 mm flap.
        still_rad_per_s: The jaw has stopped when slower than this [rad/s]; a closing jaw moves at up to
            the dVRK's 18.8 rad/s.
    """

    closing_below_rad: float = 0.15
    margin_rad: float = 0.05
    still_rad_per_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("margin_rad", "still_rad_per_s"):
            if not getattr(self, name) > 0:
                raise ConfigurationError(name, getattr(self, name), "a positive number")

    def holding(self, jaw: JawReading) -> bool:
        """Whether the reading shows a jaw stalled on tissue."""
        return bool(
            jaw.setpoint_rad < self.closing_below_rad
            and jaw.measured_rad >= jaw.setpoint_rad + self.margin_rad
            and abs(jaw.velocity_rad_per_s) < self.still_rad_per_s
        )


def as_point(value: object, name: str) -> np.ndarray:
    """A finite 3-vector [m], or a :class:`ConfigurationError` naming ``name``."""
    try:
        point = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        point = np.full(1, np.nan)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ConfigurationError(name, value, "three finite coordinates X Y Z [m] in <arm>_base")
    return point


def format_point(point: np.ndarray) -> str:
    """A point as ``X Y Z`` in metres (to 0.01 mm), as ``--site`` and ``--goal`` take it."""
    return " ".join(f"{v:.5f}" for v in point)


class TaskEstimate:
    """The task's site, goal, achieved goal and grasp from a registration and the arm's own state.

    Args:
        site: The registered grasp site [m] in ``<arm>_base``.
        goal: Where the site must go [m] in ``<arm>_base``.
        sensing: When the jaw holds tissue.
    """

    def __init__(self, site: np.ndarray, goal: np.ndarray, sensing: JawGraspSensing | None = None) -> None:
        self.registered_site = as_point(site, "site")
        self.goal = as_point(goal, "goal")
        self.sensing = sensing or JawGraspSensing()
        self._grasp_start: np.ndarray | None = None
        self._moved = np.zeros(3)

    @property
    def grasped(self) -> bool:
        """The jaw holds the tissue (as of the last :meth:`update`)."""
        return self._grasp_start is not None

    @property
    def site(self) -> np.ndarray:
        """The grasp site now [m]: registered, moved with the jaws while they hold it."""
        return self.registered_site + self._moved

    @property
    def achieved_goal(self) -> np.ndarray:
        """The task's achieved goal [m]: the site, where the held tissue point is now."""
        return self.site

    def reset(self) -> None:
        """A new episode: nothing held."""
        self._grasp_start, self._moved = None, np.zeros(3)

    def update(self, jaw: JawReading, grasp_position: np.ndarray) -> None:
        """Take one reading of the jaw and the grasp point (midway along the jaws) [m] in ``<arm>_base``."""
        point = np.asarray(grasp_position, dtype=float)
        if not self.sensing.holding(jaw):
            self.reset()
            return
        if self._grasp_start is None:
            self._grasp_start = point.copy()
        self._moved = point - self._grasp_start
