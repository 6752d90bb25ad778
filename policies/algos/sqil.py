"""SQIL: soft Q imitation learning (Reddy et al., 2020, arXiv:1905.11108) on SAC.

SAC with a tanh-squashed Gaussian actor, twin critics and a learnable entropy temperature (initial 0.1,
target entropy -dim_a). SQIL replaces the environment's reward: agent transitions get 0 and
demonstration transitions ``sqil_demo_reward`` (1), and every update learns from one agent batch and
one demonstration batch stacked. Learning rate 1e-4 for actor, critics and temperature. Returns are
not clipped: the rewards are not the task's 0/-1.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812 (the conventional name)

from policies.algos.base import Agent, Batches, frozen, polyak
from policies.networks import GaussianActor, TwinCritic

__all__ = ["SQIL"]


class SQIL(Agent):
    """SQIL on SAC."""

    name = "sqil"

    def build(self) -> None:
        c, h = self.config, self.config.hidden
        self._actor = GaussianActor(self.in_dim, self.dims.action, h)
        self.critic = TwinCritic(self.in_dim, self.dims.action, h)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.critic_params: list[torch.Tensor] = list(self.critic.parameters())
        self.target_params: list[torch.Tensor] = list(self.critic_target.parameters())
        self.log_alpha = torch.tensor([math.log(c.sac_init_temperature)], requires_grad=True)
        self.target_entropy = -float(self.dims.action)

    def optimizer_groups(self) -> list[tuple[Iterable[torch.Tensor], float]]:
        c = self.config
        return [
            (self._actor.parameters(), c.lr_actor),
            (self.critic.parameters(), c.lr_critic),
            ([self.log_alpha], c.lr_actor),
        ]

    @property
    def actor(self) -> nn.Module:
        return self._actor

    def modules(self) -> dict[str, nn.Module]:
        return {"actor": self._actor, "critic": self.critic, "critic_target": self.critic_target}

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"adam": self.optimizer}

    def extra_tensors(self) -> dict[str, torch.Tensor]:
        return {"log_alpha": self.log_alpha}

    def agent_reward(self) -> float | None:
        return 0.0

    def demo_reward(self) -> float | None:
        return self.config.sqil_demo_reward

    def explore(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """A sample of the stochastic policy."""
        with torch.inference_mode():
            action, _ = self._actor.sample(torch.from_numpy(self.inputs(obs, goal)))
        return action.numpy()

    def update(self, batches: Batches) -> dict[str, float]:
        b = batches.both
        alpha = self.log_alpha.detach().exp()
        with torch.no_grad():
            next_action, next_logp = self._actor.sample(b.next_x)
            q1_t, q2_t = self.critic_target(b.next_x, next_action)
            next_v = torch.min(q1_t, q2_t) - alpha * next_logp
            target = b.reward + self.config.gamma * (1.0 - b.done) * next_v
        q1, q2 = self.critic(b.x, b.action)
        critic_loss = F.mse_loss(q1, target) + F.mse_loss(q2, target)
        with frozen(self.critic_params):
            action, logp = self._actor.sample(b.x)
            q1_pi, q2_pi = self.critic(b.x, action)
        actor_loss = (alpha * logp - torch.min(q1_pi, q2_pi)).mean()
        alpha_loss = -(self.log_alpha * (logp.detach() + self.target_entropy)).mean()
        self.optimizer.zero_grad(set_to_none=True)
        (critic_loss + actor_loss + alpha_loss).backward()
        self.optimizer.step()

        polyak(self.target_params, self.critic_params, self.config.tau)
        return {"critic_loss": critic_loss.item(), "actor_loss": actor_loss.item(), "alpha": float(alpha)}
