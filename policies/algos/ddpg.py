"""DDPG with hindsight experience replay: the base of the DDPG family (DDPGBC, CoL, DEX).

Deterministic tanh actor, one critic, Polyak-averaged targets, Gaussian exploration noise. The critic
regresses on r + gamma Q_targ(s', pi_targ(s')) clipped to the range of returns of 0/-1 rewards,
[-1 / (1 - gamma), 0]; the actor minimises -Q(s, pi(s)) + action_l2 * mean(pi(s)^2).

Both losses are built from the networks as they are at the start of the update and minimised by one
optimiser step (the reference code steps the critic first, then builds the actor loss on the updated
critic; with tau = 0.005 targets the difference is one update of lag in the actor's critic).
"""

from __future__ import annotations

import copy
from collections.abc import Iterable

import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812 (the conventional name)

from policies.algos.base import Agent, Batches, TensorBatch, frozen, polyak
from policies.networks import Critic, DeterministicActor

__all__ = ["DDPG"]


class DDPG(Agent):
    """DDPG+HER."""

    name = "ddpg"

    def build(self) -> None:
        h = self.config.hidden
        self._actor = DeterministicActor(self.in_dim, self.dims.action, h)
        self.critic = Critic(self.in_dim, self.dims.action, h)
        self.actor_target = copy.deepcopy(self._actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.critic_params: list[torch.Tensor] = list(self.critic.parameters())
        self.target_params: list[torch.Tensor] = [*self.critic_target.parameters(), *self.actor_target.parameters()]
        self.online_params: list[torch.Tensor] = [*self.critic_params, *self._actor.parameters()]

    def optimizer_groups(self) -> list[tuple[Iterable[torch.Tensor], float]]:
        c = self.config
        return [(self._actor.parameters(), c.lr_actor), (self.critic.parameters(), c.lr_critic)]

    @property
    def actor(self) -> nn.Module:
        return self._actor

    def modules(self) -> dict[str, nn.Module]:
        return {
            "actor": self._actor,
            "critic": self.critic,
            "actor_target": self.actor_target,
            "critic_target": self.critic_target,
        }

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"adam": self.optimizer}

    @property
    def q_bounds(self) -> tuple[float, float]:
        """Range the critic target is clipped to: returns of 0/-1 rewards."""
        return -1.0 / (1.0 - self.config.gamma), 0.0

    def critic_target_value(self, batch: TensorBatch, batches: Batches) -> torch.Tensor:
        """The critic's regression target for ``batch``, the critic's rows of ``batches`` (no gradient)."""
        with torch.no_grad():
            next_q = self.critic_target(batch.next_x, self.actor_target(batch.next_x))
            target = batch.reward + self.config.gamma * (1.0 - batch.done) * next_q
            return target.clamp(*self.q_bounds)

    def critic_batch(self, batches: Batches) -> TensorBatch:
        """The transitions the critic learns from (the agent's here)."""
        return batches.agent

    def actor_loss(self, batches: Batches) -> tuple[torch.Tensor, dict[str, float]]:
        """-Q(s, pi(s)) plus the action penalty, over the agent's rows."""
        x = batches.agent.x
        action = self._actor(x)
        loss = -self.critic(x, action).mean() + self.config.action_l2 * action.pow(2).mean()
        return loss, {}

    def update(self, batches: Batches) -> dict[str, float]:
        cb = self.critic_batch(batches)
        target = self.critic_target_value(cb, batches)
        critic_loss = F.mse_loss(self.critic(cb.x, cb.action), target)
        # The actor's gradient flows through the critic's input only: with the critic's weights frozen
        # while the actor loss is built, one backward pass gives each network the gradient of its own loss.
        with frozen(self.critic_params):
            actor_loss, metrics = self.actor_loss(batches)
        self.optimizer.zero_grad(set_to_none=True)
        (critic_loss + actor_loss).backward()
        self.optimizer.step()

        polyak(self.target_params, self.online_params, self.config.tau)
        metrics["critic_loss"] = critic_loss.item()
        metrics["actor_loss"] = actor_loss.item()
        return metrics
