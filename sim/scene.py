"""The retraction scene: table, hidden tissue, flap and jaw in one physics client, the PSM beside it.

SI units, z up, gravity on. The table top is the ``z = 0`` plane; the hidden tissue is a rigid box
(with collision) under the front half of the flap; the flap's three pinned edges sit just above it.
The PSM's RCM is at a port above the flap with the tool pointing down, so the home insertion puts
the tool tip about 2 cm above the flap. The world is rebuilt on every reset, because PyBullet cannot
reset a soft body's nodes.

The arm is kinematic: its joints are set, never simulated, and it touches the tissue only through the
grasp's proxy. So it lives in a client of its own that is never stepped, loaded once and moved to each
episode's RCM, and is copied into the physics client only while a frame is drawn. In the physics client
its multibody cost half of every substep (15 of 30 us, measured) and changed the tissue's motion only
by the sag of the unsimulated joints under gravity between two set-points, up to 0.2 um at the grasp
point (measured): the grasp now holds where the arm was sent.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, replace

import numpy as np

from psm_control.errors import ConfigurationError
from psm_control.robot import PsmConfiguration
from psm_control.urdf import GRASP_FRAME
from sim.grasp import Grasp, GraspParams
from sim.psm_body import PsmBody
from sim.quiet_pybullet import pybullet as p
from sim.tissue import Tissue, TissueParams

__all__ = ["FLAP_SAG_MAX_M", "HIDDEN_HALF_EXTENTS_M", "RCM_ABOVE_FLAP_M", "PhysicsParams", "Scene"]

#: Half extents of the hidden tissue box (x, y, z) [m].
HIDDEN_HALF_EXTENTS_M = np.array([0.022, 0.015, 0.004])
_HIDDEN_CENTRE_Y_M = 0.018  # under the free-edge half of the flap
# The pinned edges sit this far above the hidden tissue so that the flap, sagging under gravity (up to
# about 15 mm over the randomization ranges), does not rest on it: resting deformable-rigid contact
# costs about three times the rest of a substep (measured), while the retraction lifts the flap anyway.
_FLAP_HEIGHT_M = 2 * HIDDEN_HALF_EXTENTS_M[2] + 0.018
#: Height of the RCM (the port) above the flap's pinned edges, before the rcm_z_m randomization [m].
RCM_ABOVE_FLAP_M = 0.135
#: Largest sag of the flap under gravity over the randomization ranges [m] (see the note above).
FLAP_SAG_MAX_M = 0.015


@dataclass(frozen=True)
class PhysicsParams:
    """Physics stepping.

    Attributes:
        time_step_s: Physics substep [s]. PyBullet's mass-spring cloth resting on a rigid body is
            stable at 1/240 s and not at 1/120 s (measured for the default flap); stiffer flaps need
            finer steps (at E 30 kPa, t 3 mm: 6 of 12 resets broke the flap at 1/240 s, none at 1/480 s).
        substeps: Substeps per environment step (12 x 1/240 s = 0.05 s per step).
        solver_iterations: Constraint solver iterations (the paper's code used 50).
        settle_s: Shortest time the flap settles under gravity before an episode starts [s].
        settle_max_s: Longest: the flap settles until at rest (see :meth:`Scene.settle`) or this long [s].
        settle_speed_m_per_s: At rest: no node of the flap moves faster than this, on average over
            0.05 s [m/s]. A flap released from flat keeps sagging for up to about 1.5 s (3-7.5 mm at
            the site, measured); an episode that started earlier began on a falling flap.
        control_period_s: Period of the control chain's ticks [s], a whole number of substeps that
            divides the step; a joint set-point is held for the substeps in between, as the dVRK's servo
            loop holds its last ``servo_jp``. 40 Hz (two ticks per step): Ruckig plans the whole
            jerk-limited motion and the tick only samples it, so the tool moves the same at 120, 60 and
            40 Hz (3.3 mm per 5 mm step in steady motion, expert 100 % over 30 episodes per task at each
            rate), while the env runs 383 instead of 241 steps per CPU-second (measured).
    """

    time_step_s: float = 1.0 / 240.0
    substeps: int = 12
    solver_iterations: int = 10
    settle_s: float = 0.25
    settle_max_s: float = 3.0
    settle_speed_m_per_s: float = 0.002
    control_period_s: float = 1.0 / 40.0

    def __post_init__(self) -> None:
        if not 0 <= self.settle_s <= self.settle_max_s or not self.settle_speed_m_per_s > 0:
            raise ConfigurationError(
                "settle_s/settle_max_s/settle_speed_m_per_s",
                (self.settle_s, self.settle_max_s, self.settle_speed_m_per_s),
                "0 <= settle_s <= settle_max_s and a positive speed",
            )
        if not 0 < self.time_step_s <= 0.01:
            raise ConfigurationError("time_step_s", self.time_step_s, "a substep in (0, 0.01] s")
        if self.substeps < 1 or self.solver_iterations < 1:
            raise ConfigurationError("substeps", self.substeps, "at least one substep and one solver iteration")
        ticks = self.control_period_s / self.time_step_s
        if not (ticks >= 1 and abs(ticks - round(ticks)) < 1e-6 and self.substeps % round(ticks) == 0):
            raise ConfigurationError(
                "control_period_s",
                self.control_period_s,
                f"a whole number of substeps ({self.time_step_s:g} s) that divides the {self.substeps} substeps",
            )

    @property
    def step_s(self) -> float:
        """Duration of one environment step [s]."""
        return self.time_step_s * self.substeps


#: The stiffest flap the default 1/240 s substeps hold (measured on the 7-node flap: 1 reset in 16 broke the
#: flap at 22 kPa, none at 18 kPa; at 30 kPa 6 of 12 broke at 1/240 s and none at 1/480 s). Every flap of
#: the default randomization (6-14 kPa, 70-90 mm, 1000-1100 kg/m^3) is within it.
STABLE_AT_DEFAULT_STEP = TissueParams(youngs_modulus_kpa=20.0)


def _node_frequency_sq(tissue: TissueParams) -> float:
    """``k / m`` of a node of the flap [1/s^2]: a spring's stiffness over a node's share of the mass."""
    return tissue.spring_stiffness_n_per_m * tissue.resolution**2 / tissue.mass_kg


def stable_physics(physics: PhysicsParams, tissue: TissueParams) -> PhysicsParams:
    """``physics`` with its substep split so that ``dt^2 k / m`` of the flap stays within the default's.

    The mass-spring flap's stable substep scales with ``sqrt(m / k)`` of its nodes; the split is the
    smallest whole number that brings ``k / m`` of this flap, per split substep, within that of
    :data:`STABLE_AT_DEFAULT_STEP` at the default substep. The step and the control period stay the same.
    """
    ratio = _node_frequency_sq(tissue) / _node_frequency_sq(STABLE_AT_DEFAULT_STEP)
    split = max(1, math.ceil(math.sqrt(ratio) * (physics.time_step_s * 240.0) - 1e-9))
    if split == 1:
        return physics
    return replace(physics, time_step_s=physics.time_step_s / split, substeps=physics.substeps * split)


class Scene:
    """Builds the scene for one episode in an existing physics client.

    Args:
        client: PyBullet physics client id (reset here with the deformable world).
        arm: The PSM, in a client of its own (moved here to the episode's RCM).
        values: The episode's randomization values (see :mod:`sim.randomization`).
        physics: Physics stepping.
        grasp: Grasp settings (the friction is taken from ``values``).
        tissue: Base tissue settings (stiffness, damping, mass, size, colour, texture from ``values``).
    """

    def __init__(
        self,
        client: int,
        arm: PsmBody,
        values: Mapping[str, float],
        physics: PhysicsParams,
        grasp: GraspParams,
        tissue: TissueParams,
    ) -> None:
        self.client = client
        self.physics = physics
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
        # Gravity after the reset: the paper's code set it before a second reset, which cleared it.
        self.gravity_m_s2 = np.array([0.0, 0.0, -values["gravity_m_s2"]])
        p.setGravity(*self.gravity_m_s2, physicsClientId=client)
        p.setPhysicsEngineParameter(
            fixedTimeStep=physics.time_step_s,
            numSubSteps=0,
            numSolverIterations=physics.solver_iterations,
            physicsClientId=client,
        )
        self.tissue_origin = np.array([values["tissue_x_m"], values["tissue_y_m"], _FLAP_HEIGHT_M])
        self.table_id = self._box([0.15, 0.15, 0.01], [0.0, 0.0, -0.01], (0.55, 0.55, 0.6, 1.0))
        self.hidden_centre = self.tissue_origin + np.array([0.0, _HIDDEN_CENTRE_Y_M, 0.0])
        self.hidden_centre[2] = HIDDEN_HALF_EXTENTS_M[2]
        self.hidden_id = self._box(HIDDEN_HALF_EXTENTS_M, self.hidden_centre, (0.9, 0.85, 0.2, 1.0))
        self.tissue_params = TissueParams(
            size_m=values["tissue_size_m"],
            resolution=tissue.resolution,
            youngs_modulus_kpa=values["tissue_youngs_modulus_kpa"],
            thickness_mm=values["tissue_thickness_mm"],
            density_kg_m3=values["tissue_density_kg_m3"],
            damping=values["tissue_damping"],
            friction=tissue.friction,
            # A texture from a file (a photo) shows in its own colours; the drawn colour tints the procedural one.
            rgba=(1.0, 1.0, 1.0, 1.0)
            if tissue.texture_path is not None
            else (values["tissue_color_r"], values["tissue_color_g"], values["tissue_color_b"], 1.0),
            texture_seed=int(values["tissue_texture_seed"]),
            texture_path=tissue.texture_path,
            mark_sites=tissue.mark_sites,
            site_offset_m=(values["site_offset_x_m"], values["site_offset_y_m"]),
            site_inset_m=tissue.site_inset_m,
            site_spacing_m=tissue.site_spacing_m,
        )
        # Stiffer or lighter flaps need finer substeps: set before the flap is loaded and settled.
        self.physics = physics = stable_physics(physics, self.tissue_params)
        p.setPhysicsEngineParameter(fixedTimeStep=physics.time_step_s, physicsClientId=client)
        self.tissue = Tissue(client, self.tissue_params, self.tissue_origin)
        self.rcm_position = self.tissue_origin + np.array(
            [values["rcm_x_m"], 0.02 + values["rcm_y_m"], RCM_ABOVE_FLAP_M + values["rcm_z_m"]]
        )
        transform = np.eye(4)
        transform[:3, 3] = self.rcm_position
        self.configuration = PsmConfiguration(arm.model, arm.model.home(), jaw=0.6, base_frame=transform)
        self.body = arm
        arm.move_base(self.rcm_position)
        self.grasp = Grasp(
            client, self.tissue.body_id, self.tissue.triangles, replace(grasp, friction=values["grip_friction"])
        )

    def _box(
        self, half_extents: np.ndarray | list[float], centre: np.ndarray | list[float], rgba: tuple[float, ...]
    ) -> int:
        half = [float(v) for v in half_extents]
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=self.client)
        visual = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=list(rgba), physicsClientId=self.client)
        position = [float(v) for v in centre]
        return int(p.createMultiBody(0.0, shape, visual, basePosition=position, physicsClientId=self.client))

    @contextlib.contextmanager
    def arm_in_view(self) -> Iterator[int]:
        """The arm copied into the physics client at its current joints, for one render; its body id.

        Removed on exit, so that the physics never steps it (nor tests its collisions): the tissue moves
        the same, frame or not.
        """
        arm = self.body
        copy = PsmBody(self.client, arm.model, arm.rcm_position, arm.rcm_orientation)
        try:
            copy.reset_joints(*arm.joint_states())
            yield copy.body_id
        finally:
            p.removeBody(copy.body_id, physicsClientId=self.client)

    def grasp_position(self) -> np.ndarray:
        """World position of the point midway along the jaws [m], from the arm's measured joints."""
        return self.body.link_pose(GRASP_FRAME)[:3, 3]

    def step_physics(self, substeps: int = 1) -> None:
        """Physics substeps with the jaw proxy on the grasp point (the arm holds still meanwhile)."""
        if self.grasp.holding:
            self.grasp.follow(self.grasp_position())
        for _ in range(substeps):
            p.stepSimulation(physicsClientId=self.client)

    def settle(self) -> float:
        """Let the flap come to rest under gravity; return how long it took [s].

        At least ``settle_s``, then 0.05 s windows until no node moved faster than
        ``settle_speed_m_per_s`` over one, at most ``settle_max_s``.
        """
        physics = self.physics
        window = max(1, round(0.05 / physics.time_step_s))
        steps = round(physics.settle_s / physics.time_step_s)
        for _ in range(steps):
            p.stepSimulation(physicsClientId=self.client)
        before = self.tissue.positions()
        while steps * physics.time_step_s < physics.settle_max_s:
            for _ in range(window):
                p.stepSimulation(physicsClientId=self.client)
            steps += window
            now = self.tissue.positions()
            fastest = float(np.max(np.linalg.norm(now - before, axis=1))) / (window * physics.time_step_s)
            before = now
            if fastest < physics.settle_speed_m_per_s:
                break
        return steps * physics.time_step_s
