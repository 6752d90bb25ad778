"""Collecting training episodes, in this process or in a worker that steps the task while this one learns.

On a small machine an off-policy run alternates between two costs of the same size: simulating the task
(about 1.3 ms per env step on one core) and the gradient updates (a few ms per episode step at the
paper's ratio). Done one after the other, one core idles. :class:`OverlappedCollector` runs the task in
a worker process (Gymnasium's :class:`~gymnasium.vector.AsyncVectorEnv` with one environment: its
``step_async``/``step_wait`` pair is exactly "start the physics, do something else, take the result")
and calls back into the learner between the two, so the updates run while the physics does.

The worker also collects half of the expert's demonstrations while this process collects the other half.
The worker's environment returns no ``info``: training reads observations, goals and the end of the
episode only, and the info dict (tens of entries) would cost a pickle per step. Episodes are seeded as
the serial loop seeds them; what differs is only that an episode's updates see the buffer as it was when
the episode started.
"""

from __future__ import annotations

import abc
import pickle
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector.async_vector_env import _async_worker

from policies.buffers import Episode
from policies.demos import collect_demos, expert_for
from policies.registry import ensure_registered  # the worker's own registry: sim's tasks

__all__ = ["Collector", "OverlappedCollector", "SerialCollector", "can_run_in_worker"]

Observation = dict[str, np.ndarray]


class _WorkerTask(gym.Wrapper[Any, Any, Any, Any]):
    """The task as the worker runs it: empty info dicts (training does not read them), and the task's
    expert demonstrations on request."""

    def __init__(self, env: gym.Env[Any, Any], task_id: str) -> None:
        super().__init__(env)
        self.task_id = task_id

    def demonstrations(self, count: int, seed: int, lag_blind: bool = False) -> list[Episode]:
        """``count`` successful expert episodes seeded from ``seed`` (:func:`policies.demos.collect_demos`;
        ``lag_blind``: :func:`policies.demos.expert_for`'s)."""
        return collect_demos(self.env, expert_for(self.task_id, lag_blind=lag_blind), count, seed)

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        observation, _ = self.env.reset(**kwargs)
        return observation, {}

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, _ = self.env.step(action)
        return observation, reward, terminated, truncated, {}


def _worker_ending_quietly(*args: Any) -> None:
    """Gymnasium's worker loop, ending without a traceback when this process's parent is gone.

    A parent killed outright (SIGKILL, the OOM killer) closes its end of the pipe: Gymnasium's worker
    then fails to read a command (EOFError), tries to report it on the same pipe (BrokenPipeError) and
    dies printing both tracebacks into the user's terminal. The worker has nothing to save, so it ends.
    """
    try:
        _async_worker(*args)
    except (EOFError, BrokenPipeError, ConnectionResetError):
        return


class _TaskFactory:
    """Makes the task in the worker (a class, not a closure, so that it pickles for a spawned process)."""

    def __init__(self, task_id: str, wrapper: Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None) -> None:
        self.task_id = task_id
        self.wrapper = wrapper

    def __call__(self) -> gym.Env[Any, Any]:
        env = gym.make(ensure_registered(self.task_id))
        return _WorkerTask(self.wrapper(env) if self.wrapper is not None else env, self.task_id)


def can_run_in_worker(wrapper: Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None) -> bool:
    """Whether a task wrapper can be sent to a worker process (a lambda or a closure cannot)."""
    try:
        pickle.dumps(wrapper)
    except (pickle.PicklingError, AttributeError, TypeError):
        return False
    return True


class Collector(abc.ABC):
    """Runs training episodes of a task, calling ``learn(step)`` once per step (and once for the reset).

    Subclasses say how a reset and a step start and finish; ``learn`` runs between the two.
    """

    def episode(self, seed: int, act: Callable[[Observation], np.ndarray], learn: Callable[[int], None]) -> Episode:
        """One episode from ``reset(seed=seed)``; ``step`` counts from 0 (-1 for the reset)."""
        self._start_reset(seed)
        learn(-1)
        obs = self._finish_reset()
        o, ag, g, a, term = [obs["observation"]], [obs["achieved_goal"]], [], [], []
        step = 0
        while True:
            action = np.asarray(act(obs), dtype=np.float32)
            g.append(obs["desired_goal"])
            self._start_step(action)
            learn(step)
            obs, terminated, truncated = self._finish_step()
            o.append(obs["observation"])
            ag.append(obs["achieved_goal"])
            a.append(action)
            term.append(terminated)
            step += 1
            if terminated or truncated:
                break
        return Episode(
            np.asarray(o, np.float32), np.asarray(ag, np.float32), np.asarray(g, np.float32),
            np.asarray(a, np.float32), np.asarray(term, bool),
        )  # fmt: skip

    @abc.abstractmethod
    def _start_reset(self, seed: int) -> None: ...

    @abc.abstractmethod
    def _finish_reset(self) -> Observation: ...

    @abc.abstractmethod
    def _start_step(self, action: np.ndarray) -> None: ...

    @abc.abstractmethod
    def _finish_step(self) -> tuple[Observation, bool, bool]: ...

    @abc.abstractmethod
    def close(self) -> None:
        """Release what the collector started."""


class SerialCollector(Collector):
    """Steps the task in this process, ``learn`` after each step (the paper's code learns after the episode).

    Args:
        env: The task (the caller's: :meth:`close` leaves it open).
    """

    def __init__(self, env: gym.Env[Any, Any]) -> None:
        self.env = env
        self._result: Any = None

    def _start_reset(self, seed: int) -> None:
        self._result = self.env.reset(seed=seed)

    def _finish_reset(self) -> Observation:
        return dict(self._result[0])

    def _start_step(self, action: np.ndarray) -> None:
        self._result = self.env.step(action)

    def _finish_step(self) -> tuple[Observation, bool, bool]:
        obs, _, terminated, truncated, _ = self._result
        return dict(obs), bool(terminated), bool(truncated)

    def close(self) -> None:
        """Nothing to release: the environment is the caller's."""


class OverlappedCollector(Collector):
    """A :class:`Collector` whose task steps in a worker process while ``learn`` runs here.

    Args:
        task_id: Gymnasium id of the task.
        wrapper: Wraps the task in the worker (as ``RunSpec.env_wrapper``; it must pickle).
    """

    def __init__(self, task_id: str, wrapper: Callable[[gym.Env[Any, Any]], gym.Env[Any, Any]] | None = None) -> None:
        # spawn, not fork: the parent has torch's and PyBullet's threads and state, which fork copies badly.
        self._envs = gym.vector.AsyncVectorEnv(
            [_TaskFactory(task_id, wrapper)], context="spawn", worker=_worker_ending_quietly
        )

    def _start_reset(self, seed: int) -> None:
        self._envs.reset_async(seed=[seed])

    def _finish_reset(self) -> Observation:
        batch, _ = self._envs.reset_wait()
        return _first(batch)

    def _start_step(self, action: np.ndarray) -> None:
        self._envs.step_async(action[None])

    def _finish_step(self) -> tuple[Observation, bool, bool]:
        batch, _, terminated, truncated, _ = self._envs.step_wait()
        return _first(batch), bool(terminated[0]), bool(truncated[0])

    def start_demonstrations(self, count: int, seed: int, lag_blind: bool = False) -> None:
        """Start collecting ``count`` expert demonstrations in the worker, seeded from ``seed`` (``lag_blind``:
        from the lag-blind expert)."""
        self._envs.call_async("demonstrations", count, seed, lag_blind)

    def finish_demonstrations(self) -> list[Episode]:
        """The demonstrations :meth:`start_demonstrations` asked for, once the worker has them.

        Raises:
            DemonstrationError: The expert did not succeed often enough in the worker.
        """
        (episodes,) = self._envs.call_wait()
        return list(episodes)

    def close(self) -> None:
        """Stop the worker at once: it holds nothing to save, and its orderly exit (torch's and PyBullet's
        teardown) took seconds on a loaded machine. Closing twice is harmless."""
        if not self._envs.closed:
            self._envs.close(terminate=True)


def _first(batch: dict[str, np.ndarray]) -> Observation:
    """The one environment's observation out of the vector's batch."""
    return {key: np.asarray(value[0]) for key, value in batch.items()}
