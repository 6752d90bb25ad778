"""Disturbances on a goal environment's observations and actions, in the manner of safe-control-gym.

Three shapes, each on observations or actions: white noise (Gaussian, every step), an impulse
(a constant offset for ``duration`` steps from ``start_step``) and a step (a constant offset from
``start_step`` to the end of the episode); plus action latency (each action applied ``k`` steps late).
Offsets of impulses and steps point in a direction drawn once per episode, so they are seeded and
reproducible. Disturbances of the dynamics (base-pose error, joint offsets, tracking lag) belong to the
simulation's randomization, not here.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Literal

import gymnasium as gym
import numpy as np

from psm_control.errors import ConfigurationError, UnknownVariantError

__all__ = ["DISTURBANCE_KINDS", "Disturbance", "DisturbanceWrapper"]

#: Shapes a disturbance can take.
DISTURBANCE_KINDS = ("white_noise", "impulse", "step")


@dataclass(frozen=True)
class Disturbance:
    """One disturbance signal.

    Attributes:
        kind: ``"white_noise"``, ``"impulse"`` or ``"step"``.
        magnitude: Standard deviation (white noise) or offset norm (impulse, step), in the units of
            the disturbed vector (metres for positions, normalised units for actions).
        start_step: First env step the impulse or step acts on.
        duration: Length of an impulse [env steps].
    """

    kind: Literal["white_noise", "impulse", "step"]
    magnitude: float
    start_step: int = 0
    duration: int = 1

    def __post_init__(self) -> None:
        if self.kind not in DISTURBANCE_KINDS:
            raise UnknownVariantError("disturbance.kind", self.kind, DISTURBANCE_KINDS)
        if not (np.isfinite(self.magnitude) and self.magnitude >= 0.0):
            raise ConfigurationError("disturbance.magnitude", self.magnitude, "a finite number >= 0")
        if self.start_step < 0:
            raise ConfigurationError("disturbance.start_step", self.start_step, "an integer >= 0")
        if self.duration < 1:
            raise ConfigurationError("disturbance.duration", self.duration, "an integer >= 1")

    def offset(self, step: int, direction: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The disturbance at ``step`` for a vector shaped like ``direction`` (a unit vector)."""
        if self.kind == "white_noise":
            return rng.normal(0.0, self.magnitude, size=direction.shape)
        active = step >= self.start_step and (self.kind == "step" or step < self.start_step + self.duration)
        return self.magnitude * direction if active else np.zeros_like(direction)


def _unit(rng: np.random.Generator, size: int) -> np.ndarray:
    vector = rng.normal(size=size)
    return vector / max(float(np.linalg.norm(vector)), 1e-12)


class DisturbanceWrapper(gym.Wrapper[dict[str, np.ndarray], np.ndarray, dict[str, np.ndarray], np.ndarray]):
    """Disturb a goal env's ``observation`` vector and its actions; delay actions.

    The reward, success and ``achieved_goal`` stay truthful: only what the policy sees and what it
    commands are disturbed. Actions are clipped back into the action space after disturbance, and
    the number of clipped components is reported in ``info["disturbance_clipped"]``.

    Args:
        env: A goal env with a dict observation holding ``observation``.
        observation: Disturbances of the ``observation`` vector.
        action: Disturbances of the action.
        latency_steps: Each action reaches the env this many steps late (zeros are sent meanwhile).
    """

    def __init__(
        self,
        env: gym.Env[dict[str, np.ndarray], np.ndarray],
        observation: tuple[Disturbance, ...] = (),
        action: tuple[Disturbance, ...] = (),
        latency_steps: int = 0,
    ) -> None:
        super().__init__(env)
        if latency_steps < 0:
            raise ConfigurationError("latency_steps", latency_steps, "an integer >= 0")
        self.observation_disturbances = tuple(observation)
        self.action_disturbances = tuple(action)
        self.latency_steps = int(latency_steps)
        self._rng = np.random.default_rng()
        self._step = 0
        self._pending: deque[np.ndarray] = deque()
        self._obs_directions: list[np.ndarray] = []
        self._action_directions: list[np.ndarray] = []

    def _disturb(
        self, vector: np.ndarray, disturbances: tuple[Disturbance, ...], directions: list[np.ndarray]
    ) -> np.ndarray:
        disturbed = np.array(vector, dtype=np.float64, copy=True)
        for disturbance, direction in zip(disturbances, directions, strict=True):
            disturbed += disturbance.offset(self._step, direction, self._rng)
        return disturbed

    def _observe(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        disturbed = dict(obs)
        vector = obs["observation"]
        disturbed["observation"] = self._disturb(vector, self.observation_disturbances, self._obs_directions).astype(
            vector.dtype
        )
        return disturbed

    def _choose_disturbances(self) -> None:
        """Set this episode's disturbances (drawing from the episode's stream); these are fixed, so nothing."""

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset the env and draw this episode's disturbance directions from the seed."""
        obs, info = self.env.reset(seed=seed, options=options)
        # A stream of its own, derived from the episode seed, so the env's own randomness is untouched; without
        # a seed the stream goes on (as a Gymnasium env's generator does), so what follows a seed repeats.
        if seed is not None:
            self._rng = np.random.default_rng([seed, 0xD157])
        self._step = 0
        self._choose_disturbances()
        obs_size = int(np.asarray(obs["observation"]).size)
        action_size = int(np.prod(self.action_space.shape or (1,)))
        self._obs_directions = [_unit(self._rng, obs_size) for _ in self.observation_disturbances]
        self._action_directions = [_unit(self._rng, action_size) for _ in self.action_disturbances]
        zero = np.zeros(self.action_space.shape or (1,), dtype=np.float64)
        self._pending = deque([zero] * self.latency_steps)
        return self._observe(obs), info

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Disturb and delay the action, step the env, disturb what the policy will see."""
        commanded = self._disturb(
            np.asarray(action, dtype=np.float64), self.action_disturbances, self._action_directions
        )
        self._pending.append(commanded)
        applied = self._pending.popleft()
        space = self.action_space
        low, high = (space.low, space.high) if isinstance(space, gym.spaces.Box) else (-np.inf, np.inf)
        finite = np.where(np.isfinite(applied), applied, 0.0)
        clipped = np.clip(finite, low, high)
        obs, reward, terminated, truncated, info = self.env.step(clipped.astype(np.float32))
        info = dict(info)
        info["disturbance_clipped"] = int(np.count_nonzero(clipped != applied))
        self._step += 1
        return self._observe(obs), float(reward), terminated, truncated, info
