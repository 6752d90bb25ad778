"""CoL (Cycle-of-Learning): behaviour-cloning pre-training, then DDPGBC without the Q-filter.

Goecks et al. (2020, arXiv:1910.04281), as configured in the paper's code: ``bc_pretrain_steps`` (2,000)
updates of pure behaviour cloning on demonstrations before the agent acts, then the DDPGBC losses
with the BC term always on (``q_filter`` defaults to off for this algorithm).
"""

from __future__ import annotations

from policies.algos.ddpgbc import DDPGBC
from policies.buffers import EpisodeBuffer, RewardFn

__all__ = ["CoL"]


class CoL(DDPGBC):
    """Behaviour-cloning pre-training followed by DDPGBC without the Q-filter."""

    name = "col"

    def pretrain(self, demos: EpisodeBuffer, reward_fn: RewardFn, steps: int) -> dict[str, float]:
        """``steps`` actor updates minimising ||pi(s) - a_demo||^2 / dim_a on demonstration batches."""
        if steps <= 0 or len(demos) == 0:
            return {}
        B = self.config.batch_size
        loss_value = float("nan")
        chunk = 100
        for start in range(0, steps, chunk):
            n = min(chunk, steps - start)
            data = self.sample(demos, n * B, reward_fn)
            for i in range(n):
                demo = data.rows(i * B, (i + 1) * B)
                loss = (self.actor(demo.x) - demo.action).pow(2).sum(-1).mean() / self.dims.action
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                self.optimizer.step()
                loss_value = loss.item()
        self.actor_target.load_state_dict(self.actor.state_dict())
        return {"bc_pretrain_loss": loss_value}
