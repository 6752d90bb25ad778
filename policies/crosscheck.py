"""Cross-check of our DDPG+HER against Stable-Baselines3's DDPG+HER on Task I (``TissueRetract-Lift-v0``).

SB3's ``DDPG`` with a ``HerReplayBuffer`` is trained with settings matched to our defaults (the seed
paper's) as far as SB3 allows, for the same number of training episodes, and its deterministic actor
is then scored by *our* evaluation (:func:`sim.evaluation.run_episode` on seeds ``S * 100000 + i``, as
``tissue-retract evaluate --seeds S`` does), so both learners pass through the same full safety chain.

Matched: 3 x 128 ReLU actor and critic, gamma 0.99, learning rate 1e-3, tau 0.005, batch 128, buffer
100k, 1,000 uniformly random seed steps, 40 gradient steps after each episode, Gaussian action noise
0.1, HER ``future`` with k = 4 (relabel probability 0.8 in both).
Not matched, because SB3's DDPG has no such option: our running normalisation of observations and goals
(clip 5), our clipping of the target Q to [-1/(1-gamma), 0] and our actor's action penalty mean(a^2).
By default SB3 sees the raw observations; ``--normalize`` wraps its env in ``VecNormalize`` (running
mean and standard deviation of every observation entry, clipped to +-5 like ours, rewards untouched),
which takes the largest of these differences out of the comparison. SB3's replay buffer then keeps raw
observations and normalises sampled batches, so HER's relabelled rewards are computed on raw goals.
SB3's ``MultiInputPolicy`` also feeds the networks all three dict entries (``achieved_goal`` too); ours
feeds ``observation`` and ``desired_goal``.

Run as ``python -m policies.crosscheck --episodes 300 --seed 1 --out runs/crosscheck/sb3``. Needs the
``dev`` extra (``pip install -e .[dev]``), which brings stable-baselines3.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

import sim.envs
from psm_control.errors import ConfigurationError
from sim.envs import MAX_EPISODE_STEPS
from sim.evaluation import FAILURE_CLASSES, run_episode
from sim.strict_json import write_strict_json
from sim.sweep import wilson_interval

__all__ = ["TASK_ID", "crosscheck_sb3", "main"]

TASK_ID = "TissueRetract-Lift-v0"


def crosscheck_sb3(
    episodes: int = 300,
    seed: int = 1,
    eval_episodes: int = 50,
    eval_seed: int = 1,
    learning_starts: int = 1000,
    gradient_steps: int = 40,
    out: str | Path | None = None,
    normalize: bool = False,
) -> dict[str, Any]:
    """Train SB3 DDPG+HER on Task I for ``episodes`` episodes and evaluate it with our evaluation.

    Args:
        episodes: Training episodes (the budget; 50 env steps each unless an episode ends early).
        seed: Seed of SB3's model (torch, NumPy, action space) and of its training env.
        eval_episodes: Evaluation episodes, on seeds ``eval_seed * 100000 + i``.
        eval_seed: Evaluation seed, as ``tissue-retract evaluate --seeds``.
        learning_starts: Uniformly random env steps before learning (1,000 = ours).
        gradient_steps: Gradient steps after each episode (40 = ours).
        out: If given, the SB3 model (``sb3_ddpg_her.zip``), ``result.json`` and, with ``normalize``,
            the normalisation statistics (``vecnormalize.pkl``) are written there.
        normalize: Normalise SB3's observations with ``VecNormalize`` (clip 5), frozen for evaluation.

    Returns:
        ``successes``, ``eval_episodes``, ``success_rate``, ``ci95`` (Wilson, low/high),
        ``train_episodes``, ``env_steps``, ``train_wall_s``, ``env_steps_per_s`` (training, including
        updates), ``eval_wall_s``, ``failure_classes`` (as ``evaluate``'s JSON), ``seed``, ``eval_seed``
        and ``settings``.

    Raises:
        ConfigurationError: A count is not positive, or stable-baselines3 is not installed.
    """
    for name, value in (("episodes", episodes), ("eval_episodes", eval_episodes)):
        if value < 1:
            raise ConfigurationError(name, value, "a positive number of episodes")
    try:  # the dev extra: optional, so imported only for the cross-check
        from stable_baselines3 import DDPG, HerReplayBuffer
        from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes
        from stable_baselines3.common.logger import Logger
        from stable_baselines3.common.noise import NormalActionNoise
        from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize
    except ImportError as e:
        raise ConfigurationError(
            "stable_baselines3", None, "stable-baselines3 installed: pip install -e .[dev] (the dev extra)"
        ) from e

    settings: dict[str, Any] = dict(
        learning_rate=1e-3,
        buffer_size=100_000,
        learning_starts=learning_starts,
        batch_size=128,
        tau=0.005,
        gamma=0.99,
        train_freq=(1, "episode"),
        gradient_steps=gradient_steps,
        replay_buffer_kwargs=dict(goal_selection_strategy="future", n_sampled_goal=4),
        policy_kwargs=dict(net_arch=dict(pi=[128, 128, 128], qf=[128, 128, 128])),
        action_noise_sigma=0.1,
        normalize=normalize,
    )
    env = sim.envs.make(TASK_ID)
    action_dim = int(env.action_space.shape[0])
    normalizer = None
    if normalize:
        normalizer = VecNormalize(DummyVecEnv([lambda: env]), norm_obs=True, norm_reward=False, clip_obs=5.0)
    sb3_kwargs = {k: v for k, v in settings.items() if k not in ("action_noise_sigma", "normalize")}
    noise = NormalActionNoise(np.zeros(action_dim), settings["action_noise_sigma"] * np.ones(action_dim))
    model = DDPG(
        "MultiInputPolicy",
        normalizer if normalizer is not None else env,
        replay_buffer_class=HerReplayBuffer,
        action_noise=noise,
        seed=seed,
        **sb3_kwargs,
    )
    # A logger of our own that writes nothing: SB3's default one creates an empty SB3-<time> folder in the
    # system's temporary directory on every learn() and never removes it.
    model.set_logger(Logger(folder=None, output_formats=[]))
    start = time.perf_counter()
    model.learn(total_timesteps=episodes * MAX_EPISODE_STEPS, callback=StopTrainingOnMaxEpisodes(episodes, verbose=0))
    train_wall_s = time.perf_counter() - start
    if normalizer is not None:
        normalizer.training = False  # evaluation must neither update nor depend on its own statistics
    env.close()

    eval_env = sim.envs.make(TASK_ID)
    try:

        def policy(observation: dict[str, np.ndarray]) -> np.ndarray:
            seen = normalizer.normalize_obs(observation) if normalizer is not None else observation
            action, _ = model.predict(seen, deterministic=True)
            return np.asarray(action)

        start = time.perf_counter()
        seeds = [eval_seed * 100000 + i for i in range(eval_episodes)]
        results = [run_episode(eval_env, policy, lambda: None, s) for s in seeds]
        eval_wall_s = time.perf_counter() - start
    finally:
        eval_env.close()
    successes = sum(r.success for r in results)
    result: dict[str, Any] = {
        "successes": successes,
        "eval_episodes": eval_episodes,
        "success_rate": successes / eval_episodes,
        "ci95": list(wilson_interval(successes, eval_episodes)),
        "train_episodes": episodes,
        "env_steps": int(model.num_timesteps),
        "train_wall_s": train_wall_s,
        "env_steps_per_s": model.num_timesteps / train_wall_s,
        "eval_wall_s": eval_wall_s,
        "failure_classes": {c: sum(r.failure_class == c for r in results) for c in FAILURE_CLASSES},
        "seed": seed,
        "eval_seed": eval_seed,
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in settings.items()},
    }
    if out is not None:
        directory = Path(out)
        directory.mkdir(parents=True, exist_ok=True)
        model.save(directory / "sb3_ddpg_her.zip")
        write_strict_json(directory / "result.json", result)
        if normalizer is not None:
            normalizer.save(str(directory / "vecnormalize.pkl"))
    return result


def main(argv: list[str] | None = None) -> int:
    """Command line: train and evaluate SB3 DDPG+HER on Task I and print a table."""
    parser = argparse.ArgumentParser(prog="python -m policies.crosscheck", description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=300, help="training episodes (default: 300)")
    parser.add_argument("--seed", type=int, default=1, help="training seed (default: 1)")
    parser.add_argument("--eval-episodes", type=int, default=50, help="evaluation episodes (default: 50)")
    parser.add_argument("--eval-seed", type=int, default=1, help="evaluation seed (default: 1)")
    parser.add_argument("--out", default=None, help="directory for the SB3 model and result.json")
    parser.add_argument("--normalize", action="store_true", help="normalise SB3's observations (VecNormalize)")
    args = parser.parse_args(argv)

    torch.set_num_threads(1)
    r = crosscheck_sb3(
        args.episodes, args.seed, args.eval_episodes, args.eval_seed, out=args.out, normalize=args.normalize
    )
    low, high = r["ci95"]
    inputs = "VecNormalize" if args.normalize else "raw observations"
    print(f"SB3 DDPG+HER on {TASK_ID}, seed {r['seed']}, {r['train_episodes']} training episodes, {inputs}")
    print(f"{'metric':<28}{'value':>22}")
    print(f"{'success (eval)':<28}{r['successes']:>10}/{r['eval_episodes']} = {r['success_rate']:.2f}")
    print(f"{'95 % Wilson interval':<28}{f'[{low:.2f}, {high:.2f}]':>22}")
    print(f"{'env steps (training)':<28}{r['env_steps']:>22}")
    print(f"{'training wall time [s]':<28}{r['train_wall_s']:>22.1f}")
    print(f"{'env steps/s (with updates)':<28}{r['env_steps_per_s']:>22.1f}")
    print(f"{'evaluation wall time [s]':<28}{r['eval_wall_s']:>22.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
