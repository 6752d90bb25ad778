"""The scripted expert: the paper's rule-based demonstrator (approach, grasp, retract, hold).

It reads privileged simulator state (the site and the jaw's grasp point) and returns actions in the
environment's action box, so its demonstrations replay through the same control chain as a policy's.

``observed=True`` makes it act on what a robot observes where the environment is wrapped in one's view
(``evaluate --blind``, ``--perception camera``: the wrapper's ``estimate``, a registered or camera-estimated
site that moves with the jaws once they are sensed holding): it carries the *observed* site to the goal.
Demonstrations for a learner that observes the estimate come from it. A privileged expert instead carries
the true site there, so where it stops in the learner's observation is the goal plus the estimate's error,
which the learner cannot see: cloning it teaches the learner to stop anywhere within that error of the goal,
and its own error then adds to the estimate's (measured with a Task III camera policy cloned from the
privileged expert: 13 of 100 episodes ended out of the goal radius, 6 of them with even the observed site
outside it).

``lag_blind=True`` makes it approach and carry without knowing the actions still in flight, for the same
reason. The expert aims each action from where the tool will be once the environment's pending actions
have landed (``env._pending``, the action latency, which the learner does not observe); cloned over a sweep
whose latency is 0-3 steps, its policy cannot tell how much to hold back and fails where the lag is longest
(the Task III policy shipped before: 30 % of the 400-trial sweep's trials at 3 steps, at most 13 % at
fewer). Lag-blind, each action covers :data:`LAG_BLIND_GAIN` of the way to its target, a step small enough
that three in flight do not overshoot. The descent to the grasp point stays as it is: its few millimetres,
crept at a quarter per step under the observation's noise, taught a clone to close its jaws off the site.
Over the first 100 trials of the sweep (``robustness --task T --trials 100 --vary stiffness=0.3:3x,
size=0.8:1.2x,obs_noise=0:0.002,latency=0:3,friction=0.7:1.3x``), Task III unless named:

* the expert lag-blind in every phase: 97 successes at gains 0.2 and 0.25, 96 at 0.3, 71 at 0.5 (2 of 29
  at 3 steps); its clone (``train --robust``, seed 1) 92, on Lift 92 (7 improper grasps);
* lag-blind approaching and carrying only, at 0.25: the expert 98 (Lift 100), its clone 98, on Lift 100
  and on Task II 100;
* the lag-aware expert 97 (Lift 100); the policy cloned from it and shipped before, 86 (Lift 99).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from sim.envs.base import TissueRetractEnv
from sim.envs.expose import ExposeEnv

__all__ = ["LAG_BLIND_GAIN", "ScriptedExpert"]

_HOVER_M = 0.008
_NEAR_M = 0.0015
_RETRACT_OFFSET_M = np.array([0.0, -0.02, 0.035])  # up and back towards the pinned edge (Expose task)
#: The Expose task's retraction stops this far past the exposure target (a margin for the flap's sway).
_EXPOSURE_MARGIN = 0.1
# Fraction of a step's goal the control chain covers within the step, from rest or in steady motion.
_TRACKED_FRACTION = 0.5
#: The share of the way to its target a lag-blind expert's action covers (see the module notes).
LAG_BLIND_GAIN = 0.25
#: The phases a lag-blind expert moves in lag-blind: approaching the site and carrying it.
_LAG_BLIND_PHASES = frozenset({"approach", "retract", "hold"})


class ScriptedExpert:
    """Approach above the site, descend, close the jaw, carry the site to the goal and hold it.

    Args:
        env: The environment (wrappers are looked through).
        observed: Act on the site and grasp of the first wrapper that carries an ``estimate`` (see the module
            notes); on the truth where none does.
        lag_blind: Move without knowing the actions still in flight (see the module notes).
    """

    def __init__(self, env: Any, *, observed: bool = False, lag_blind: bool = False) -> None:
        self.env: TissueRetractEnv = env.unwrapped
        self._view = _estimating_wrapper(env) if observed else None
        self.lag_blind = lag_blind
        self.phase = "approach"
        self._waited = 0
        self._start_site: np.ndarray | None = None

    def reset(self) -> None:
        """Start a new episode."""
        self.phase = "approach"
        self._waited = 0
        self._start_site = None

    def __call__(self, observation: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """The action for the current state (read from the simulation or its view, not the observation)."""
        env = self.env
        grasp, site, holding = env.grasp_position(), *self._site_and_holding()
        if self._start_site is None:  # the first call of an episode: where the flap rests
            self._start_site = site.copy()
        if self.phase in ("retract", "hold") and not holding:
            self.phase = "approach"  # the grip slipped: start again
        if self.phase == "approach":
            target = site + np.array([0.0, 0.0, _HOVER_M])
            if np.linalg.norm(target - grasp) < _NEAR_M:
                self.phase = "descend"
            return self._move(target - grasp, jaw=1.0)
        if self.phase == "descend":
            if np.linalg.norm(site - grasp) < _NEAR_M:
                self.phase, self._waited = "close", 0
                return self._move(site - grasp, jaw=-1.0)
            return self._move(site - grasp, jaw=1.0)
        if self.phase == "close":
            self._waited += 1
            if holding:
                self.phase = "retract"
            elif self._waited > len(self.env._pending) + 1:
                self.phase, self._waited = "reopen", 0
                return self._move(np.zeros(3), jaw=1.0)
            else:
                return self._move(site - grasp, jaw=-1.0)
        if self.phase == "reopen":
            self._waited += 1
            if self._waited > len(self.env._pending):
                self.phase, self._waited = "approach", 0
            return self._move(np.zeros(3), jaw=1.0)
        if isinstance(self.env, ExposeEnv) and self.env.exposure() >= self.env.exposure_target + _EXPOSURE_MARGIN:
            return self._move(np.zeros(3), jaw=-1.0)  # enough is exposed: hold, do not stretch the flap further
        return self._move(self._retract_target(site) - site, jaw=-1.0)

    def _site_and_holding(self) -> tuple[np.ndarray, bool]:
        """The grasp site [m] and whether the jaws hold the tissue: observed, or the simulation's truth."""
        estimate = None if self._view is None else self._view.estimate
        if estimate is not None:
            return np.array(estimate.site, dtype=float), bool(estimate.grasped)
        return self.env.site_position(), bool(self.env.scene is not None and self.env.scene.grasp.holding)

    def _retract_target(self, site: np.ndarray) -> np.ndarray:
        env = self.env
        if isinstance(env, ExposeEnv):  # from where the site rested when the episode began
            start = site if self._start_site is None else self._start_site
            return np.asarray(start + _RETRACT_OFFSET_M)
        return np.asarray(env.goal, dtype=float)

    def _move(self, delta_m: np.ndarray, jaw: float) -> np.ndarray:
        """The action whose goal, once the latency has passed, lands ``delta_m`` from here.

        Each applied action replaces the control chain's goal with *the tool's pose then* plus the action's
        step, so an action must be aimed from where the tool will be when it is applied, not from where it is
        now. Every pending action is taken to carry the tool :data:`_TRACKED_FRACTION` of its step before the
        next one replaces it. Assuming the full step instead turns the loop into a dead-beat controller
        that, with the chain's acceleration-limited motion, alternates +-5 mm commands forever (measured).
        A lag-blind expert instead covers :data:`LAG_BLIND_GAIN` of the way with each action while it
        approaches and carries.
        """
        step = self.env.config.max_step_m
        action = np.zeros(5, dtype=np.float32)
        if self.lag_blind and self.phase in _LAG_BLIND_PHASES:
            action[:3] = np.clip(LAG_BLIND_GAIN * delta_m / step, -1.0, 1.0)
        else:
            in_flight = sum((pending[:3] * step for pending in self.env._pending), np.zeros(3))
            action[:3] = np.clip((delta_m - _TRACKED_FRACTION * in_flight) / step, -1.0, 1.0)
        action[4] = jaw
        return action


def _estimating_wrapper(env: Any) -> Any:
    """The outermost wrapper of ``env`` that has an ``estimate`` attribute (the robot's view), or None."""
    while isinstance(env, gym.Wrapper):
        if "estimate" in vars(env):
            return env
        env = env.env
    return None
