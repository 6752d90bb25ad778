"""DEX: demonstration-guided exploration (Huang et al., 2023, arXiv:2303.03536).

An expert action is propagated to any state by soft-min weighted k-nearest-neighbour regression over
the demonstration batch of the current update (distances in the normalised observation-goal space).
The behaviour gap ``-||a_prop(s) - a||^2 / dim_a`` enters twice, with weight ``bc_weight`` (5):

* critic target: ``r + gamma Q_targ(s', pi_targ(s')) + w * gap(a_prop(s'), pi_targ(s'))``, with
  ``a_prop(s')`` regressed from the demonstrations' next states and next actions, clipped to
  ``[-w / (1 - gamma), 0]``;
* actor loss: ``-(Q(s, pi(s)) + w * gap(a_prop(s), pi(s)))`` plus the action penalty.

The critic learns from the agent's batch only, as in the reference code. Networks are 4 x 256.
"""

from __future__ import annotations

import torch
from torch.nn import functional as F  # noqa: N812 (the conventional name)

from policies.algos.base import Batches, TensorBatch
from policies.algos.ddpg import DDPG

__all__ = ["DEX", "propagate_actions"]


def propagate_actions(x: torch.Tensor, demo_x: torch.Tensor, demo_action: torch.Tensor, k: int) -> torch.Tensor:
    """Soft-min weighted mean of the actions of the k demonstration states nearest to each row of ``x``."""
    k = min(k, demo_x.shape[0])
    distance = torch.cdist(x, demo_x)
    nearest, index = distance.topk(k, dim=1, largest=False)
    weight = F.softmin(nearest, dim=1)
    return (weight.unsqueeze(-1) * demo_action[index]).sum(dim=1)


class DEX(DDPG):
    """DDPG+HER with a behaviour gap to kNN-propagated expert actions in critic target and actor loss."""

    name = "dex"

    def gap(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """The behaviour gap -||a - b||^2 / dim_a, one per row (<= 0)."""
        return -(a - b).pow(2).sum(-1, keepdim=True) / self.dims.action

    @property
    def q_bounds(self) -> tuple[float, float]:
        return -self.config.bc_weight / (1.0 - self.config.gamma), 0.0

    def critic_target_value(self, batch: TensorBatch, batches: Batches) -> torch.Tensor:
        demo = batches.demo
        if demo is None:
            return super().critic_target_value(batch, batches)
        with torch.no_grad():
            next_action = self.actor_target(batch.next_x)
            next_q = self.critic_target(batch.next_x, next_action)
            target = batch.reward + self.config.gamma * (1.0 - batch.done) * next_q
            guide = propagate_actions(batch.next_x, demo.next_x, demo.next_action, self.config.dex_k)
            target = target + self.config.bc_weight * self.gap(guide, next_action)
            return target.clamp(*self.q_bounds)

    def actor_loss(self, batches: Batches) -> tuple[torch.Tensor, dict[str, float]]:
        demo = batches.demo
        if demo is None:
            return super().actor_loss(batches)
        batch = batches.agent
        action = self.actor(batch.x)
        with torch.no_grad():
            guide = propagate_actions(batch.x, demo.x, demo.action, self.config.dex_k)
        gap = self.gap(action, guide)
        q = self.critic(batch.x, action)
        loss = -(q + self.config.bc_weight * gap).mean() + self.config.action_l2 * action.pow(2).mean()
        return loss, {"behaviour_gap": gap.mean().item()}
