"""DDPGBC: DDPG+HER plus a behaviour-cloning term on demonstrations, gated by a Q-filter.

Following Nair et al. (2018, arXiv:1709.10089) as configured in the paper's code: every update draws one
batch from the agent's buffer and one from the demonstrations. Critic and actor learn from both; the
actor also minimises ``bc_weight * ||pi(s) - a_demo||^2 / dim_a`` on the demonstration rows, masked by the
Q-filter ``Q_targ(s, a_demo) >= Q_targ(s, pi(s))`` (the demonstrated action is kept only where the critic
does not already prefer the policy's own).

The reference code takes a separate critic and actor step for each of the two batches; here one step
is taken on both batches stacked, which halves the optimiser overhead with the same expected gradient.
"""

from __future__ import annotations

import torch

from policies.algos.base import Batches, TensorBatch
from policies.algos.ddpg import DDPG

__all__ = ["DDPGBC"]


class DDPGBC(DDPG):
    """DDPG+HER with a Q-filtered behaviour-cloning loss."""

    name = "ddpgbc"

    def critic_batch(self, batches: Batches) -> TensorBatch:
        return batches.both

    def q_filter(self, x: torch.Tensor, demo_action: torch.Tensor, policy_action: torch.Tensor) -> torch.Tensor:
        """1.0 where Q_targ(s, a_demo) >= Q_targ(s, pi(s)), else 0.0 (one per row; no gradient)."""
        with torch.no_grad():
            # Both actions in one pass: half the per-call overhead, and the rows' values are unchanged.
            q = self.critic_target(torch.cat((x, x)), torch.cat((demo_action, policy_action)))
            return (q[: len(x)] >= q[len(x) :]).float()

    def bc_loss(self, demo: TensorBatch, policy_action: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
        """The (optionally Q-filtered) mean squared distance to the demonstrated actions."""
        dist = (policy_action - demo.action).pow(2).sum(-1, keepdim=True) / self.dims.action
        if not self.config.use_q_filter:
            return dist.mean(), {}
        mask = self.q_filter(demo.x, demo.action, policy_action.detach())
        return (mask * dist).mean(), {"q_filter_pass": mask.mean().item()}

    def actor_loss(self, batches: Batches) -> tuple[torch.Tensor, dict[str, float]]:
        demo = batches.demo
        if demo is None:
            return super().actor_loss(batches)
        x = batches.both.x
        action = self.actor(x)
        loss = -self.critic(x, action).mean() + self.config.action_l2 * action.pow(2).mean()
        bc, metrics = self.bc_loss(demo, action[batches.agent_rows :])
        metrics["bc_loss"] = bc.item()
        return loss + self.config.bc_weight * bc, metrics
