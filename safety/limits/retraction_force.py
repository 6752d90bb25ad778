"""The retraction-force limit: the force after a step stays within the limit in every direction.

A step ``dq`` moves the grasp point (midway along the jaws, where the held tissue is) by ``J dq`` and
changes the force the tool applies to the tissue by about ``K J dq``, with ``K`` the stiffness estimate.
``J`` is the grasp point's Jacobian, not the tool tip's: the wrist can swing the jaws while the tip stays
put (measured: the filter held the tip within 1 mm while the wrist pitched 0.6 rad and dragged the held
flap 4 mm). The estimate is learned along the force; it is used across
the force as well, because a sideways step turns the tissue with the tool and grows the force as surely
as a pull along it (measured: with a row along the force alone, 0.05 N limit, the filter let the tool
move 3-7 mm a tick across the force, and the force reached 9 times the limit).

The rows apply while the tool may be pulling on tissue: the jaw closed (below :data:`CLOSED_JAW_RAD`) or a
force measured (at least :data:`CONTACT_FORCE_N`). An open jaw with no force holds nothing, and the stiff
prior would otherwise slow every approach to a crawl.

The bound ``|F + K J dq| <= F_max`` is a ball; a QP takes linear rows, so the ball is replaced by its 32
tangent planes ``u_k^T (F + K J dq) <= F_max`` at the vertices and face centres of an icosahedron, turned so
that one of them points along the force. Along the force the rows are exact; between the planes the
polytope reaches at most 8.4 % beyond the ball (the 32 directions cover every direction within 22.7 deg:
1 / cos 22.7 deg = 1.084). The rows hold at any force, so no force threshold or trusted direction is needed:
right after a grasp they allow a step of ``F_max / K`` towards any plane, and above the limit every plane the
force crosses asks for a step that lowers it, which is backing off along the force. Soft, because a force
beyond the limit may take more than one step to relax, and cannot relax at all when the limit is below
what holding the tissue costs.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from safety.limits.limit import FilterState, Limit

__all__ = ["CLOSED_JAW_RAD", "CONTACT_FORCE_N", "FORCE_DIRECTIONS", "RetractionForceLimit", "may_hold_tissue"]

#: Below this jaw opening the jaws may hold tissue [rad] (the simulation's grasp closes below 0.15 rad; a jaw
#: stalled on a held flap reads about 0.12 rad).
CLOSED_JAW_RAD = 0.15
#: A force this large means contact whatever the jaw does [N] (below the smallest limit presets allow).
CONTACT_FORCE_N = 0.05


def may_hold_tissue(jaw_rad: float, force_n: np.ndarray, error_n: float = 0.0) -> bool:
    """The jaws may hold tissue: closed (below :data:`CLOSED_JAW_RAD`) or a contact force measured.

    ``error_n`` is how far the measured force may be off: a contact is told only beyond it.
    """
    contact = CONTACT_FORCE_N + error_n
    return jaw_rad < CLOSED_JAW_RAD or float(force_n @ force_n) >= contact * contact


def _icosahedral_directions() -> np.ndarray:
    """The 12 vertices and 20 face centres of an icosahedron, unit vectors (32, 3), the first one +z."""
    golden = (1.0 + math.sqrt(5.0)) / 2.0
    vertices = np.array(
        [(s1 * 1.0, s2 * golden, 0.0) for s1 in (-1, 1) for s2 in (-1, 1)]
        + [(0.0, s1 * 1.0, s2 * golden) for s1 in (-1, 1) for s2 in (-1, 1)]
        + [(s2 * golden, 0.0, s1 * 1.0) for s1 in (-1, 1) for s2 in (-1, 1)]
    )
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    edge = float(np.max(vertices[1:] @ vertices[0]))  # cosine between neighbouring vertices
    faces = [
        vertices[[i, j, k]].sum(axis=0)
        for i, j, k in itertools.combinations(range(12), 3)
        if min(vertices[i] @ vertices[j], vertices[j] @ vertices[k], vertices[i] @ vertices[k]) > edge - 1e-9
    ]
    directions = np.vstack([vertices, np.array(faces) / np.linalg.norm(faces, axis=1, keepdims=True)])
    onto_z = _rotation_from_z(*directions[0].tolist()).T  # the inverse: the first direction onto +z
    return np.asarray(directions @ onto_z.T)


def _rotation_from_z(x: float, y: float, z: float) -> np.ndarray:
    """The rotation taking +z onto the unit vector (x, y, z), the shortest way (a half turn about x for -z).

    Written out on floats: it runs every control tick, and numpy's cross products on 3-vectors cost
    more than the rest of the limit together (measured).
    """
    if z < -1.0 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    k = 1.0 / (1.0 + z)
    return np.array(
        [
            [1.0 - x * x * k, -x * y * k, x],
            [-x * y * k, 1.0 - y * y * k, y],
            [-x, -y, 1.0 - (x * x + y * y) * k],
        ]
    )


#: The planes' normals with the force along +z (32, 3); see the module notes.
FORCE_DIRECTIONS = _icosahedral_directions()


class RetractionForceLimit(Limit):
    """Keep the predicted force ``F + K J (dq + d_stop)`` inside the 32 tangent planes of the ``F_max`` ball (soft).

    ``d_stop`` is the way the joints still travel when they brake from their current velocity at the
    jerk-limited smoother's limits, ``|qd| qd / (2 a) + a qd / (2 j)`` per joint: the step is judged by
    where the motion ends, not where the tick ends (measured: the wrist, moving at 2.6 rad/s when the
    force rows took hold, carried the held flap a further 2 mm while it braked).

    Args:
        force_limit_n: ``F_max`` [N].
        acceleration: Per-joint acceleration limits of the smoother (dof,).
        jerk: Per-joint jerk limits of the smoother (dof,).
    """

    name = "retraction_force"
    soft = True
    rows = len(FORCE_DIRECTIONS)

    def __init__(self, force_limit_n: float, acceleration: np.ndarray, jerk: np.ndarray) -> None:
        self.force_limit_n = float(force_limit_n)
        self._half_over_acceleration = 0.5 / np.asarray(acceleration, dtype=float)
        self._ramp = 0.5 * np.asarray(acceleration, dtype=float) / np.asarray(jerk, dtype=float)
        dof = self._ramp.size
        self._G = np.zeros((self.rows, dof))
        self._h = np.zeros(self.rows)

    def stopping_displacement(self, qd: np.ndarray) -> np.ndarray:
        """How far each joint still moves while braking from ``qd`` (dof,)."""
        qd = np.asarray(qd, dtype=float)
        return qd * (np.abs(qd) * self._half_over_acceleration + self._ramp)

    def directions(self, force_n: np.ndarray) -> np.ndarray:
        """The planes' normals (32, 3) for a force: one along it (the fixed set for no or a non-finite force)."""
        x, y, z = (float(v) for v in force_n)
        magnitude = math.sqrt(x * x + y * y + z * z)
        if not (magnitude > 1e-9 and math.isfinite(magnitude)):
            return FORCE_DIRECTIONS
        return np.asarray(FORCE_DIRECTIONS @ _rotation_from_z(x / magnitude, y / magnitude, z / magnitude).T)

    def compute_qp_inequalities(self, state: FilterState) -> tuple[np.ndarray, np.ndarray]:
        """Rows ``K u_k^T J dq <= F_max - m - u_k^T (F + K J d_stop)`` for the 32 normals, ``m`` the force's margin.

        Unused when nothing is held.
        """
        force = np.asarray(state.retraction_force_n, dtype=float)
        if not np.all(np.isfinite(force)):
            force = np.zeros(3)  # the chain stops on a non-finite force before filtering; never trust one here
        elif not (state.tissue_held or may_hold_tissue(state.jaw_rad, force, state.force_margin_n)):
            self._G[:] = 0.0
            self._h[:] = np.inf
            return self._G, self._h
        normals = self.directions(force)
        np.dot(normals, state.grasp_jacobian, out=self._G)
        self._G *= state.stiffness_n_per_m
        coasting = state.stiffness_n_per_m * (state.grasp_jacobian @ self.stopping_displacement(state.qd))
        np.subtract(self.force_limit_n - state.force_margin_n, normals @ (force + coasting), out=self._h)
        return self._G, self._h
