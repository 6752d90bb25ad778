"""The scene's kinematic arm: never simulated, moved between episodes, copied into the world only to be drawn."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

import sim.grasp
from psm_control.robot import PsmModel
from sim.expert import ScriptedExpert
from sim.psm_body import PsmBody
from sim.rendering import CLASSES
from tests.sim.conftest import make_env


def _actions(count: int, seed: int) -> list[np.ndarray]:
    """Random actions that close the jaw every third step, so that grasps happen."""
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, (count, 5)).astype(np.float32)
    actions[::3, 4] = -1.0
    return list(actions)


def test_the_arm_stays_where_it_was_set() -> None:
    """After every step the grasp point is exactly where the arm's set joints put it (no sag), and no
    body in the physics client has joints (the arm is not simulated)."""
    env = make_env("multisite")
    try:
        env.reset(seed=4)
        u = env.unwrapped
        for action in _actions(30, seed=4):
            env.step(action)
            grasp = u.scene.grasp_position()
            u.scene.body.reset_joints(u.backend.q, u.backend.jaw)
            np.testing.assert_array_equal(u.scene.grasp_position(), grasp)
        count = p.getNumBodies(physicsClientId=u.client)
        bodies = [p.getBodyUniqueId(i, physicsClientId=u.client) for i in range(count)]
        assert all(p.getNumJoints(body, physicsClientId=u.client) == 0 for body in bodies)
    finally:
        env.close()


def test_drawing_frames_changes_no_episode() -> None:
    """The same seed and actions give the same observations and infos whether every step is drawn or not."""
    traces = []
    for draw in (False, True):
        env = make_env("lift")
        try:
            obs, _ = env.reset(seed=9)
            u = env.unwrapped
            bodies = p.getNumBodies(physicsClientId=u.client)
            trace = [obs["observation"]]
            for action in _actions(25, seed=9):
                obs, reward, _, _, info = env.step(action)
                if draw:
                    frame = u.render_frame()
                    assert CLASSES.index("instrument") in frame.labels
                    assert p.getNumBodies(physicsClientId=u.client) == bodies  # the arm's copy is gone
                trace += [obs["observation"], reward, info["force_n"], info["grasped"], info["max_strain"]]
            traces.append(trace)
        finally:
            env.close()
    for drawn, plain in zip(traces[1], traces[0], strict=True):
        np.testing.assert_array_equal(drawn, plain)


def test_a_moved_arm_is_one_loaded_there() -> None:
    """An arm moved to an RCM has, bit for bit, the link poses of an arm loaded at that RCM."""
    model = PsmModel()
    client = p.connect(p.DIRECT)
    try:
        rcm = np.array([0.004, 0.027, 0.16])
        moved = PsmBody(client, model)
        moved.move_base(rcm)
        loaded = PsmBody(client, model, rcm)
        q = model.home() + np.array([0.2, -0.1, 0.01, 0.3, -0.4, 0.2])
        for body in (moved, loaded):
            body.reset_joints(q, 0.4)
        for link in loaded.link_index:
            np.testing.assert_array_equal(moved.link_pose(link), loaded.link_pose(link), err_msg=link)
        joints, jaw = moved.joint_states()
        np.testing.assert_array_equal(joints, q)
        assert jaw == 0.4
    finally:
        p.disconnect(client)


def _expert_episode(seed: int) -> tuple[float, bool, int]:
    """Peak force [N], success and length of one scripted Task III episode."""
    env = make_env("multisite")
    try:
        expert = ScriptedExpert(env)
        obs, _ = env.reset(seed=seed)
        expert.reset()
        peak, steps, done = 0.0, 0, False
        while not done:
            obs, _, terminated, truncated, info = env.step(expert(obs))
            peak, steps, done = max(peak, info["force_peak_n"]), steps + 1, terminated or truncated
        return peak, bool(info["is_success"]), steps
    finally:
        env.close()


def test_a_grasp_a_sag_away_gives_the_same_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    """Grasps closed 0.2 um off the grasp point (the most the simulated arm used to sag between set-points)
    change an expert episode's peak force by under 1e-4 N, and neither its success nor its length."""
    exact = [_expert_episode(seed) for seed in (7700000, 7700002)]
    update = sim.grasp.Grasp.update
    sag = np.array([1.2e-7, -0.8e-7, -1.4e-7])  # 0.2 um
    monkeypatch.setattr(sim.grasp.Grasp, "update", lambda self, jaw, at, *rest: update(self, jaw, at + sag, *rest))
    sagged = [_expert_episode(seed) for seed in (7700000, 7700002)]
    for (peak, success, steps), (peak_sagged, success_sagged, steps_sagged) in zip(exact, sagged, strict=True):
        assert (success, steps) == (success_sagged, steps_sagged)
        assert abs(peak - peak_sagged) < 1e-4
