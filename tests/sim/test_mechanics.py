"""Tissue mechanics: gravity acts, and the grasp-force estimate matches a known answer."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from sim.mechanics import grasp_force, spring_strain
from sim.tissue import Tissue, TissueParams


def _world(gravity: float) -> int:
    client = p.connect(p.DIRECT)
    p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
    p.setGravity(0.0, 0.0, -gravity, physicsClientId=client)
    p.setPhysicsEngineParameter(fixedTimeStep=1 / 240, numSolverIterations=10, physicsClientId=client)
    return client


def _settle(client: int, seconds: float) -> None:
    for _ in range(round(seconds * 240)):
        p.stepSimulation(physicsClientId=client)


def test_gravity_makes_the_flap_sag() -> None:
    """With gravity the pinned flap's free edge sags by millimetres; without it the flap stays flat."""
    sags = []
    for gravity in (9.81, 0.0):
        client = _world(gravity)
        tissue = Tissue(client, TissueParams(), np.zeros(3))
        _settle(client, 1.0)
        sags.append(-tissue.positions()[:, 2].min())
        p.disconnect(client)
    assert sags[0] > 0.003
    assert abs(sags[1]) < 1e-5


def test_env_scene_has_gravity_on() -> None:
    """The environment's world has gravity on after its reset (the paper's code silently lost it)."""
    from tests.sim.conftest import make_env

    env = make_env("lift")
    try:
        env.reset(seed=0)
        u = env.unwrapped
        gravity = p.getPhysicsEngineParameters(physicsClientId=u.client)["gravityAccelerationZ"]
        assert gravity == pytest.approx(-u.values["gravity_m_s2"])
        assert u.scene.tissue.positions()[:, 2].min() < u.scene.tissue_origin[2] - 0.003
    finally:
        env.close()


@pytest.mark.parametrize("grasped", [[45], [44, 45, 46]])
def test_force_estimate_carries_a_hanging_flap(grasped: list[int]) -> None:
    """A free flap hung from the grasp: the estimated force equals its weight within 10 %."""
    params = TissueParams()
    client = _world(9.81)
    try:
        tissue = Tissue(client, params, np.zeros(3), pin_edges=False)
        shape = p.createCollisionShape(p.GEOM_SPHERE, radius=0.001, physicsClientId=client)
        start = tissue.positions()[grasped].mean(axis=0)
        holder = p.createMultiBody(0.0, shape, basePosition=start.tolist(), physicsClientId=client)
        for node in grasped:
            p.createSoftBodyAnchor(tissue.body_id, node, holder, -1, physicsClientId=client)
        _settle(client, 5.0)
        nodes = tissue.positions()
        force = grasp_force(
            nodes,
            tissue.edges,
            tissue.rest_lengths,
            params.spring_stiffness_n_per_m,
            np.array(grasped),
            tissue.node_mass_kg,
            np.array([0, 0, -9.81]),
        )
        weight = params.mass_kg * 9.81
        assert nodes[:, 2].min() < start[2] - 0.06  # it really hangs
        assert force[2] == pytest.approx(-weight, rel=0.10)
        assert np.hypot(force[0], force[1]) < 0.1 * weight
    finally:
        p.disconnect(client)


def test_strain_of_a_uniform_stretch() -> None:
    """Stretching every node by 10 % about the centre gives a strain of 0.1 in every spring."""
    tissue_params = TissueParams()
    client = _world(0.0)
    try:
        tissue = Tissue(client, tissue_params, np.zeros(3))
        strain = spring_strain(tissue.rest_positions * 1.1, tissue.edges, tissue.rest_lengths)
        np.testing.assert_allclose(strain, 0.1, atol=1e-9)
    finally:
        p.disconnect(client)


def test_flap_never_falls_asleep() -> None:
    """After 5 s at rest (Bullet sleeps a body after 2 s), lifting one node still drags its neighbours."""
    client = _world(9.81)
    try:
        tissue = Tissue(client, TissueParams(), np.zeros(3))
        _settle(client, 5.0)
        start = tissue.positions()
        node, neighbour = 45, 44
        holder = p.createMultiBody(0.0, -1, basePosition=start[node].tolist(), physicsClientId=client)
        p.createSoftBodyAnchor(tissue.body_id, node, holder, -1, physicsClientId=client)
        for step in range(240):
            lifted = start[node] + np.array([0.0, 0.0, 0.02 * (step + 1) / 240])
            p.resetBasePositionAndOrientation(holder, lifted.tolist(), (0, 0, 0, 1), physicsClientId=client)
            p.stepSimulation(physicsClientId=client)
        rise = tissue.positions()[[node, neighbour], 2] - start[[node, neighbour], 2]
        assert rise[0] > 0.019
        assert rise[1] > 0.005  # a sleeping flap leaves it where it was
    finally:
        p.disconnect(client)
