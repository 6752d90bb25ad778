"""Scripted-expert episodes for ``tissue-retract demo``: summary, demonstration file and video."""

from __future__ import annotations

import argparse
import json
from typing import Any

import imageio.v2 as imageio
import numpy as np

from psm_control import __version__
from psm_control.errors import ConfigurationError
from psm_control.inputs import check_output_path
from psm_control.outputs import atomic_path
from sim.registration import gym_id
from tissue_retract.cli._camera import tissue_params

__all__ = ["run_episodes"]


def run_episodes(args: argparse.Namespace) -> int:
    """Run the expert, print one line per episode, and write demos and a video if asked."""
    if args.episodes < 1:
        raise ConfigurationError("--episodes", args.episodes, "a positive number of episodes")
    if args.out:
        # numpy adds .npz to a name without it: the file checked is the file written.
        args.out = args.out if args.out.endswith(".npz") else f"{args.out}.npz"
        check_output_path(args.out, "--out", (args.texture,))
    if args.video:
        if not args.video.endswith((".gif", ".mp4")):
            raise ConfigurationError("--video", args.video, "a .gif or .mp4 file")
        check_output_path(args.video, "--video", (args.out, args.texture))
    from sim.envs import make  # PyBullet: once the outputs are checked
    from sim.expert import ScriptedExpert

    env = make(args.task, tissue=tissue_params(args.texture))
    expert = ScriptedExpert(env)
    kept: list[dict[str, Any]] = []
    frames: list[Any] = []
    successes = 0
    try:
        for index in range(args.episodes):
            seed = args.seed + index
            episode = _episode(env, expert, seed, frames if args.video and index == 0 else None)
            successes += int(episode["success"])
            print(
                f"episode {index} seed {seed}: site {episode['site']}, "
                f"{'success' if episode['success'] else 'failure'} in {len(episode['action'])} steps, "
                f"peak force {episode['peak_force_n']:.3f} N, max strain {episode['max_strain']:.2f}, "
                f"final exposure {episode['exposure']:.2f}, controller: {env.unwrapped.controller_name}"
            )
            if episode["success"]:
                kept.append(episode)
    finally:
        env.close()
    print(f"{gym_id(args.task)}: scripted expert succeeded in {successes}/{args.episodes} episodes")
    if args.out:
        _save(args.out, kept, gym_id(args.task), args.task, __version__)
        print(f"wrote {len(kept)} demonstrations to {args.out}")
    if args.video:
        timing: dict[str, Any] = {"duration": 50} if args.video.endswith(".gif") else {"fps": 20}
        with atomic_path(args.video, "--video") as temporary:
            imageio.mimsave(temporary, frames, **timing)
        print(f"wrote {len(frames)} frames to {args.video}")
    return 0


def _episode(env: Any, expert: Any, seed: int, frames: list[np.ndarray] | None) -> dict[str, Any]:
    observation, info = env.reset(seed=seed)
    expert.reset()
    observations, actions, rewards = [observation], [], []
    peak, strain = 0.0, 0.0
    if frames is not None:
        frames.append(env.unwrapped.render_frame().rgb)
    while True:
        action = expert(observation)
        observation, reward, terminated, truncated, info = env.step(action)
        observations.append(observation)
        actions.append(action)
        rewards.append(reward)
        peak, strain = max(peak, info["force_norm_n"]), max(strain, info["max_strain"])
        if frames is not None:
            frames.append(env.unwrapped.render_frame().rgb)
        if terminated or truncated:
            break
    return {
        "seed": seed,
        "site": info["site"],
        "success": bool(info["is_success"]) and not info["sim_unstable"],
        "observation": np.stack([o["observation"] for o in observations]),
        "achieved_goal": np.stack([o["achieved_goal"] for o in observations]),
        "desired_goal": np.stack([o["desired_goal"] for o in observations]),
        "action": np.stack(actions).astype(np.float32),
        "reward": np.asarray(rewards, dtype=np.float32),
        "peak_force_n": peak,
        "max_strain": strain,
        "exposure": info["exposure"],
        "randomization": info["randomization"],
    }


def _save(path: str, episodes: list[dict[str, Any]], env_id: str, task: str, version: str) -> None:
    metadata = {
        "task": task,
        "gym_id": env_id,
        "seeds": [e["seed"] for e in episodes],
        "sites": [e["site"] for e in episodes],
        "randomization": [e["randomization"] for e in episodes],
        "package_version": version,
        "source": "sim.expert.ScriptedExpert",
        "layout": "observation (E,T+1,18), achieved_goal/desired_goal (E,T+1,G), action (E,T,5), reward (E,T)",
    }
    arrays: dict[str, Any] = {
        key: np.stack([e[key] for e in episodes]) if episodes else np.zeros((0,))
        for key in ("observation", "achieved_goal", "desired_goal", "action", "reward")
    }
    with atomic_path(path, "--out") as temporary:
        np.savez_compressed(
            temporary,
            **arrays,
            seed=np.array([e["seed"] for e in episodes], dtype=np.int64),
            metadata=json.dumps(metadata),
        )
