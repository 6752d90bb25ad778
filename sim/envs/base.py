"""The goal-conditioned retraction environment that every task specialises.

One environment owns one PyBullet physics client. A step turns the 5-D action into a
:class:`~psm_control.commands.CartesianDelta`, gives it to the controller once, then ticks the
controller and applies its joint set-points during the physics substeps. Tasks say only which grasp
site counts, how the goal is drawn and what the achieved goal is.
"""

from __future__ import annotations

import collections
import contextlib
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from psm_control.commands import CartesianDelta, MeasuredState
from psm_control.errors import UnknownVariantError
from psm_control.quaternion import quaternion_xyzw
from psm_control.robot import PsmModel
from safety.chain import ControlChain
from safety.config import SafetyConfig
from safety.force_watch import FORCE_LIMIT_STALL, ForceLimitWatch
from sim.backend import SimBackend
from sim.control import make_controller
from sim.endoscope import Appearance, Endoscope, StereoFrame, render_stereo
from sim.exposure import exposed_fraction, surface_samples
from sim.force_sensing import ForceSensor, SensingParams, error_bound_n, sensing_params, with_sensing
from sim.grasp import GraspParams
from sim.mechanics import DamageLimits, grasp_force, measure, spring_strain
from sim.psm_body import PsmBody
from sim.quiet_pybullet import pybullet as p
from sim.randomization import INSERTION_M_PER_RAD, Randomizer
from sim.rendering import Camera, Frame, render
from sim.scene import HIDDEN_HALF_EXTENTS_M, PhysicsParams, Scene
from sim.tissue import TissueParams

__all__ = ["EnvConfig", "TissueRetractEnv"]

_OBS_SIZE = 18
_UNSTABLE_SPEED_M_S = 5.0
_UNSTABLE_DISTANCE_M = 0.5
#: A flap at rest is stretched a few per cent by its weight; a spring this far past its rest length after
#: settling means the solver broke the flap (measured on the 7-node flap at 1/240 s substeps: 1 reset in
#: 16 at E 22 kPa and t 3 mm, 7 in 16 at 28 kPa, all at 40 kPa, with one spring left at 2-6 times its length).
_BROKEN_AT_REST_STRAIN = 0.5


@dataclass(frozen=True)
class EnvConfig:
    """Settings of a retraction environment.

    Attributes:
        max_step_m: Tool-tip translation of a full action [m].
        max_yaw_rad: Tool yaw of a full action [rad] (0 ignores the yaw action, as the paper did).
        jaw_open_rad: Jaw angle for a non-negative jaw action [rad]; a negative one closes it.
        jaw_closed_rad: Jaw angle for a negative jaw action [rad].
        success_threshold_m: Goal distance that counts as success [m].
        safety: Run the control chain's safety filter (False is an ablation).
        physics: Physics stepping.
        tissue: Flap settings (randomized fields are overridden per episode).
        grasp: Grasp settings.
        damage: Tissue damage thresholds.
        randomization: Overrides of the randomization ranges.
        camera: The camera of ``render()`` (placed relative to the flap).
        endoscope: The stereo endoscope, fixed in the world (:meth:`TissueRetractEnv.render_endoscope`).
        safety_config: The control chain's limits (force limit, workspace box, motion limits); None: the
            :class:`~safety.config.SafetyConfig` defaults. Its control rate is replaced by the physics', and
            its force-sensing error and tissue bounds by the sensing's and the tissue ranges' (see
            :func:`sim.force_sensing.with_sensing`).
        force_sensing: What the controller and the policy sense of the tissue force: ``ideal`` (the exact
            force), ``dvrk`` (the console's ``measured_cf`` from motor currents) or ``dvrk-calibrated``
            (:mod:`sim.force_sensing`), or a sensing model (a calibration file's,
            :func:`sim.force_sensing.calibrated_sensing`). Episode records keep the true force as well.
    """

    max_step_m: float = 0.005
    max_yaw_rad: float = 0.0
    jaw_open_rad: float = 0.6
    jaw_closed_rad: float = 0.0
    success_threshold_m: float = 0.005
    safety: bool = True
    physics: PhysicsParams = field(default_factory=PhysicsParams)
    tissue: TissueParams = field(default_factory=TissueParams)
    grasp: GraspParams = field(default_factory=GraspParams)
    damage: DamageLimits = field(default_factory=DamageLimits)
    randomization: dict[str, tuple[float, float]] = field(default_factory=dict)
    camera: Camera = field(default_factory=Camera)
    endoscope: Endoscope = field(default_factory=Endoscope)
    safety_config: SafetyConfig | None = None
    force_sensing: str | SensingParams = "ideal"


class TissueRetractEnv(gym.Env[dict[str, np.ndarray], np.ndarray]):
    """Grasp a tissue flap with the PSM and retract it (goal-conditioned, sparse reward).

    Args:
        config: Environment settings.
        render_mode: ``None`` or ``"rgb_array"``.
        **overrides: Fields of :class:`EnvConfig` (``gym.make(id, safety=False)``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}  # noqa: RUF012 (Gymnasium convention)
    #: Task option keys accepted by ``reset(options=...)`` besides the randomization parameters.
    task_options: tuple[str, ...] = ("site", "goal")
    goal_size = 3

    def __init__(self, config: EnvConfig | None = None, render_mode: str | None = None, **overrides: Any) -> None:
        base = config if config is not None else EnvConfig()
        self.config = EnvConfig(**{**base.__dict__, **overrides})
        if render_mode not in (None, "rgb_array"):
            raise UnknownVariantError("render_mode", render_mode, ["None", "rgb_array"])
        self.render_mode = render_mode
        self.randomizer = Randomizer(self.config.randomization)
        self.use_force_sensing(self.config.force_sensing)
        self.model = PsmModel()
        self.client = p.connect(p.DIRECT)
        self._arm_client = p.connect(p.DIRECT)  # the kinematic arm's own, never stepped (see sim.scene)
        self.arm = PsmBody(self._arm_client, self.model)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(5,), dtype=np.float32)
        box = gym.spaces.Box(-np.inf, np.inf, shape=(_OBS_SIZE,), dtype=np.float32)
        goal = gym.spaces.Box(-np.inf, np.inf, shape=(self.goal_size,), dtype=np.float32)
        self.observation_space = gym.spaces.Dict(  # type: ignore[assignment]
            {"observation": box, "achieved_goal": goal, "desired_goal": goal}
        )
        self.scene: Scene | None = None
        self.values: dict[str, float] = {}
        self.site = "centre"
        self.goal = np.zeros(self.goal_size)
        self.controller: ControlChain | None = None
        self.controller_name = ""
        self._joint_offset: np.ndarray | None = None
        self._base_error: np.ndarray | None = None
        self._commanded_qd: np.ndarray | None = None

    def use_randomization(self, ranges: dict[str, tuple[float, float]], log_uniform: Iterable[str] = ()) -> None:
        """Draw the next episodes from these ranges (over the configured ones; ``log_uniform`` names those drawn
        log-uniformly, see :class:`sim.randomization.Randomizer`), and bound the tissue by them."""
        self.randomizer = Randomizer({**self.config.randomization, **ranges}, log_uniform)
        self.use_force_sensing(self.sensing)

    @property
    def force_sensing(self) -> str:
        """The force-sensing preset the observation's and the controller's force come through."""
        return self.sensing.name

    def use_force_sensing(self, sensing: str | SensingParams) -> None:
        """Sense the tissue force through the preset of that name, or that model, from the next episode on
        (:mod:`sim.force_sensing`).

        The controller is rebuilt at the next reset: its filter trusts the force to the sensing's error bound.
        """
        self.sensing = sensing if isinstance(sensing, SensingParams) else sensing_params(sensing)
        config = self.config.safety_config or SafetyConfig()
        self.safety_config = with_sensing(config, error_bound_n(self.sensing, config), self.randomizer.ranges)
        self.controller = None

    # ----------------------------------------------------------------- task hooks
    def _choose_site(self, rng: np.random.Generator) -> str:
        return "centre"

    def _sample_goal(self, rng: np.random.Generator, site_position: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _achieved_goal(self) -> np.ndarray:
        return self.site_position()

    @classmethod
    def nominal_goal(cls, site_position: np.ndarray) -> np.ndarray | None:
        """The middle of the task's goal range for a site [m] (None: the goal is not a place)."""
        return None

    # ----------------------------------------------------------------- Gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Start an episode; ``options`` may fix any randomization parameter, ``site`` or ``goal``."""
        super().reset(seed=seed)
        options = dict(options or {})
        task = {k: options.pop(k) for k in self.task_options if k in options}
        for name in options:
            if name not in self.randomizer.ranges:
                raise UnknownVariantError("reset option", name, [*self.task_options, *sorted(self.randomizer.ranges)])
        # The dynamics disturbances and their directions come from their own stream (jumped, so the
        # episode generator does not advance and the same seed gives the same episode without them).
        dynamics_rng = self.randomizer.dynamics_stream(self.np_random)
        self.values = self.randomizer.sample(self.np_random, options, dynamics_rng)
        self._joint_offset, self._base_error = self._dynamics_errors(dynamics_rng)
        # The sensor's noise and drift: the sensing stream's own sensing stream (the scale is drawn from the first).
        sensing_rng = self.randomizer.sensing_stream(self.randomizer.sensing_stream(self.np_random))
        self.sensor = ForceSensor(self.sensing.scaled(self.values["force_sensing_scale"]), sensing_rng)
        self.site = str(task.get("site", self._choose_site(self.np_random)))
        cfg = self.config
        self.scene = Scene(self.client, self.arm, self.values, cfg.physics, cfg.grasp, cfg.tissue)
        if self.site not in self.scene.tissue.site_local:
            raise UnknownVariantError("site", self.site, list(self.scene.tissue.site_local))
        offset = np.array([self.values["site_offset_x_m"], self.values["site_offset_y_m"], 0.0])
        self._site_nodes, self._site_weights = self.scene.tissue.site_binding(
            self.scene.tissue.site_local[self.site] + offset
        )
        self.scene.settle()
        tissue = self.scene.tissue
        # An episode on a broken flap ends at once as unstable: its forces and strains would be the solver's.
        self._broken_at_rest = bool(
            spring_strain(tissue.positions(), tissue.edges, tissue.rest_lengths).max() > _BROKEN_AT_REST_STRAIN
        )
        self.backend = SimBackend(
            self.scene.body,
            self.scene.configuration.q,
            cfg.jaw_open_rad,
            joint_offset=self._joint_offset,
            tracking_lag=self.values["tracking_lag"],
            substep_s=self.scene.physics.time_step_s,
        )
        if self.controller is None:  # built once: the chain's QP workspaces outlive episodes
            self.controller, self.controller_name = make_controller(
                self.scene.configuration,
                safety=cfg.safety,
                control_period_s=cfg.physics.control_period_s,
                config=self.safety_config,
            )
        self.controller.log.clear()
        self.controller.reset(self.backend.measure())
        # Against the configured limit even with the filter off (the ablation shows what it would exceed).
        self._force_watch = ForceLimitWatch(
            self.controller.config.effective_force_limit_n, self.controller.control_period_s
        )
        self._ticks = 0
        self._controller_events: list[dict[str, Any]] = []  # the chain's events of this episode (force-limit stalls)
        self._nodes = self.scene.tissue.positions()
        self._exposure_points = surface_samples(self.scene.hidden_centre, HIDDEN_HALF_EXTENTS_M)
        self._eye = cfg.camera.eye(self.scene.tissue_origin)
        given = task.get("goal")
        self.goal = (
            np.asarray(given, dtype=float)
            if given is not None
            else self._sample_goal(self.np_random, self.site_position())
        )
        # The jaw an invalid action keeps: the jaw command last given (the pending zeros open it).
        self._last_jaw_action = 0.0
        latency = int(self.values["action_latency_steps"])
        self._pending: collections.deque[np.ndarray] = collections.deque([np.zeros(5)] * latency)
        self._force = np.zeros(3)
        self._sensed_force = np.zeros(3)
        self._sensed_peak = 0.0
        self._commanded_qd = None  # the chain's last command's velocities (the sensing's acceleration)
        self._force_over_travel_bound: float | None = None
        self._strain = 0.0
        self._holding_steps = 0
        self._last_measured = self._measured()
        return self._observation(), self._info(events={})

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        """Apply one action for one control step (``physics.substeps`` substeps)."""
        if self.scene is None or self.controller is None:
            raise RuntimeError("call reset() before step()")
        events: dict[str, Any] = {}
        safe_action = self._checked_action(action, events)
        self._pending.append(safe_action)
        act = self._pending.popleft()
        cfg = self.config
        jaw = cfg.jaw_closed_rad if act[4] < 0 else cfg.jaw_open_rad
        delta = CartesianDelta(act[:3] * cfg.max_step_m, float(act[3]) * cfg.max_yaw_rad, jaw, "base")
        measured = self._last_measured
        self.controller.set_target(delta, measured)
        stops, reasons = 0, []
        interventions: set[str] = set()
        physics = self.scene.physics  # the substeps this flap needs (sim.scene.stable_physics)
        per_tick = max(1, round(self.controller.control_period_s / physics.time_step_s))
        done = 0
        peak = 0.0
        while done < physics.substeps:
            output = self.controller.tick(measured)
            self._check_travel_bound()
            if output.safety_stop:
                stops += 1
                reasons.append(output.reason)
            interventions.update(output.interventions)
            self._controller_events.extend(output.events)
            self.backend.servo_jp(output.command)
            self._commanded_qd = output.command.qd
            count = min(per_tick, physics.substeps - done)
            if self.backend.lagging:  # the arm moves during the substeps, so step them one by one
                for _ in range(count):
                    self.backend.advance()
                    self.scene.step_physics(1)
            else:
                self.scene.step_physics(count)
            done += count
            if done < physics.substeps:  # the step's last tick is measured below, with the grasp's update
                self._force = self._held_force(self.scene.tissue.positions())
                peak = max(peak, self._watch_tick())
                measured = self._measured()
        previous = self._nodes
        self._nodes = self.scene.tissue.positions()
        unstable = self._broken_at_rest or self._unstable(previous, self._nodes)
        if unstable:
            self._nodes = np.nan_to_num(previous)
            self.scene.grasp.release()
        else:
            self._update_tissue(events)
        peak = max(peak, self._watch_tick())
        self._last_measured = self._measured()  # what the next step starts from, and the observation's force
        events.update(
            force_peak_n=peak,
            sim_unstable=unstable,
            safety_stop=stops > 0,
            safety_stops=stops,
            safety_reason=reasons[0] if reasons else "",
            interventions=tuple(sorted(interventions)),
        )
        observation = self._observation()
        info = self._info(events)
        reward = float(self.compute_reward(observation["achieved_goal"], observation["desired_goal"], info))
        return observation, reward, False, unstable, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """Sparse reward, batch-capable: 0 where the goal is reached, -1 elsewhere."""
        return -(~self._reached(np.asarray(achieved_goal), np.asarray(desired_goal))).astype(np.float32)

    def _reached(self, achieved: np.ndarray, desired: np.ndarray) -> np.ndarray:
        return np.asarray(np.linalg.norm(achieved - desired, axis=-1) <= self.config.success_threshold_m)

    def render(self) -> np.ndarray | None:
        """The endoscope's RGB image (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        return self.render_frame().rgb

    def render_frame(self) -> Frame:
        """RGB, depth and class segmentation of the current scene."""
        with self._bodies_in_view() as bodies:
            return render(self.client, self.config.camera, self._scene().tissue_origin, bodies)

    def render_endoscope(self, appearance: Appearance, rng: np.random.Generator) -> StereoFrame:
        """The stereo endoscope's pair under ``appearance`` (``rng`` draws the sensor noise)."""
        with self._bodies_in_view() as bodies:
            return render_stereo(self.client, self.config.endoscope, appearance, bodies, rng)

    def _scene(self) -> Scene:
        if self.scene is None:
            raise RuntimeError("call reset() before rendering")
        return self.scene

    @contextlib.contextmanager
    def _bodies_in_view(self) -> Iterator[dict[str, int]]:
        """The scene's bodies by class for one render, the flap textured and the arm copied in."""
        s = self._scene()
        s.tissue.show_texture()
        with s.arm_in_view() as instrument:
            yield {"tissue": s.tissue.body_id, "hidden_tissue": s.hidden_id, "instrument": instrument}

    def close(self) -> None:
        """Disconnect the physics client and the arm's."""
        for client in (self.client, self._arm_client):
            if client >= 0 and p.isConnected(client):
                p.disconnect(client)
        self.client = self._arm_client = -1

    # ----------------------------------------------------------------- internals
    def site_position(self) -> np.ndarray:
        """World position of the episode's grasp site (a material point of the flap) [m]."""
        return np.asarray(self._site_weights @ self._nodes[self._site_nodes])

    def grasp_position(self) -> np.ndarray:
        """World position of the point midway along the jaws [m]."""
        assert self.scene is not None
        return self.scene.grasp_position()

    def exposure(self) -> float:
        """Fraction of the hidden tissue the camera sees past the flap."""
        assert self.scene is not None
        return exposed_fraction(self._exposure_points, self._eye, self._nodes, self.scene.tissue.triangles)

    def _dynamics_errors(self, rng: np.random.Generator) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The episode's encoder offset (6,) and base registration error (3,) [m]; None where off.

        Both directions are always drawn from ``rng`` (the dynamics stream), so each stays the same for a
        seed whatever the other magnitude is.
        """
        joint_direction = rng.standard_normal(6)
        base_direction = rng.standard_normal(3)
        joint_offset = base_error = None
        magnitude = self.values["joint_offset_rad"]
        if magnitude > 0:
            scale = np.ones(6)
            scale[2] = INSERTION_M_PER_RAD  # the insertion joint is prismatic [m]
            joint_offset = magnitude * scale * joint_direction
        norm = self.values["base_error_m"]
        if norm > 0:
            base_error = norm * base_direction / np.linalg.norm(base_direction)
        return joint_offset, base_error

    def _checked_action(self, action: np.ndarray, events: dict[str, Any]) -> np.ndarray:
        raw = np.asarray(action, dtype=float).reshape(-1)
        if raw.shape != (5,) or not np.all(np.isfinite(raw)):
            events["invalid_action"] = True
            # Hold position and keep the jaw as it is: opening it would drop the tissue.
            return np.array([0.0, 0.0, 0.0, 0.0, self._last_jaw_action])
        clipped = np.clip(raw, -1.0, 1.0)
        events["action_clipped"] = bool(np.any(clipped != raw))
        self._last_jaw_action = float(clipped[4])
        return clipped

    def _held_force(self, nodes: np.ndarray) -> np.ndarray:
        """The force the tissue exerts on the jaws now (zero when they hold nothing) [N]."""
        return grasp_force(**self._mechanics(nodes))

    def _mechanics(self, nodes: np.ndarray) -> dict[str, Any]:
        """What the tissue's force and strain are computed from: these node positions, the flap, the grasp now."""
        assert self.scene is not None
        t = self.scene.tissue
        return {
            "positions": nodes,
            "edges": t.edges,
            "rest_lengths": t.rest_lengths,
            "stiffness_n_per_m": t.params.spring_stiffness_n_per_m,
            "grasped": self.scene.grasp.nodes,
            "node_mass_kg": t.node_mass_kg,
            "gravity_m_s2": self.scene.gravity_m_s2,
        }

    def _watch_tick(self) -> float:
        """Give the force of the tick just simulated to the force-limit watch; return its magnitude [N]."""
        self._ticks += 1
        self._force_watch.update(self._force, self._ticks * self._force_watch.period_s)
        return float(np.linalg.norm(self._force))

    def _check_travel_bound(self) -> None:
        """Hold the true force of the tick the chain just filtered against its travel bound (NaN: not in force)."""
        assert self.controller is not None
        bound = self.controller.force_bound.travel_bound_n
        if not math.isnan(bound):
            ratio = float(np.linalg.norm(self._force)) / bound
            self._force_over_travel_bound = max(ratio, self._force_over_travel_bound or 0.0)

    def _measured(self) -> MeasuredState:
        """The arm's measurement, with the force as the robot senses it (the true one with ``ideal``)."""
        assert self.scene is not None and self.controller is not None
        measured_q = self.backend.measure().q
        configuration = self.scene.configuration
        configuration.update(measured_q, self.backend.jaw)
        self._sensed_force = self.sensor.measure(
            configuration, self.backend.qd, self._force, self.controller.control_period_s, self._commanded_qd
        )
        self._sensed_peak = max(self._sensed_peak, float(np.linalg.norm(self._sensed_force)))
        self.backend.force_n = self._sensed_force
        return self.backend.measure()

    def _unstable(self, previous: np.ndarray, nodes: np.ndarray) -> bool:
        if not np.all(np.isfinite(nodes)):
            return True
        assert self.scene is not None
        speed = np.abs(nodes - previous).max() / self.config.physics.step_s
        far = np.abs(nodes - self.scene.tissue_origin).max()
        return bool(speed > _UNSTABLE_SPEED_M_S or far > _UNSTABLE_DISTANCE_M)

    def _update_tissue(self, events: dict[str, Any]) -> None:
        assert self.scene is not None
        s, damage = self.scene, self.config.damage
        now = measure(**self._mechanics(self._nodes), limits=damage)
        grasp = s.grasp.update(self.backend.jaw, s.grasp_position(), self._nodes, float(np.linalg.norm(now.force_n)))
        if grasp.grasped or grasp.lost:  # the jaws now hold other nodes
            now = measure(**self._mechanics(self._nodes), limits=damage)
        self._force, self._strain = now.force_n, now.max_strain
        events.update(
            grip_loss=grasp.lost, improper_grasp=grasp.improper, tissue_damage=now.damaged, new_grasp=grasp.grasped
        )

    def _observation(self) -> dict[str, np.ndarray]:
        assert self.scene is not None
        configuration = self.scene.configuration
        if self._joint_offset is None and self._base_error is None:
            configuration.update(self.backend.q, self.backend.jaw)
            pose = configuration.measured_pose()
        else:
            # Calibration errors: the tool pose is what the robot reports, the forward kinematics of the
            # encoder joints through the base frame it believes in; the site (seen by the camera) is true.
            configuration.update(self.backend.measure().q, self.backend.jaw)
            pose = np.array(configuration.measured_pose(), dtype=float)
            if self._base_error is not None:
                pose[:3, 3] += self._base_error
            configuration.update(self.backend.q, self.backend.jaw)
        tip = pose[:3, 3]
        site = self.site_position()
        noise = self.values["observation_noise_m"]
        if noise > 0:
            tip = tip + self.np_random.normal(0.0, noise, 3)
            site = site + self.np_random.normal(0.0, noise, 3)
        quaternion = quaternion_xyzw(pose[:3, :3])  # x, y, z, w
        observation = np.concatenate(
            [
                tip,
                quaternion,
                [self.backend.jaw],
                site,
                site - tip,
                self._sensed_force,
                [float(self.scene.grasp.holding)],
            ]
        )
        return {
            "observation": observation.astype(np.float32),
            "achieved_goal": np.asarray(self._achieved_goal(), dtype=np.float32),
            "desired_goal": np.asarray(self.goal, dtype=np.float32),
        }

    def _workspace_violation_m(self) -> float:
        """How far the tool tip is outside the control chain's workspace box (0 inside) [m].

        The box is about the RCM (the chain's base frame), where the configuration's local pose is.
        """
        assert self.scene is not None and self.controller is not None
        config = self.controller.config
        self.scene.configuration.update(self.backend.q, self.backend.jaw)
        tip = self.scene.configuration.local_pose()[:3, 3]
        outside = np.maximum(np.asarray(config.workspace_min_m) - tip, tip - np.asarray(config.workspace_max_m))
        return float(np.linalg.norm(np.maximum(outside, 0.0)))

    def _info(self, events: dict[str, Any]) -> dict[str, Any]:
        assert self.scene is not None
        achieved = np.asarray(self._achieved_goal())
        info: dict[str, Any] = {
            "is_success": bool(self._reached(achieved, np.asarray(self.goal))),
            "force_n": self._force.copy(),
            "force_norm_n": float(np.linalg.norm(self._force)),
            "max_strain": self._strain,
            "exposure": self.exposure(),
            "grasped": self.scene.grasp.holding,
            "site": self.site,
            "randomization": dict(self.values),
            "controller": self.controller_name,
            "q": self.backend.q.copy(),
            "insertion_m": float(self.backend.q[2]),
            "workspace_violation_m": self._workspace_violation_m(),
        }
        for flag in (
            "grip_loss", "improper_grasp", "tissue_damage", "sim_unstable", "invalid_action", "action_clipped",
            "safety_stop", "new_grasp",
        ):  # fmt: skip
            info[flag] = bool(events.get(flag, False))
        info["safety_stops"] = int(events.get("safety_stops", 0))
        info["safety_reason"] = str(events.get("safety_reason", ""))
        info["interventions"] = tuple(events.get("interventions", ()))
        info["force_peak_n"] = float(events.get("force_peak_n", info["force_norm_n"]))
        info["force_limit_n"] = self._force_watch.limit_n
        info["measured_force_n"] = self._sensed_force.copy()
        info["measured_force_peak_n"] = self._sensed_peak
        info["force_over_travel_bound_peak"] = self._force_over_travel_bound
        info["force_limit_exceeded"] = tuple(e.to_event() for e in self._force_watch.all())
        info["force_limit_stall"] = tuple(e for e in self._controller_events if e["kind"] == FORCE_LIMIT_STALL)
        return info
