"""Material tests of the flap in PyBullet: uniaxial tension, picture-frame shear, and a lift.

The flap's spring constant is derived from a Young's modulus and a thickness (:mod:`sim.material`);
these tests measure what the simulated sheet actually does, against the closed forms a materials lab
would use:

* uniaxial tension: a W x W sheet, one edge clamped, the opposite edge gripped and pulled quasi-statically
  to the target strain; expected ``F = E t W eps``;
* picture-frame shear (the standard in-plane shear test of fabrics and membranes): every edge node moved
  with the frame, ``x += gamma y``, so the sheet is in uniform simple shear; expected ``F = G t W gamma``
  with ``G = E / (2 (1 + nu))`` and the lattice's ``nu = 1/3``;
* lift (no closed form): the flap as in the environments, back and sides pinned, under gravity, the
  middle of its free edge raised; the curve on which the two models below are compared.

Two models of the same material: ``"spring"``, the flap the environments simulate (:mod:`sim.tissue`),
and ``"fem"``, PyBullet's Neo-Hookean tetrahedral plate (:mod:`sim.fem`) as a reference. The force is
what the moving grip must apply: minus the elastic forces on its nodes, computed from the node positions
with the model's own force law (the same way the retraction force is computed in the environments); the
lift leaves out the grasped nodes' own weight (a few mN) in both models. Only the lift has gravity; grips
are kinematic bodies the nodes are anchored to. Time step and ramp are set from the
material (the stable step of the lightest node, the period of the slowest mode), so every E, t and W
takes the same number of steps.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np

from sim.fem import FEM_POISSON_RATIO, FemSheet
from sim.material import LATTICE_POISSON_RATIO, MODELS, Model
from sim.quiet_pybullet import pybullet as p
from sim.tissue import Tissue, TissueParams

__all__ = ["MODELS", "MaterialTest", "Model", "lift", "picture_frame_shear", "uniaxial_tension"]

_POINTS = 10  # points on the force-strain curve
_SETTLE_PERIODS = 6.0  # slowest-mode periods of rest at each point
_RAMP_PERIODS = 3.0  # slowest-mode periods to ramp from one point to the next
_GRAVITY_M_S2 = 9.81
# Damping ratio of the slowest mode. Measured: at 0.7 the sheet still crept after 6 periods and the grips
# read 11 % more than the clamp (a viscous drag on the creeping nodes); at 0.2 both read the same.
_DAMPING_RATIO = 0.2


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


def uniaxial_tension(params: TissueParams, strain: float = 0.10, model: Model = "spring") -> MaterialTest:
    """Clamp the edge ``y = -W/2``, pull the edge ``y = +W/2`` to ``strain``; measure the force."""
    width = params.size_m
    expected = params.youngs_modulus_kpa * 1e3 * params.thickness_mm * 1e-3 * width

    def pulled(rest: np.ndarray, level: float) -> np.ndarray:
        return rest + np.array([0.0, level * width, 0.0])

    def top(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
        return rows == n - 1

    def bottom(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
        return rows == 0

    curve = _run(params, model, strain, gripped=top, move=pulled, measured=top, axis=1, clamped=bottom)
    return MaterialTest("uniaxial", strain, curve[-1][1], expected * strain, curve)


def picture_frame_shear(params: TissueParams, shear: float = 0.10, model: Model = "spring") -> MaterialTest:
    """Move every edge node with a frame sheared by ``shear`` (x += shear y); measure the shear force."""
    width = params.size_m
    poisson = LATTICE_POISSON_RATIO if model == "spring" else FEM_POISSON_RATIO
    shear_modulus = params.youngs_modulus_kpa * 1e3 / (2.0 * (1.0 + poisson))
    expected = shear_modulus * params.thickness_mm * 1e-3 * width

    def framed(rest: np.ndarray, level: float) -> np.ndarray:
        return rest + np.array([level * (rest[1] + width / 2.0), 0.0, 0.0])

    def edge(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
        return (rows == 0) | (rows == n - 1) | (cols == 0) | (cols == n - 1)

    def top(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
        return rows == n - 1

    curve = _run(params, model, shear, gripped=edge, move=framed, measured=top, axis=0, clamped=None)
    return MaterialTest("shear", shear, curve[-1][1], expected * shear, curve)


def lift(params: TissueParams, height_m: float = 0.03, model: Model = "spring") -> tuple[tuple[float, float], ...]:
    """The flap as in the environments (back and sides pinned, under gravity), its free edge's middle node
    lifted to ``height_m``: (lift [m], force on the grasp [N]) at every point. No closed form: this is the
    curve the two models are compared on.
    """

    def raised(rest: np.ndarray, level: float) -> np.ndarray:
        return rest + np.array([0.0, 0.0, level])

    def grasped(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
        return (rows == n - 1) & (cols == n // 2)

    def pinned(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
        return (rows == 0) | (cols == 0) | (cols == n - 1)

    return _run(
        params, model, height_m, gripped=grasped, move=raised, measured=grasped, axis=2, clamped=pinned, gravity=True
    )


Selector = Callable[[np.ndarray, np.ndarray, int], np.ndarray]


def _run(
    params: TissueParams,
    model: Model,
    target: float,
    *,
    gripped: Selector,
    move: Callable[[np.ndarray, float], np.ndarray],
    measured: Selector,
    axis: int,
    clamped: Selector | None,
    gravity: bool = False,
) -> tuple[tuple[float, float], ...]:
    """Ramp the grips through ``_POINTS`` levels up to ``target``; the settled grip force at each level.

    Nodes are chosen by their row and column in the grid (every layer of the FEM plate). With ``gravity``
    the sheet first settles under its weight (the grips hold their nodes where they are at rest).
    """
    client = p.connect(p.DIRECT)
    try:
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
        p.setGravity(0.0, 0.0, 0.0, physicsClientId=client)
        n = params.resolution
        slowest = math.pi / params.size_m * math.sqrt(params.youngs_modulus_kpa * 1e3 / params.density_kg_m3)
        damping_time_s = 2.0 * _DAMPING_RATIO / slowest  # stiffness-proportional: zeta = omega * time / 2
        sheet: Tissue | FemSheet
        if model == "spring":
            damping = damping_time_s * params.spring_stiffness_n_per_m
            sheet = Tissue(client, dataclasses.replace(params, damping=damping), np.zeros(3), pin_edges=False)
        else:
            sheet = FemSheet(client, dataclasses.replace(params, damping=damping_time_s), np.zeros(3))
        time_step = _stable_step(params)
        p.setPhysicsEngineParameter(fixedTimeStep=time_step, numSubSteps=0, physicsClientId=client)
        rows, cols = sheet.grid_rows, sheet.grid_cols
        if clamped is not None:
            for node in np.flatnonzero(clamped(rows, cols, n)):
                p.createSoftBodyAnchor(sheet.body_id, int(node), -1, -1, physicsClientId=client)
        period = 2.0 * math.pi / slowest
        settle_steps = max(1, round(_SETTLE_PERIODS * period / time_step))
        if gravity:
            p.setGravity(0.0, 0.0, -_GRAVITY_M_S2, physicsClientId=client)
            for _ in range(settle_steps):
                p.stepSimulation(physicsClientId=client)
        grips = [_grip(client, sheet, int(node)) for node in np.flatnonzero(gripped(rows, cols, n))]
        on_measured = np.flatnonzero(measured(rows, cols, n))
        ramp_steps = max(1, round(_RAMP_PERIODS * period / time_step))
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
            elastic = sheet.elastic_forces(sheet.positions())
            curve.append((end, float(-elastic[on_measured, axis].sum())))
        return tuple(curve)
    finally:
        p.disconnect(client)


def _stable_step(params: TissueParams) -> float:
    """A fifth of the period bound of the lightest node (a corner: a sixth of a cell) on its springs."""
    cell_m = params.size_m / (params.resolution - 1)
    corner_kg = params.density_kg_m3 * cell_m**2 * params.thickness_mm * 1e-3 / 6.0
    return 0.2 / math.sqrt(8.0 * params.spring_stiffness_n_per_m / corner_kg)


def _grip(client: int, sheet: Tissue | FemSheet, node: int) -> tuple[int, np.ndarray]:
    """A massless (kinematic) body where ``node`` is now, the node anchored to it; and that position."""
    at = sheet.positions()[node]
    body = p.createMultiBody(0.0, -1, -1, at.tolist(), physicsClientId=client)
    p.createSoftBodyAnchor(sheet.body_id, node, body, -1, physicsClientId=client)
    return int(body), at
