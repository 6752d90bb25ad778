"""What a deploy is asked to do: :class:`DeployOptions`, checked as a whole before anything runs."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hardware_if.client.task_estimate import as_point
from hardware_if.common.task_topics import DEFAULT_RIG
from hardware_if.wrench.calibration import WrenchCalibration
from psm_control.errors import ConfigurationError
from safety.config import SafetyConfig
from sim.tissue_params import SITE_NAMES

__all__ = ["DeployOptions"]


@dataclass(frozen=True)
class DeployOptions:
    """Settings of one deploy.

    Attributes:
        policy: ``scripted``, ``random``, ``module:callable`` or a checkpoint path.
        target: ``sim`` or ``dvrk``.
        task: Task id (the policy's task; for ``dvrk`` the task topics' meaning).
        arm: Arm name (dVRK).
        rate_hz: Control rate of the chain [Hz]; None: the simulation's (sim) or the dVRK's 100 Hz.
        dry_run: Listen and compute only (dVRK).
        safety_config: Chain limits; None: :class:`SafetyConfig` defaults.
        record: MCAP output file.
        episodes: Number of episodes.
        seed: Seed of the first episode.
        wait_s: How long to wait for the arm's first measurement, the task topics, and for the arm to be
            ENABLED, homed and idle at each episode start [s]; running out is a hold.
        policy_budget_s: Longest a policy step may take [s]; None: one policy period. Slower is a hold.
        live: Serve the 3-D scene for the Foxglove app on ws://127.0.0.1 at this port (0 picks one);
            None serves nothing. The recording holds the same scene either way.
        site: The registered grasp site [m] in ``<arm>_base`` (dVRK): the task state then comes from it,
            the goal and the jaw (:class:`~hardware_if.client.remote_task.RegisteredSite`), not from the task
            topics. None: the ``/<arm>/task/*`` topics.
        goal: Where the site must go [m] in ``<arm>_base``, with ``site``; None: the task's nominal goal
            about the site (:func:`sim.envs.nominal_goal`).
        force_sensing: What the simulation's chain and policy sense of the force (sim; :mod:`sim.force_sensing`).
        force_sensing_error_n: The robot's force-sensing error bound [N] (dVRK); None: the ``dvrk`` model's
            bound for the console's uncompensated ``measured_cf``.
        force_sensing_source: What that bound is from, for the run-start warning (dVRK).
        wrench_calibration: The force-sensing calibration to take the force with (dVRK); None: ``measured_cf``.
        force_sensor: ``measured_cf`` comes from a force sensor at the instrument (dVRK), off by at most
            ``force_sensing_error_n`` as the user declared (``deploy --force-sensor``), not from motor currents.
        wrench_calibration_path: The file ``wrench_calibration`` was read from, for the recording.
        wrench_calibration_sha256: That file's SHA-256 (hex) as it was read, for the recording.
        perception: ``camera[:MODEL]``: the site from the endoscope's images (:mod:`hardware_if.client.perceived_env`).
        texture: The flap's texture image file (sim).
        image_timeout_s: With ``perception`` on a dVRK: endoscope images older than this hold the arm [s].
        endoscope_rig: With ``perception`` on a dVRK: the stereo rig's name (``/<rig>/left/image_raw`` ...).
        camera_site: With ``perception`` on a dVRK: which of the flap's named sites (``centre``, ``left``,
            ``right``) the episodes grasp; the camera sees all three (MultiSite varies it per episode).
    """

    policy: str
    target: str
    record: Path
    task: str = "lift"
    arm: str = "PSM1"
    rate_hz: float | None = None
    dry_run: bool = False
    safety_config: SafetyConfig | None = None
    episodes: int = 1
    seed: int = 0
    wait_s: float = 30.0
    policy_budget_s: float | None = None
    live: int | None = None
    site: tuple[float, float, float] | None = None
    goal: tuple[float, float, float] | None = None
    force_sensing: str = "ideal"
    force_sensing_error_n: float | None = None
    force_sensing_source: str = "dvrk measured_cf, uncompensated"
    wrench_calibration: WrenchCalibration | None = None
    force_sensor: bool = False
    wrench_calibration_path: Path | None = None
    wrench_calibration_sha256: str | None = None
    perception: str | None = None
    texture: str | None = None
    image_timeout_s: float = 0.5
    endoscope_rig: str = DEFAULT_RIG
    camera_site: str = "centre"

    def __post_init__(self) -> None:
        if self.site is not None and self.target != "dvrk":
            raise ConfigurationError("site", self.site, "--site with --target dvrk (the simulation sees its tissue)")
        if self.perception is not None and self.site is not None:
            raise ConfigurationError("perception", self.perception, "either --perception or --site/--registration")
        if self.camera_site not in SITE_NAMES:
            raise ConfigurationError("camera_site", self.camera_site, f"one of {', '.join(SITE_NAMES)}")
        if self.camera_site != "centre" and (self.perception is None or self.target != "dvrk"):
            raise ConfigurationError(
                "camera_site", self.camera_site, "--camera-site with --perception camera on --target dvrk"
            )
        if self.goal is not None and self.target != "dvrk":
            raise ConfigurationError("goal", self.goal, "--goal with --target dvrk (the simulation sets its own goal)")
        if self.goal is not None and self.site is None and self.perception is None:
            raise ConfigurationError(
                "goal", self.goal, "--goal with --site or --perception (the task topics bring their own goal)"
            )
        if self.site is not None:
            as_point(self.site, "site")
        if self.goal is not None:
            as_point(self.goal, "goal")
        if self.policy_budget_s is not None and not (np.isfinite(self.policy_budget_s) and self.policy_budget_s > 0):
            raise ConfigurationError("policy_budget_s", self.policy_budget_s, "a finite number of seconds > 0")
        if self.target not in ("sim", "dvrk"):
            raise ConfigurationError("target", self.target, "'sim' or 'dvrk'")
        error_n = self.force_sensing_error_n
        if error_n is not None and not (np.isfinite(error_n) and error_n > 0.0):
            # The filter would take a dVRK's force as exact: no sensor is, and a 0 N bound turns the margin off.
            raise ConfigurationError(
                "force_sensing_error_n",
                error_n,
                "a sensing error bound, a finite number of newtons > 0 (no sensing is exact)",
            )
        if self.force_sensor and (self.target != "dvrk" or self.wrench_calibration is not None or error_n is None):
            raise ConfigurationError(
                "force_sensor",
                self.force_sensor,
                "--force-sensor N on --target dvrk, with the sensor's error bound and without --wrench-calibration",
            )
        if self.dry_run and self.target != "dvrk":
            raise ConfigurationError("dry_run", self.dry_run, "--dry-run with --target dvrk (live robot state)")
        if self.episodes < 1:
            raise ConfigurationError("episodes", self.episodes, "at least 1")
