"""The task scene behind sim-dvrk: an idle scene costs no physics, and wakes on the next set-point."""

from __future__ import annotations

import numpy as np

from hardware_if.console.sim_task import REST_AFTER_STEPS, TaskArm


def test_an_idle_scene_sleeps_and_a_new_setpoint_wakes_it() -> None:
    """With a still set-point and a still flap the scene stops being stepped; a new set-point steps it again."""
    arm = TaskArm("lift", seed=2)
    try:
        arm.reset(arm.home_q, 0.6)
        for _ in range(4 * REST_AFTER_STEPS):
            arm.step(1.0 / 100.0)
            if arm.at_rest:
                break
        assert arm.at_rest, "a still scene never went to rest"
        nodes = arm.env.scene.tissue.positions().copy()
        for _ in range(50):
            sample = arm.step(1.0 / 100.0)
        assert np.array_equal(arm.env.scene.tissue.positions(), nodes), "a sleeping scene was stepped"
        assert np.allclose(sample.qd, 0.0)
        goal = arm.home_q.copy()
        goal[2] += 0.01
        arm.command(goal, 0.6)
        for _ in range(20):
            sample = arm.step(1.0 / 100.0)
        assert not arm.at_rest and abs(sample.q[2] - goal[2]) < 1e-3, "the arm did not follow a new set-point"
    finally:
        arm.close()


def test_a_held_flap_at_rest_sleeps_and_stays_held() -> None:
    """Jaws closed on the site hold the flap; once still it is not stepped, and it is still held after."""
    arm = TaskArm("lift", seed=2)
    try:
        q = arm.jaws_on("site")
        arm.reset(q, 0.6)
        arm.step(1.0 / 100.0)
        arm.command(q, 0.0)
        for _ in range(6 * REST_AFTER_STEPS):
            arm.step(1.0 / 100.0)
            if arm.at_rest:
                break
        assert arm.env.scene.grasp.holding, "the closed jaws did not hold the flap"
        assert arm.at_rest, "a held, still flap never went to rest"
        nodes = arm.env.scene.tissue.positions().copy()
        for _ in range(50):
            arm.step(1.0 / 100.0)
        assert np.array_equal(arm.env.scene.tissue.positions(), nodes) and arm.env.scene.grasp.holding
    finally:
        arm.close()
