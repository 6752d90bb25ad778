"""HER replay and normalisation."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv

from policies.buffers import Episode, EpisodeBuffer
from policies.normalizer import Normalizer
from policies.toy_env import ToyReachEnv


def _episode(rng: np.random.Generator, T: int = 50) -> Episode:
    ag = np.cumsum(rng.normal(0, 0.05, (T + 1, 3)), axis=0).astype(np.float32)
    obs = np.concatenate((ag, np.ones((T + 1, 1))), axis=1).astype(np.float32)
    goal = np.repeat(rng.uniform(-0.3, 0.3, (1, 3)), T, axis=0).astype(np.float32)
    return Episode(obs, ag, goal, rng.uniform(-1, 1, (T, 5)).astype(np.float32), np.zeros(T, bool))


@pytest.fixture
def filled() -> EpisodeBuffer:
    rng = np.random.default_rng(0)
    buffer = EpisodeBuffer(10_000, 50, 4, 3, 5)
    for _ in range(20):
        buffer.add(_episode(rng))
    return buffer


def test_relabelled_rewards_agree_with_compute_reward(filled: EpisodeBuffer) -> None:
    """Every sampled reward equals the env's compute_reward of the next achieved goal and the (relabelled) goal."""
    env = ToyReachEnv()
    batch = filled.sample(4096, np.random.default_rng(1), env.compute_reward, 0.8)
    next_achieved = batch.next_obs[:, :3]
    np.testing.assert_array_equal(batch.reward, env.compute_reward(next_achieved, batch.goal, {}))
    assert (batch.reward == 0).mean() > 0.05  # relabelling makes successes out of failures


def test_relabelled_goals_come_from_the_future_of_the_same_episode(filled: EpisodeBuffer) -> None:
    """A relabelled goal is an achieved goal at a step t' + 1 with t' >= t of the transition's own episode."""
    rng = np.random.default_rng(2)
    batch = filled.sample(2000, rng, ToyReachEnv().compute_reward, 1.0)
    for i in range(len(batch.goal)):
        match = np.argwhere((filled.obs[: filled.size] == batch.obs[i]).all(-1))
        ep, t = match[0]
        future = filled.achieved_goal[ep, t + 1 : filled.length[ep] + 1]
        assert (future == batch.goal[i]).all(-1).any()


def test_relabel_fraction_matches_k() -> None:
    """With k = 4 about 80 % of goals are relabelled, and with probability 0 none are."""
    rng = np.random.default_rng(3)
    buffer = EpisodeBuffer(10_000, 50, 4, 3, 5)
    for _ in range(10):
        e = _episode(rng)
        buffer.add(e._replace(desired_goal=np.full_like(e.desired_goal, 100.0)))
    fn = ToyReachEnv().compute_reward
    relabelled = (buffer.sample(20_000, rng, fn, 0.8).goal != 100.0).all(-1)
    assert 0.78 < relabelled.mean() < 0.82
    assert (buffer.sample(2000, rng, fn, 0.0).goal == 100.0).all()


def test_future_offsets_match_stable_baselines3() -> None:
    """The distribution of relabelling offsets (t' - t) agrees with SB3's HerReplayBuffer (future, k=4)."""
    T = 50
    env = DummyVecEnv([lambda: ToyReachEnv()])
    assert isinstance(env.observation_space, spaces.Dict)
    sb3 = HerReplayBuffer(
        5 * T, env.observation_space, env.action_space, env=env, n_sampled_goal=4, goal_selection_strategy="future"
    )
    ours = EpisodeBuffer(5 * T, T, 4, 3, 5)
    # One episode whose achieved goal encodes the step index, so a sampled goal reveals t'.
    ag = np.zeros((T + 1, 3), np.float32)
    ag[:, 0] = np.arange(T + 1)
    obs = np.zeros((T + 1, 4), np.float32)
    obs[:, 1] = np.arange(T + 1)
    goal = np.full((T, 3), -1.0, np.float32)
    ours.add(Episode(obs, ag, goal, np.zeros((T, 5), np.float32), np.zeros(T, bool)))
    for t in range(T):
        o = {"observation": obs[t : t + 1], "achieved_goal": ag[t : t + 1], "desired_goal": goal[t : t + 1]}
        n = {"observation": obs[t + 1 : t + 2], "achieved_goal": ag[t + 1 : t + 2], "desired_goal": goal[t : t + 1]}
        sb3.add(o, n, np.zeros((1, 5)), np.zeros(1), np.array([t == T - 1]), [{"TimeLimit.truncated": t == T - 1}])
    np.random.seed(0)
    theirs = sb3.sample(20_000)
    t_sb3 = theirs.observations["observation"].numpy()[..., 1].reshape(-1)
    g_sb3 = theirs.observations["desired_goal"].numpy()[..., 0].reshape(-1)
    relabelled = g_sb3 >= 0
    off_sb3 = g_sb3[relabelled] - t_sb3[relabelled] - 1
    mine = ours.sample(20_000, np.random.default_rng(0), ToyReachEnv().compute_reward, 0.8)
    relab = mine.goal[:, 0] >= 0
    off_ours = mine.goal[relab, 0] - mine.obs[relab, 1] - 1
    assert off_sb3.min() == off_ours.min() == 0
    assert off_sb3.max() <= T - 1 and off_ours.max() <= T - 1
    assert abs(relabelled.mean() - relab.mean()) < 0.02
    assert abs(off_sb3.mean() - off_ours.mean()) < 0.6
    hist_sb3 = np.bincount(off_sb3.astype(int), minlength=T) / len(off_sb3)
    hist_ours = np.bincount(off_ours.astype(int), minlength=T) / len(off_ours)
    assert np.abs(np.cumsum(hist_sb3) - np.cumsum(hist_ours)).max() < 0.03


def test_buffer_overwrites_oldest_and_round_trips(filled: EpisodeBuffer) -> None:
    """A full buffer overwrites its oldest episode, and state() -> load_state() restores it exactly."""
    small = EpisodeBuffer(100, 50, 4, 3, 5)
    rng = np.random.default_rng(4)
    episodes = [_episode(rng) for _ in range(3)]
    for e in episodes:
        small.add(e)
    assert len(small) == 2
    np.testing.assert_array_equal(small.obs[0], episodes[2].obs)
    copy = EpisodeBuffer(10_000, 50, 4, 3, 5)
    copy.load_state(filled.state())
    for key, value in filled.state().items():
        np.testing.assert_array_equal(copy.state()[key], value)


def test_normalizer_standardises_and_clips() -> None:
    """The normaliser gives zero mean, unit std on its data, clips to +-clip and floors the std at eps."""
    rng = np.random.default_rng(5)
    data = rng.normal(3.0, 2.0, (10_000, 2))
    data[:, 1] = 7.0
    norm = Normalizer(2, eps=0.01, clip=5.0)
    norm.update(data)
    out = norm(data)
    assert abs(out[:, 0].mean()) < 1e-3 and abs(out[:, 0].std() - 1) < 1e-3
    assert np.allclose(norm.std[1], 0.01)
    assert np.abs(norm(np.array([[1e6, -1e6]]))).max() <= 5.0
