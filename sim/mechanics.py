"""Tissue mechanics as signals: the retraction force on the grasp, the tissue strain, damage.

PyBullet reports no force for soft-body anchors, so the force is computed from the same mass-spring
model the solver integrates: every spring between a grasped node and a free node pulls with
``k (length - rest)`` along itself, and the grasped nodes' own weight hangs on the jaw. Spring damping
is left out (the estimate is quasi-static); ``tests/sim/test_mechanics.py`` checks the estimate
against a hanging flap whose whole weight the grasp must carry.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from psm_control.errors import ConfigurationError

__all__ = ["DamageLimits", "TissueSignals", "grasp_force", "measure", "spring_forces", "spring_strain"]


@dataclass(frozen=True)
class DamageLimits:
    """Thresholds beyond which the tissue counts as damaged.

    Attributes:
        max_force_n: Retraction force limit [N]; 5 N is a conservative figure for delicate tissue
            (suture traction tolerated before tearing: 1.25-11.4 N, Rodrigues et al. 2012).
        max_strain: Largest spring strain (length / rest - 1) the tissue tolerates; a point grasp on a
            13 mm mesh concentrates strain in the few springs at the jaw, hence the generous default.
    """

    max_force_n: float = 5.0
    max_strain: float = 1.0

    def __post_init__(self) -> None:
        if not self.max_force_n > 0:
            raise ConfigurationError("max_force_n", self.max_force_n, "a positive force [N]")
        if not self.max_strain > 0:
            raise ConfigurationError("max_strain", self.max_strain, "a positive strain")


class TissueSignals(NamedTuple):
    """Mechanical state of the tissue after one step.

    Attributes:
        force_n: Force the tissue exerts on the grasp (3,) [N], world axes (zero when not grasped).
        max_strain: Largest spring strain in the flap.
        damaged: True when the force or the strain crossed its damage limit.
    """

    force_n: np.ndarray
    max_strain: float
    damaged: bool


def spring_strain(positions: np.ndarray, edges: np.ndarray, rest_lengths: np.ndarray) -> np.ndarray:
    """Strain of every spring (length / rest - 1)."""
    lengths = np.linalg.norm(positions[edges[:, 1]] - positions[edges[:, 0]], axis=1)
    return lengths / rest_lengths - 1.0


def spring_forces(
    positions: np.ndarray, edges: np.ndarray, rest_lengths: np.ndarray, stiffness_n_per_m: float
) -> np.ndarray:
    """The force (N, 3) [N] the springs exert on every node: ``k (length - rest)`` along each spring."""
    span = positions[edges[:, 1]] - positions[edges[:, 0]]
    length = np.linalg.norm(span, axis=1)
    pull = (stiffness_n_per_m * (length - rest_lengths) / np.maximum(length, 1e-12))[:, None] * span
    forces = np.zeros_like(positions)
    np.add.at(forces, edges[:, 0], pull)
    np.add.at(forces, edges[:, 1], -pull)
    return forces


def grasp_force(
    positions: np.ndarray,
    edges: np.ndarray,
    rest_lengths: np.ndarray,
    stiffness_n_per_m: float,
    grasped: np.ndarray,
    node_mass_kg: np.ndarray,
    gravity_m_s2: np.ndarray,
) -> np.ndarray:
    """Force (3,) [N] the tissue exerts on the grasp holding the nodes ``grasped``.

    Args:
        positions: Node positions (N, 3) [m].
        edges: Spring node pairs (E, 2).
        rest_lengths: Spring rest lengths (E,) [m].
        stiffness_n_per_m: Spring stiffness [N/m].
        grasped: Indices of the nodes the jaw holds.
        node_mass_kg: Node masses (N,) [kg].
        gravity_m_s2: Gravity vector (3,) [m/s^2].
    """
    if len(grasped) == 0:
        return np.zeros(3)
    held = np.zeros(len(positions), dtype=bool)
    held[grasped] = True
    crossing = held[edges[:, 0]] != held[edges[:, 1]]
    inner = np.where(held[edges[crossing, 0]], edges[crossing, 0], edges[crossing, 1])
    outer = np.where(held[edges[crossing, 0]], edges[crossing, 1], edges[crossing, 0])
    span = positions[outer] - positions[inner]
    length = np.linalg.norm(span, axis=1)
    tension = stiffness_n_per_m * (length - rest_lengths[crossing])
    pull = (tension / np.maximum(length, 1e-12))[:, None] * span
    weight = node_mass_kg[grasped].sum() * np.asarray(gravity_m_s2, dtype=float)
    return np.asarray(pull.sum(axis=0) + weight)


def measure(
    positions: np.ndarray,
    edges: np.ndarray,
    rest_lengths: np.ndarray,
    stiffness_n_per_m: float,
    grasped: np.ndarray,
    node_mass_kg: np.ndarray,
    gravity_m_s2: np.ndarray,
    limits: DamageLimits,
) -> TissueSignals:
    """All the tissue signals of one step (see :func:`grasp_force` for the arguments)."""
    force = grasp_force(positions, edges, rest_lengths, stiffness_n_per_m, grasped, node_mass_kg, gravity_m_s2)
    strain = float(spring_strain(positions, edges, rest_lengths).max())
    damaged = bool(np.linalg.norm(force) > limits.max_force_n or strain > limits.max_strain)
    return TissueSignals(force, strain, damaged)
