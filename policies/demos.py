"""Demonstrations: from a ``.npz`` file or from a task's scripted expert.

The ``.npz`` layout read here (one array per key, N episodes of T steps):

* ``obs`` (N, T + 1, obs_dim), ``achieved_goal`` (N, T + 1, goal_dim): the dict observation's entries,
  including the final observation;
* ``desired_goal`` (N, T, goal_dim) or (N, T + 1, goal_dim) or (N, goal_dim);
* ``actions`` (N, T, act_dim) in [-1, 1]; optionally ``terminal`` (N, T).

``observation`` and ``action`` are accepted as aliases of ``obs`` and ``actions``. Files are read with
``allow_pickle=False``: no code in a file is ever run.

The simulation's writer (``tissue-retract demo --task ID --episodes N --out demos.npz``) produces this
layout. Without a file, episodes are generated with the task's scripted expert (:func:`expert_for`):
the toy task's is :func:`policies.toy_env.toy_expert`; the simulation's is ``sim.expert.ScriptedExpert``, acting
on what the learner observes (``observed=True``: the estimated site of ``train --blind`` or ``--perception``).
Only successful expert episodes are kept (``info["is_success"]`` and not ``info["sim_unstable"]``).
"""

from __future__ import annotations

import functools
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from policies.buffers import Episode
from policies.errors import DemonstrationError
from policies.toy_env import TOY_TASK_ID, toy_expert
from psm_control.errors import InputFileError
from psm_control.inputs import check_regular_file
from sim.expert import ScriptedExpert

__all__ = ["Controller", "ExpertFactory", "collect_demos", "default_attempts", "expert_for", "load_demos", "rollout"]


class Controller(Protocol):
    """A scripted controller for one env: ``reset()`` at each episode start, then ``controller(obs)``."""

    def reset(self) -> None: ...

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray: ...


#: ``factory(env) -> Controller``: how a task's scripted expert is built for an env.
ExpertFactory = Callable[[gym.Env[Any, Any]], Controller]


class _FunctionController:
    """A stateless ``expert(env, obs)`` function as a :class:`Controller`."""

    def __init__(
        self, env: gym.Env[Any, Any], function: Callable[[gym.Env[Any, Any], dict[str, np.ndarray]], np.ndarray]
    ) -> None:
        self.env = env
        self.function = function

    def reset(self) -> None:
        """Nothing to reset."""

    def __call__(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        return self.function(self.env, observation)


def rollout(
    env: gym.Env[Any, Any], act: Callable[[dict[str, np.ndarray]], np.ndarray], seed: int | None
) -> tuple[Episode, bool]:
    """Run one episode with ``act``; returns it and whether it succeeded at its final step."""
    obs, _ = env.reset(seed=seed)
    o, ag, g, a, term = [obs["observation"]], [obs["achieved_goal"]], [], [], []
    success = False
    while True:
        action = np.asarray(act(obs), dtype=np.float32)
        g.append(obs["desired_goal"])
        obs, _, terminated, truncated, info = env.step(action)
        o.append(obs["observation"])
        ag.append(obs["achieved_goal"])
        a.append(action)
        term.append(bool(terminated))
        if terminated or truncated:
            success = bool(info.get("is_success", False)) and not info.get("sim_unstable", False)
            break
    episode = Episode(
        np.asarray(o, np.float32), np.asarray(ag, np.float32), np.asarray(g, np.float32),
        np.asarray(a, np.float32), np.asarray(term, bool),
    )  # fmt: skip
    return episode, success


def expert_for(task_id: str, *, lag_blind: bool = False) -> ExpertFactory:
    """The scripted expert of a task, as a factory of controllers (``lag_blind``: the simulation's expert
    moving without knowing the actions still in flight, :class:`sim.expert.ScriptedExpert`).

    Raises:
        DemonstrationError: No expert is known for the task.
    """
    if task_id == TOY_TASK_ID:
        return lambda env: _FunctionController(env, toy_expert)
    if task_id.startswith("TissueRetract-"):
        return functools.partial(ScriptedExpert, observed=True, lag_blind=lag_blind)
    raise DemonstrationError(
        f"no scripted expert is known for {task_id!r}: write demonstrations to a file "
        "(tissue-retract demo --task ID --episodes N --out demos.npz) and pass --demos-file demos.npz"
    )


def default_attempts(count: int) -> int:
    """Episodes :func:`collect_demos` tries for ``count`` successful ones unless told otherwise."""
    return 3 * count + 10


def collect_demos(
    env: gym.Env[Any, Any],
    expert: ExpertFactory,
    count: int,
    seed: int,
    max_attempts: int | None = None,
    on_success: Callable[[], None] | None = None,
) -> list[Episode]:
    """``count`` successful expert episodes (failed ones are discarded), seeded from ``seed``.

    ``on_success`` is called after each successful episode (a progress bar).

    Raises:
        DemonstrationError: The expert did not succeed ``count`` times within ``max_attempts`` episodes.
    """
    attempts = max_attempts if max_attempts is not None else default_attempts(count)
    controller = expert(env)
    episodes: list[Episode] = []
    for i in range(attempts):
        if len(episodes) == count:
            break
        controller.reset()
        episode, success = rollout(env, controller, seed=seed + i)
        if success:
            episodes.append(episode)
            if on_success is not None:
                on_success()
    if len(episodes) < count:
        raise DemonstrationError(f"the expert succeeded in only {len(episodes)} of {attempts} episodes")
    return episodes


#: Largest demonstrations file [bytes] and largest total of its arrays once read [bytes].
MAX_DEMOS_FILE_BYTES = 2_000_000_000
MAX_DEMOS_ARRAY_BYTES = 2_000_000_000


def _array_sizes(path: Path) -> dict[str, int]:
    """Bytes each array of an ``.npz`` will take once read, from the ``.npy`` headers alone (nothing allocated).

    Raises:
        DemonstrationError: Not a zip of ``.npy`` arrays, truncated, or arrays larger than allowed.
    """
    sizes: dict[str, int] = {}
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with archive.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    if version == (1, 0):
                        shape, _, dtype = np.lib.format.read_array_header_1_0(member)
                    else:
                        shape, _, dtype = np.lib.format.read_array_header_2_0(member)
                sizes[info.filename[: -len(".npy")]] = int(np.prod(shape, dtype=object)) * dtype.itemsize
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError, TypeError) as e:
        raise DemonstrationError(
            f"--demos-file {path}: not a readable .npz of arrays (empty, truncated or another format: {e})"
        ) from e
    total = sum(sizes.values())
    if total > MAX_DEMOS_ARRAY_BYTES:
        raise DemonstrationError(
            f"--demos-file {path}: its arrays would take {total} bytes once read; "
            f"at most {MAX_DEMOS_ARRAY_BYTES} allowed"
        )
    return sizes


def load_demos(path: str | Path, count: int | None = None, dims: tuple[int, int, int] | None = None) -> list[Episode]:
    """Read demonstration episodes from a ``.npz`` file (the first ``count`` of them, or all).

    Args:
        path: The ``.npz`` file.
        count: How many episodes to take (None: all).
        dims: Expected (observation, goal, action) sizes of the task; None: not checked.

    Raises:
        DemonstrationError: The file is missing, not a regular file, too large, empty or truncated, holds
            objects, lacks a required array, or holds arrays of the wrong shape or non-finite values.
    """
    path = Path(path)
    try:
        check_regular_file(path, "--demos-file", MAX_DEMOS_FILE_BYTES)
    except InputFileError as e:
        raise DemonstrationError(str(e)) from e
    _array_sizes(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
        raise DemonstrationError(f"--demos-file {path}: cannot read demonstrations: {e}") from e

    def pick(*names: str, ndim: int) -> np.ndarray:
        for name in names:
            if name in arrays:
                array = arrays[name]
                if not np.issubdtype(array.dtype, np.number) and array.dtype != bool:
                    raise DemonstrationError(f"--demos-file {path}: {name} holds {array.dtype}, not numbers")
                if array.ndim != ndim:
                    raise DemonstrationError(
                        f"--demos-file {path}: {name} has shape {array.shape}; expected {ndim} dimensions"
                    )
                array = np.asarray(array, dtype=np.float32)
                if not np.all(np.isfinite(array)):
                    bad = int(np.count_nonzero(~np.isfinite(array)))
                    raise DemonstrationError(
                        f"--demos-file {path}: {name} holds {bad} non-finite values (NaN or inf); only finite "
                        "values are allowed"
                    )
                return array
        raise DemonstrationError(
            f"--demos-file {path} has no array named {' or '.join(names)} (it has {sorted(arrays)})"
        )

    obs, ag = pick("obs", "observation", ndim=3), pick("achieved_goal", ndim=3)
    actions = pick("actions", "action", ndim=3)
    goal_array = arrays.get("desired_goal")
    goal = pick("desired_goal", ndim=2 if goal_array is not None and goal_array.ndim == 2 else 3)
    n, T = actions.shape[:2]
    if n == 0 or T == 0:
        raise DemonstrationError(
            f"--demos-file {path}: actions has shape {actions.shape}; at least one step of one episode"
        )
    if obs.shape[:2] != (n, T + 1) or ag.shape[:2] != (n, T + 1):
        raise DemonstrationError(
            f"--demos-file {path}: obs and achieved_goal must be (N, T + 1, dim) = ({n}, {T + 1}, dim) with "
            f"actions {actions.shape}; they are {obs.shape} and {ag.shape}"
        )
    if goal.shape[0] != n or (goal.ndim == 3 and goal.shape[1] not in (T, T + 1)):
        raise DemonstrationError(
            f"--demos-file {path}: desired_goal has shape {goal.shape}; "
            f"expected ({n}, {T} or {T + 1}, dim) or ({n}, dim)"
        )
    if float(np.max(np.abs(actions))) > 1.0 + 1e-6:
        raise DemonstrationError(
            f"--demos-file {path}: actions must lie in [-1, 1] (largest {np.max(np.abs(actions)):.3g})"
        )
    if dims is not None:
        found = (obs.shape[2], goal.shape[-1], actions.shape[2])
        for name, want, have in zip(("obs", "desired_goal", "actions"), dims, found, strict=True):
            if want != have:
                raise DemonstrationError(f"--demos-file {path}: {name} has {have} values per step; the task has {want}")
        if ag.shape[2] != dims[1]:
            raise DemonstrationError(
                f"--demos-file {path}: achieved_goal has {ag.shape[2]} values; the task has {dims[1]}"
            )
    if goal.ndim == 2:
        goal = np.repeat(goal[:, None, :], T, axis=1)
    goal = goal[:, :T]
    terminal = np.asarray(arrays.get("terminal", np.zeros((n, T))), dtype=bool)
    if terminal.shape != (n, T):
        raise DemonstrationError(f"--demos-file {path}: terminal has shape {terminal.shape}; expected ({n}, {T})")
    take = n if count is None else count
    if take > n:
        raise DemonstrationError(f"--demos-file {path} holds {n} demonstrations, {take} were asked for")
    return [Episode(obs[i], ag[i], goal[i], actions[i], terminal[i]) for i in range(take)]
