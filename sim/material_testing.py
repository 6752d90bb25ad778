"""Material tests of the flap in PyBullet: uniaxial tension and picture-frame shear.

The flap's spring constant is derived from a Young's modulus and a thickness (:mod:`sim.material`);
these tests measure what the simulated sheet actually does, against the closed forms a materials lab
would use:

* uniaxial tension: a W x W sheet, one edge clamped, the opposite edge gripped and pulled quasi-statically
  to the target strain; expected ``F = E t W eps``;
* picture-frame shear (the standard in-plane shear test of fabrics and membranes): every edge node moved
  with the frame, ``x += gamma y``, so the sheet is in uniform simple shear; expected ``F = G t W gamma``
  with ``G = E / (2 (1 + nu))`` and the lattice's ``nu = 1/3``.

The force is the exact sum of the spring tensions across the sheet's middle row, as the retraction force
is computed in the environments (:func:`sim.mechanics.grasp_force`). There is no gravity; grips are
kinematic bodies the nodes are anchored to. Time step and ramp are set from the material (the stable
step of the stiffest node, the period of the slowest mode), so every E, t and W takes the same number of
steps.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np
import pybullet as p

from sim.material import LATTICE_POISSON_RATIO
from sim.mechanics import grasp_force
from sim.tissue import Tissue, TissueParams

__all__ = ["MaterialTest", "picture_frame_shear", "uniaxial_tension"]

_POINTS = 10  # points on the force-strain curve
_SETTLE_PERIODS = 6.0  # slowest-mode periods of rest at each point
_RAMP_PERIODS = 3.0  # slowest-mode periods to ramp from one point to the next
_DAMPING_RATIO = 0.7  # of the slowest mode, by the springs' own (stiffness-proportional) damping


class MaterialTest(NamedTuple):
    """The outcome of one material test.

    Attributes:
        kind: ``"uniaxial"`` or ``"shear"``.
        strain: Final nominal strain (tension) or shear angle (shear).
        force_n: Measured force at that strain [N].
        expected_force_n: The closed form at that strain [N].
        curve: (strain, force [N]) at every point of the quasi-static ramp.
    """

    kind: Literal["uniaxial", "shear"]
    strain: float
    force_n: float
    expected_force_n: float
    curve: tuple[tuple[float, float], ...]

    @property
    def relative_error(self) -> float:
        """(measured - expected) / expected."""
        return self.force_n / self.expected_force_n - 1.0

    def to_dict(self) -> dict[str, object]:
        """JSON-ready fields."""
        return {
            "strain": self.strain,
            "force_n": self.force_n,
            "expected_force_n": self.expected_force_n,
            "relative_error": self.relative_error,
            "curve": [list(point) for point in self.curve],
        }


def uniaxial_tension(params: TissueParams, strain: float = 0.10) -> MaterialTest:
    """Clamp the edge ``y = -W/2``, pull the edge ``y = +W/2`` to ``strain``; measure the force."""
    width = params.size_m
    expected = params.youngs_modulus_kpa * 1e3 * params.thickness_mm * 1e-3 * width

    def pulled(rest: np.ndarray, level: float) -> np.ndarray:
        return rest + np.array([0.0, level * width, 0.0])

    curve = _run(params, strain, lambda rows, cols, n: rows == n - 1, pulled, axis=1, clamp=lambda rows, n: rows == 0)
    return MaterialTest("uniaxial", strain, curve[-1][1], expected * strain, curve)


def picture_frame_shear(params: TissueParams, shear: float = 0.10) -> MaterialTest:
    """Move every edge node with a frame sheared by ``shear`` (x += shear y); measure the shear force."""
    width = params.size_m
    shear_modulus = params.youngs_modulus_kpa * 1e3 / (2.0 * (1.0 + LATTICE_POISSON_RATIO))
    expected = shear_modulus * params.thickness_mm * 1e-3 * width

    def framed(rest: np.ndarray, level: float) -> np.ndarray:
        return rest + np.array([level * (rest[1] + width / 2.0), 0.0, 0.0])

    def edge(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
        return (rows == 0) | (rows == n - 1) | (cols == 0) | (cols == n - 1)

    curve = _run(params, shear, edge, framed, axis=0, clamp=None)
    return MaterialTest("shear", shear, curve[-1][1], expected * shear, curve)


def _run(
    params: TissueParams,
    target: float,
    gripped: Callable[[np.ndarray, np.ndarray, int], np.ndarray],
    move: Callable[[np.ndarray, float], np.ndarray],
    *,
    axis: int,
    clamp: Callable[[np.ndarray, int], np.ndarray] | None,
) -> tuple[tuple[float, float], ...]:
    """Ramp the grips through ``_POINTS`` levels up to ``target``; the settled cut force at each level."""
    client = p.connect(p.DIRECT)
    try:
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
        p.setGravity(0.0, 0.0, 0.0, physicsClientId=client)
        n, k = params.resolution, params.spring_stiffness_n_per_m
        slowest = math.pi / params.size_m * math.sqrt(params.youngs_modulus_kpa * 1e3 / params.density_kg_m3)
        damped = dataclasses.replace(params, damping=2.0 * _DAMPING_RATIO * k / slowest)
        tissue = Tissue(client, damped, np.zeros(3), pin_edges=False)
        time_step = 0.2 / math.sqrt(8.0 * k / float(tissue.node_mass_kg.min()))
        p.setPhysicsEngineParameter(fixedTimeStep=time_step, numSubSteps=0, physicsClientId=client)
        rows, cols = np.divmod(np.arange(n * n), n)
        if clamp is not None:
            for node in np.flatnonzero(clamp(rows, n)):
                p.createSoftBodyAnchor(tissue.body_id, int(node), -1, -1, physicsClientId=client)
        grips = [
            (_grip(client, tissue, int(node)), tissue.rest_positions[node])
            for node in np.flatnonzero(gripped(rows, cols, n))
        ]
        period = 2.0 * math.pi / slowest
        ramp_steps = max(1, round(_RAMP_PERIODS * period / time_step))
        settle_steps = max(1, round(_SETTLE_PERIODS * period / time_step))
        upper = np.flatnonzero(rows >= n // 2)
        curve = []
        level = 0.0
        for point in range(1, _POINTS + 1):
            start, end = level, target * point / _POINTS
            for step in range(ramp_steps + settle_steps):
                level = start + (end - start) * min(1.0, (step + 1) / ramp_steps)
                for body, rest in grips:
                    p.resetBasePositionAndOrientation(
                        body, move(rest, level).tolist(), (0, 0, 0, 1), physicsClientId=client
                    )
                p.stepSimulation(physicsClientId=client)
            nodes = tissue.positions()
            pull = grasp_force(nodes, tissue.edges, tissue.rest_lengths, k, upper, tissue.node_mass_kg, np.zeros(3))
            curve.append((end, float(-pull[axis])))
        return tuple(curve)
    finally:
        p.disconnect(client)


def _grip(client: int, tissue: Tissue, node: int) -> int:
    """A massless (kinematic) body at ``node``, the node anchored to it."""
    body = p.createMultiBody(0.0, -1, -1, tissue.rest_positions[node].tolist(), physicsClientId=client)
    p.createSoftBodyAnchor(tissue.body_id, node, body, -1, physicsClientId=client)
    return int(body)
