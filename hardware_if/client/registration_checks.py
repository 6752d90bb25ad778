"""Is a registered site plausible? Jaws closed, inside the workspace box, on the tissue's surface.

``register`` records wherever the jaws are; a registration made with the jaws in the air or open would
send every episode to the wrong place. These checks compare the site (in ``<arm>_base``, made relative
to the RCM with the console's base frame) with what a grasp site can be: the jaws closed on it, inside
the control chain's workspace box (the chain never takes the tool out of it), and at the depth below the
port where the task scenes' tissue lies. Each finding says what was measured and what is allowed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from safety.config import SafetyConfig
from sim.randomization import DEFAULT_RANGES
from sim.scene import FLAP_SAG_MAX_M, RCM_ABOVE_FLAP_M

__all__ = [
    "JAW_CLOSED_MAX_RAD",
    "SURFACE_TOLERANCE_M",
    "RegistrationFinding",
    "check_registration",
    "tissue_depth_range_m",
]

#: Jaw angles above this are open [rad]: the jaws rest closed on the site (0 rad closed, 0.6 rad open).
JAW_CLOSED_MAX_RAD = 0.2
#: How far above or below the tissue's depth range a site may be before it is far from any surface [m].
SURFACE_TOLERANCE_M = 0.01


@dataclass(frozen=True)
class RegistrationFinding:
    """One problem with a registration.

    Attributes:
        refuse: True when the registration cannot be used; False for a warning.
        text: What was measured and what is allowed, with units.
    """

    refuse: bool
    text: str


def tissue_depth_range_m() -> tuple[float, float]:
    """Depths below the RCM at which the task scenes' tissue surface lies [m], sag included."""
    low_z, high_z = DEFAULT_RANGES["rcm_z_m"]
    return RCM_ABOVE_FLAP_M + low_z, RCM_ABOVE_FLAP_M + high_z + FLAP_SAG_MAX_M


def check_registration(
    site_m: np.ndarray,
    transform_rcm_to_base: np.ndarray,
    jaw_rad: float | None = None,
    config: SafetyConfig | None = None,
) -> list[RegistrationFinding]:
    """What is wrong with a registered site (empty when nothing is).

    Args:
        site_m: The registered grasp point [m] in ``<arm>_base``.
        transform_rcm_to_base: Pose of the RCM in ``<arm>_base`` (4x4), from the console.
        jaw_rad: The measured jaw angle while registering [rad]; None skips the jaw check.
        config: The chain's settings (the workspace box); default :class:`SafetyConfig`.
    """
    config = config if config is not None else SafetyConfig()
    findings = []
    if jaw_rad is not None and jaw_rad > JAW_CLOSED_MAX_RAD:
        findings.append(
            RegistrationFinding(
                True,
                f"the jaws are open ({jaw_rad:.2f} rad, closed is at most {JAW_CLOSED_MAX_RAD:g} rad): "
                "close them on the site",
            )
        )
    rcm_to_base = np.asarray(transform_rcm_to_base, dtype=float)
    local = rcm_to_base[:3, :3].T @ (np.asarray(site_m, dtype=float) - rcm_to_base[:3, 3])
    low, high = np.asarray(config.workspace_min_m), np.asarray(config.workspace_max_m)
    outside = [
        f"{axis} = {1000 * v:+.1f} mm (box {1000 * lo:+.0f}..{1000 * hi:+.0f} mm)"
        for axis, v, lo, hi in zip("xyz", local, low, high, strict=True)
        if not lo <= v <= hi
    ]
    if outside:
        findings.append(
            RegistrationFinding(
                True,
                "the site is outside the workspace box about the RCM: " + ", ".join(outside) + "; the chain "
                "never takes the tool there: put the closed jaws on the tissue and register again",
            )
        )
    depth, (shallow, deep) = -float(local[2]), tissue_depth_range_m()
    if not shallow - SURFACE_TOLERANCE_M <= depth <= deep + SURFACE_TOLERANCE_M:
        where = "above" if depth < shallow else "below"
        findings.append(
            RegistrationFinding(
                False,
                f"the site is {1000 * abs(depth):.0f} mm {'below' if depth >= 0 else 'above'} the RCM, {where} "
                "the tissue's surface "
                f"({1000 * shallow:.0f}-{1000 * deep:.0f} mm below it in the task scenes, "
                f"+-{1000 * SURFACE_TOLERANCE_M:.0f} mm): far from any surface the arm reaches",
            )
        )
    return findings
