"""The five algorithms' losses on a tiny deterministic goal task, the Q-filter and kNN propagation."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch import nn

from policies.algos import AGENTS, DDPGBC, Agent, Dims, TensorBatch, make_agent
from policies.algos.dex import DEX, propagate_actions
from policies.buffers import EpisodeBuffer
from policies.config import TrainConfig
from policies.demos import collect_demos, expert_for, rollout
from policies.toy_env import TOY_TASK_ID, ToyReachEnv

DIMS = Dims(4, 3, 5)
SMALL = {"hidden_sizes": (64, 64), "batch_size": 64}


@pytest.fixture(scope="module")
def data() -> tuple[EpisodeBuffer, EpisodeBuffer]:
    """Random-action agent episodes and expert demonstrations on the toy task."""
    env = gym.make(TOY_TASK_ID)
    rng = np.random.default_rng(0)
    agent = EpisodeBuffer(5000, 50, 4, 3, 5)
    for i in range(20):
        episode, _ = rollout(env, lambda o: rng.uniform(-1, 1, 5).astype(np.float32), seed=i)
        agent.add(episode)
    demos = EpisodeBuffer(1000, 50, 4, 3, 5)
    for episode in collect_demos(gym.make(TOY_TASK_ID), expert_for(TOY_TASK_ID), 10, seed=100):
        demos.add(episode)
    return agent, demos


def _agent(algo: str, data: tuple[EpisodeBuffer, EpisodeBuffer], **overrides: object) -> Agent:
    agent = make_agent(DIMS, TrainConfig(algo=algo, **{**SMALL, **overrides}), seed=0)  # type: ignore[arg-type]
    for buffer in data:
        for e in buffer.episodes():
            agent.observe_episode(e.obs, e.achieved_goal, e.desired_goal)
    return agent


def _fixed(agent: Agent, buffer: EpisodeBuffer, reward: float | None = None) -> TensorBatch:
    agent.rng = np.random.default_rng(123)
    return agent.sample(buffer, 512, ToyReachEnv().compute_reward, reward)


def _td_error(agent: Agent, batch: TensorBatch) -> float:
    with torch.no_grad():
        q = agent.critic(batch.x, batch.action)  # type: ignore[attr-defined]
        q = q[0] if isinstance(q, tuple) else q
        a_next = agent.actor(batch.next_x)
        q_next = agent.critic(batch.next_x, a_next)  # type: ignore[attr-defined]
        q_next = torch.min(*q_next) if isinstance(q_next, tuple) else q_next
        return float((q - (batch.reward + 0.99 * q_next)).pow(2).mean())


@pytest.mark.parametrize("algo", sorted(AGENTS))
def test_critic_td_error_falls(algo: str, data: tuple[EpisodeBuffer, EpisodeBuffer]) -> None:
    """Gradient updates reduce the critic's TD error on a fixed batch of the task."""
    agent = _agent(algo, data)
    batch = _fixed(agent, data[0], agent.agent_reward())
    torch.manual_seed(0)
    with torch.no_grad():
        for p in agent.modules()["critic"].parameters():
            p.add_(0.3 * torch.randn_like(p))
    before = _td_error(agent, batch)
    agent.train(data[0], data[1], ToyReachEnv().compute_reward, 150)
    assert _td_error(agent, batch) < 0.5 * before


def test_ddpg_actor_climbs_the_critic(data: tuple[EpisodeBuffer, EpisodeBuffer]) -> None:
    """DDPG's actor ends with a higher Q under its critic than random actions get."""
    agent = _agent("ddpg", data)
    agent.train(data[0], None, ToyReachEnv().compute_reward, 300)
    batch = _fixed(agent, data[0])
    with torch.no_grad():
        q_pi = agent.critic(batch.x, agent.actor(batch.x)).mean()  # type: ignore[attr-defined]
        q_rand = agent.critic(batch.x, torch.rand_like(batch.action) * 2 - 1).mean()  # type: ignore[attr-defined]
    assert q_pi > q_rand


def _bc_distance(agent: Agent, demo: TensorBatch) -> float:
    with torch.no_grad():
        return float((agent.actor(demo.x) - demo.action).pow(2).mean())


@pytest.mark.parametrize("algo", ["ddpgbc", "col", "dex"])
def test_demonstration_algorithms_move_towards_the_expert(algo: str, data: tuple[EpisodeBuffer, EpisodeBuffer]) -> None:
    """DDPGBC, CoL and DEX bring the actor's actions closer to the demonstrated ones."""
    agent = _agent(algo, data, bc_pretrain_steps=100)
    demo = _fixed(agent, data[1])
    before = _bc_distance(agent, demo)
    agent.pretrain(data[1], ToyReachEnv().compute_reward, agent.config.pretrain_steps)
    agent.train(data[0], data[1], ToyReachEnv().compute_reward, 200)
    assert _bc_distance(agent, demo) < 0.7 * before


def test_col_pretraining_is_behaviour_cloning(data: tuple[EpisodeBuffer, EpisodeBuffer]) -> None:
    """CoL's pre-training alone fits the demonstrated actions and leaves the critic untouched."""
    agent = _agent("col", data, bc_pretrain_steps=300)
    demo = _fixed(agent, data[1])
    critic = [p.clone() for p in agent.modules()["critic"].parameters()]
    before = _bc_distance(agent, demo)
    metrics = agent.pretrain(data[1], ToyReachEnv().compute_reward, 300)
    assert _bc_distance(agent, demo) < 0.3 * before
    assert metrics["bc_pretrain_loss"] < before
    assert all(torch.equal(a, b) for a, b in zip(critic, agent.modules()["critic"].parameters(), strict=True))


def test_sqil_values_demonstrations_above_agent_transitions(data: tuple[EpisodeBuffer, EpisodeBuffer]) -> None:
    """SQIL's critic learns a higher value for demonstrated (reward 1) than for agent (reward 0) transitions."""
    agent = _agent("sqil", data, actor_lr=1e-3, critic_lr=1e-3)
    agent.train(data[0], data[1], ToyReachEnv().compute_reward, 300)
    agent_batch, demo_batch = _fixed(agent, data[0], 0.0), _fixed(agent, data[1], 1.0)
    with torch.no_grad():
        q_demo = agent.critic(demo_batch.x, demo_batch.action)[0].mean()  # type: ignore[attr-defined]
        q_agent = agent.critic(agent_batch.x, agent_batch.action)[0].mean()  # type: ignore[attr-defined]
    assert q_demo > q_agent


def test_dex_behaviour_gap_closes(data: tuple[EpisodeBuffer, EpisodeBuffer]) -> None:
    """DEX's actor reduces its behaviour gap to the kNN-propagated expert actions."""
    agent = _agent("dex", data)
    assert isinstance(agent, DEX)
    batch, demo = _fixed(agent, data[0]), _fixed(agent, data[1])

    def gap() -> float:
        with torch.no_grad():
            guide = propagate_actions(batch.x, demo.x, demo.action, 5)
            return float(agent.gap(agent.actor(batch.x), guide).mean())

    before = gap()
    agent.train(data[0], data[1], ToyReachEnv().compute_reward, 200)
    assert gap() > 0.5 * before  # gaps are <= 0: closer to 0 is smaller


class _PreferSmallFirstAction(nn.Module):
    """Q(s, a) = -a_0: a critic that prefers actions with a small first component."""

    def forward(self, x: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        return -a[:, :1]


@pytest.mark.parametrize("use_filter", [True, False])
def test_q_filter_masks_where_the_critic_prefers_the_policy(use_filter: bool) -> None:
    """The BC term counts a demo row iff Q(s, a_demo) >= Q(s, pi(s)) (always, without the filter)."""
    agent = make_agent(DIMS, TrainConfig(algo="ddpgbc", q_filter=use_filter, **SMALL), seed=0)  # type: ignore[arg-type]
    assert isinstance(agent, DDPGBC)
    agent.critic_target = _PreferSmallFirstAction()  # type: ignore[assignment]
    g = torch.Generator().manual_seed(0)
    n = 256
    demo_action = torch.rand(n, 5, generator=g) * 2 - 1
    policy_action = torch.rand(n, 5, generator=g) * 2 - 1
    demo = TensorBatch(
        torch.zeros(n, 7), demo_action, torch.zeros(n, 1), torch.zeros(n, 7), demo_action, torch.zeros(n, 1)
    )
    expected_mask = (demo_action[:, 0] <= policy_action[:, 0]).float().unsqueeze(-1)
    mask = agent.q_filter(demo.x, demo_action, policy_action)
    assert torch.equal(mask, expected_mask)
    loss, _ = agent.bc_loss(demo, policy_action)
    dist = (policy_action - demo_action).pow(2).sum(-1, keepdim=True) / 5
    expected = (expected_mask * dist).mean() if use_filter else dist.mean()
    torch.testing.assert_close(loss, expected)


def test_propagated_action_is_a_soft_min_weighted_neighbour_mean() -> None:
    """k = 1 gives the nearest demo action; equidistant neighbours are averaged with equal weight."""
    demo_x = torch.tensor([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [10.0, 10.0]])
    demo_a = torch.tensor([[0.0], [1.0], [3.0], [100.0]])
    x = torch.tensor([[0.9, 0.0], [0.0, 0.0]])
    torch.testing.assert_close(propagate_actions(x, demo_x, demo_a, 1), torch.tensor([[1.0], [0.0]]))
    at_origin = propagate_actions(torch.tensor([[0.0, 5.0]]), demo_x[:3], demo_a[:3], 3)
    d = torch.tensor([5.0, 26.0**0.5, 26.0**0.5])
    w = torch.softmax(-d, 0)
    torch.testing.assert_close(at_origin, (w.unsqueeze(-1) * demo_a[:3]).sum(0, keepdim=True))


def test_same_seed_same_updates(data: tuple[EpisodeBuffer, EpisodeBuffer]) -> None:
    """Two agents with the same seed and data end with identical weights."""
    weights = []
    for _ in range(2):
        agent = _agent("ddpgbc", data)
        agent.train(data[0], data[1], ToyReachEnv().compute_reward, 20)
        weights.append(torch.cat([p.flatten() for p in agent.actor.parameters()]))
    assert torch.equal(weights[0], weights[1])
