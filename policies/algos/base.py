"""What every algorithm shares: normalisers, the actor's interface, batched updates and target networks.

An algorithm subclasses :class:`Agent` and says only how it differs: which networks it builds
(:meth:`Agent.build`), how it explores (:meth:`Agent.explore`) and what one gradient update does
(:meth:`Agent.update`). Sampling, normalisation and tensor conversion for all of an episode's updates
happen at once in :meth:`Agent.train`, which keeps the per-update Python overhead to the optimiser steps.
"""

from __future__ import annotations

import abc
import contextlib
from collections.abc import Iterable, Iterator
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

from policies.buffers import Batch, EpisodeBuffer, RewardFn
from policies.config import TrainConfig
from policies.normalizer import Normalizer

__all__ = ["Agent", "Batches", "Dims", "FusedAdam", "TensorBatch", "adam", "frozen", "polyak"]


class Dims(NamedTuple):
    """Sizes of the spaces an agent acts in."""

    obs: int
    goal: int
    action: int


class TensorBatch(NamedTuple):
    """A batch ready for the networks: ``x`` is the normalised observation and goal, concatenated."""

    x: torch.Tensor
    action: torch.Tensor
    reward: torch.Tensor
    next_x: torch.Tensor
    next_action: torch.Tensor
    done: torch.Tensor

    def rows(self, start: int, stop: int) -> TensorBatch:
        """Rows ``start:stop``."""
        return TensorBatch(*(t[start:stop] for t in self))

    def interleave(self, other: TensorBatch, block: int) -> TensorBatch:
        """Blocks of ``block`` rows of ``self`` and of ``other``, alternating (both of the same length)."""
        n = len(self.x) // block
        return TensorBatch(
            *(
                torch.cat((a.view(n, block, -1), b.view(n, block, -1)), 1).view(2 * n * block, -1)
                for a, b in zip(self, other, strict=True)
            )
        )


class Batches(NamedTuple):
    """One update's transitions: the agent's rows, followed by as many demonstration rows if any.

    Algorithms that learn from agent and demonstration rows stacked use ``both`` as it is: the rows
    of every update of an episode are laid out this way once, not concatenated update by update.
    """

    both: TensorBatch
    agent_rows: int

    @property
    def agent(self) -> TensorBatch:
        """The agent's rows."""
        return self.both if len(self.both.x) == self.agent_rows else self.both.rows(0, self.agent_rows)

    @property
    def demo(self) -> TensorBatch | None:
        """The demonstration rows, or None."""
        total = len(self.both.x)
        return None if total == self.agent_rows else self.both.rows(self.agent_rows, total)


@torch.no_grad()
def polyak(target: list[torch.Tensor], online: list[torch.Tensor], tau: float) -> None:
    """target <- (1 - tau) target + tau online, for paired parameter lists (one multi-tensor op)."""
    torch._foreach_lerp_(target, online, tau)


@contextlib.contextmanager
def frozen(params: list[torch.Tensor]) -> Iterator[None]:
    """Build graphs in which ``params`` are constants: gradients flow through, not into, them.

    Parameter lists are cached by the agents: iterating a module's parameters on every update costs
    as much as a small layer's arithmetic.
    """
    for p in params:
        p.requires_grad_(False)
    try:
        yield
    finally:
        for p in params:
            p.requires_grad_(True)


class FusedAdam(torch.optim.Adam):
    """``torch.optim.Adam(fused=True)`` whose steps call the fused kernel directly.

    ``Optimizer.step`` spends about twice as long on hooks, profiling records and regrouping tensors
    as the kernel takes to update every parameter of these networks. Once each parameter has state,
    :meth:`step` makes the same calls as ``Adam`` does (step counts + 1, then ``_fused_adam_`` per
    group, skipping parameters without a gradient) and nothing else, so the results are identical;
    the first step, which creates the state, is ``Adam``'s own. State dicts are ``Adam``'s.
    """

    def __init__(self, params: list[dict[str, Any]]) -> None:
        super().__init__(params, fused=True)
        self._one = torch.ones(())

    @torch.no_grad()
    def step(self, closure: None = None) -> None:  # type: ignore[override]
        """One Adam step on the current gradients (no closure)."""
        groups = []
        for group in self.param_groups:
            params = [p for p in group["params"] if p.grad is not None]
            if any(p not in self.state for p in params):
                super().step()
                return
            if params:
                groups.append((group, params, [self.state[p] for p in params]))
        for group, params, states in groups:
            steps = [s["step"] for s in states]
            # A list of tensor ones: the scalar overload converts the scalar once per tensor (3x slower).
            torch._foreach_add_(steps, [self._one] * len(steps))
            beta1, beta2 = group["betas"]
            torch._fused_adam_(
                params,
                [p.grad for p in params],
                [s["exp_avg"] for s in states],
                [s["exp_avg_sq"] for s in states],
                [],
                steps,
                amsgrad=False,
                lr=group["lr"],
                beta1=beta1,
                beta2=beta2,
                weight_decay=group["weight_decay"],
                eps=group["eps"],
                maximize=group["maximize"],
            )

    def zero_grad(self, set_to_none: bool = True) -> None:
        """Drop every gradient (the next backward pass allocates fresh ones)."""
        if not set_to_none:
            super().zero_grad(set_to_none=False)
            return
        for group in self.param_groups:
            for p in group["params"]:
                p.grad = None


def adam(groups: Iterable[tuple[Iterable[torch.Tensor], float]]) -> FusedAdam:
    """One Adam over (parameters, learning rate) groups, with the fused CPU kernel.

    Every algorithm here adds its losses and takes a single backward pass and a single optimiser step
    per update: with networks this small, the per-call overhead of separate steps is a large share of
    an update's time.
    """
    return FusedAdam([{"params": list(p), "lr": lr} for p, lr in groups])


class Agent(abc.ABC):
    """An off-policy goal-conditioned agent.

    Args:
        dims: Observation, goal and action sizes.
        config: Hyperparameters.
        seed: Seed of the agent's own randomness (network initialisation, exploration noise).
    """

    #: Name used in checkpoints and on the command line.
    name: str = ""

    def __init__(self, dims: Dims, config: TrainConfig, seed: int = 0) -> None:
        self.dims = dims
        self.config = config
        self.generator = torch.manual_seed(seed)
        self.rng = np.random.default_rng(seed)
        c = config
        self.obs_norm = Normalizer(dims.obs, c.norm_eps, c.norm_clip, c.obs_clip)
        self.goal_norm = Normalizer(dims.goal, c.norm_eps, c.norm_clip, c.obs_clip)
        self.in_dim = dims.obs + dims.goal
        self.updates = 0
        self._optimizer: FusedAdam | None = None
        self.build()

    @property
    @abc.abstractmethod
    def actor(self) -> nn.Module:
        """The network whose ``forward(x)`` is the deterministic action in [-1, 1]."""

    @abc.abstractmethod
    def build(self) -> None:
        """Create the networks."""

    @abc.abstractmethod
    def optimizer_groups(self) -> list[tuple[Iterable[torch.Tensor], float]]:
        """The optimiser's (parameters, learning rate) groups."""

    @property
    def optimizer(self) -> FusedAdam:
        """The agent's one optimiser (:func:`adam` over :meth:`optimizer_groups`), made at its first use: acting
        needs none, and making one imports torch's compiler stack (1.2 s of CPU measured), which every deploy,
        evaluation and sweep worker that loads a policy would otherwise pay."""
        if self._optimizer is None:
            self._optimizer = adam(self.optimizer_groups())
        return self._optimizer

    @abc.abstractmethod
    def modules(self) -> dict[str, nn.Module]:
        """Every network by name (checkpointed)."""

    @abc.abstractmethod
    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        """Every optimiser by name (checkpointed for resuming)."""

    @abc.abstractmethod
    def update(self, batches: Batches) -> dict[str, float]:
        """One gradient update from an agent batch and, for demonstration-based algorithms, a demo batch."""

    def extra_tensors(self) -> dict[str, torch.Tensor]:
        """Learnable tensors outside :meth:`modules` (SAC's temperature), checkpointed too."""
        return {}

    # --- acting ---------------------------------------------------------------------------------------

    def inputs(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The network input for raw observations and goals: both normalised, concatenated."""
        return np.concatenate((self.obs_norm(obs), self.goal_norm(goal)), axis=-1)

    @torch.inference_mode()
    def act(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The deterministic action(s) in [-1, 1] for raw observation(s) and goal(s)."""
        x = torch.from_numpy(self.inputs(obs, goal))
        return self.actor(x).numpy()

    def explore(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """An exploratory action: the deterministic action plus Gaussian noise, sometimes a random one."""
        c = self.config
        if c.random_eps > 0 and self.rng.random() < c.random_eps:
            return self.rng.uniform(-1.0, 1.0, self.dims.action).astype(np.float32)
        a = self.act(obs, goal)
        a = a + c.noise_std * self.rng.standard_normal(a.shape).astype(np.float32)
        return np.clip(a, -1.0, 1.0)

    # --- learning -------------------------------------------------------------------------------------

    def observe_episode(self, obs: np.ndarray, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> None:
        """Update the normalisers with an episode's observations and goals (desired and achieved)."""
        self.obs_norm.update(obs)
        self.goal_norm.update(np.concatenate((desired_goal, achieved_goal)))

    def to_tensors(self, batch: Batch, reward_shift: float = 0.0) -> TensorBatch:
        """Normalise a sampled batch and make it tensors."""
        return TensorBatch(
            x=torch.from_numpy(self.inputs(batch.obs, batch.goal)),
            action=torch.from_numpy(np.ascontiguousarray(batch.action)),
            reward=torch.from_numpy(batch.reward + np.float32(reward_shift)).unsqueeze(-1),
            next_x=torch.from_numpy(self.inputs(batch.next_obs, batch.goal)),
            next_action=torch.from_numpy(np.ascontiguousarray(batch.next_action)),
            done=torch.from_numpy(batch.done).unsqueeze(-1),
        )

    def sample(
        self, buffer: EpisodeBuffer, count: int, reward_fn: RewardFn, reward_override: float | None = None
    ) -> TensorBatch:
        """Sample ``count`` HER-relabelled transitions and make them network-ready."""
        raw = buffer.sample(count, self.rng, reward_fn, self.config.her_probability, reward_override)
        return self.to_tensors(raw)

    def agent_reward(self) -> float | None:
        """A constant reward replacing the env's on agent transitions (SQIL), or None."""
        return None

    def demo_reward(self) -> float | None:
        """A constant reward replacing the env's on demonstration transitions (SQIL), or None."""
        return None

    def train(
        self,
        buffer: EpisodeBuffer,
        demos: EpisodeBuffer | None,
        reward_fn: RewardFn,
        n_updates: int,
    ) -> dict[str, float]:
        """Run ``n_updates`` gradient updates, sampling every batch up front; returns the last metrics."""
        if n_updates <= 0 or len(buffer) == 0:
            return {}
        B = self.config.batch_size
        data = self.sample(buffer, n_updates * B, reward_fn, self.agent_reward())
        if demos is not None and len(demos) > 0 and self.config.uses_demos:
            data = data.interleave(self.sample(demos, n_updates * B, reward_fn, self.demo_reward()), B)
        rows = len(data.x) // n_updates
        metrics: dict[str, float] = {}
        for i in range(n_updates):
            metrics = self.update(Batches(data.rows(i * rows, (i + 1) * rows), B))
            self.updates += 1
        return metrics

    def pretrain(self, demos: EpisodeBuffer, reward_fn: RewardFn, steps: int) -> dict[str, float]:
        """Learning from demonstrations alone before interacting (nothing by default; CoL overrides)."""
        return {}
