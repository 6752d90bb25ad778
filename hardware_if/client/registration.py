"""Registering the grasp site by touch: where the jaws are while the operator holds them on the site.

On a robot without perception the operator shows the robot the site once: they hold the closed jaws on
it and ``tissue-retract register`` records the grasp point (midway along the jaws, where they close on
tissue) by the arm's kinematics in ``<arm>_base``, averaged over a still moment. The same point is what
the task's observation compares the site with, so a registration with the jaws on the site leaves no
offset between the two. The result is printed (``site: X Y Z``) for ``deploy --site`` and can be
written as JSON for ``deploy --registration FILE``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hardware_if.client.task_estimate import as_point, format_point
from psm_control.errors import ConfigurationError, TissueRetractError
from psm_control.inputs import read_text
from psm_control.robot import PsmModel

__all__ = [
    "MAX_SPREAD_M",
    "Registration",
    "RegistrationError",
    "console_base_frame",
    "grasp_point",
    "read_registration",
    "register_site",
]

#: Largest distance of any sample from their mean [m]: a tool that moved more was not held still.
MAX_SPREAD_M = 0.001


class RegistrationError(TissueRetractError):
    """The tool was not held still on the site, or no measurement came."""


@dataclass(frozen=True)
class Registration:
    """A registered site.

    Attributes:
        arm: Arm name.
        site_m: The grasp point [m] in ``<arm>_base`` (the mean of the samples).
        spread_m: Largest distance of a sample from the mean [m].
        samples: Number of measurements averaged.
    """

    arm: str
    site_m: np.ndarray
    spread_m: float
    samples: int

    def line(self) -> str:
        """``site: X Y Z`` in metres, as ``deploy --site`` takes it."""
        return f"site: {format_point(self.site_m)}"

    def to_dict(self) -> dict[str, Any]:
        """The JSON form ``deploy --registration`` reads."""
        return {
            "arm": self.arm,
            "frame": f"{self.arm}_base",
            "site_m": [float(v) for v in self.site_m],
            "spread_m": self.spread_m,
            "samples": self.samples,
            "point": "grasp point: midway along the jaws",
        }


def console_base_frame(client: Any) -> np.ndarray:
    """Pose of the RCM in ``<arm>_base`` from ``measured_cp`` and ``local/measured_cp`` (4x4)."""
    base, _ = client.pose("measured_cp")
    local, _ = client.pose("local/measured_cp")
    return np.asarray(base @ np.linalg.inv(local))


def grasp_point(client: Any, configuration: Any) -> np.ndarray:
    """The grasp point [m] in ``<arm>_base`` by kinematics from the arm's measured joints.

    The RCM's pose in ``<arm>_base`` comes from ``measured_cp`` and ``local/measured_cp`` (the console's
    base frame), so the point is in the frame the console reports poses in.

    Args:
        client: A :class:`~hardware_if.client.psm_client.PsmClient` (or anything with ``measure`` and ``pose``).
        configuration: The arm's :class:`~psm_control.robot.PsmConfiguration`, updated in place.
    """
    measured = client.measure()
    configuration.set_base_frame(console_base_frame(client))
    configuration.update(measured.q, measured.jaw)
    return np.asarray(configuration.grasp_position(), dtype=float)


def register_site(client: Any, *, samples: int = 50, timeout_s: float = 10.0) -> Registration:
    """Average the grasp point over ``samples`` successive measurements of a still arm.

    Raises:
        RegistrationError: No new measurement within ``timeout_s``, or the tool moved more than
            :data:`MAX_SPREAD_M` while it was sampled.
    """
    configuration = PsmModel().configuration()
    points, stamp = [], float("-inf")
    try:
        for _ in range(samples):
            stamp = client.next_measurement(stamp, timeout_s).stamp_s
            points.append(grasp_point(client, configuration))
    except TissueRetractError as e:
        raise RegistrationError(f"no registration: {e}") from None
    cloud = np.array(points)
    site = cloud.mean(axis=0)
    spread = float(np.max(np.linalg.norm(cloud - site, axis=1)))
    if spread > MAX_SPREAD_M:
        raise RegistrationError(
            f"the tool moved {spread * 1000:.2f} mm while registering (at most {MAX_SPREAD_M * 1000:g} mm): "
            "hold the closed jaws still on the site and register again"
        )
    return Registration(client.topics.arm, site, spread, samples)


def read_registration(path: str | Path, arm: str) -> np.ndarray:
    """The site [m] of a registration file written for ``arm``.

    Raises:
        ConfigurationError: Not a registration JSON, another arm's, or not three finite coordinates.
    """
    text = read_text(path, "--registration")
    try:
        data = json.loads(text)
        site = as_point(data["site_m"], "site_m")
        recorded_arm = str(data["arm"])
    except ConfigurationError:
        raise ConfigurationError("--registration", str(path), "site_m: three finite coordinates [m]") from None
    except (ValueError, KeyError, TypeError):
        raise ConfigurationError(
            "--registration", str(path), "a JSON file written by `tissue-retract register --out`"
        ) from None
    if recorded_arm != arm:
        raise ConfigurationError("--registration", str(path), f"a registration of {arm} (this one is {recorded_arm}'s)")
    return site
