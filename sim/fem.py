"""The flap as PyBullet's FEM volume: a reference for the mass-spring flap.

PyBullet's deformable FEM (``useNeoHookean``) is Bullet's "stable Neo-Hookean" tetrahedral model
(Smith, de Goes and Kim, ACM TOG 2018): first Piola stress ``P = mu (1 - 1/(I_C + 1)) F +
(lambda (J - 1) - 3/4 mu) cof F``. Linearised at rest it is an isotropic solid with Lame parameters
``3/4 mu`` and ``lambda - 5/8 mu``, so a material of Young's modulus E and Poisson's ratio nu is given to
PyBullet as ``mu = 4/3 mu_E`` and ``lambda = lambda_E + 5/6 mu_E`` (the paper's reparametrisation), with
``mu_E, lambda_E`` the usual Lame parameters of (E, nu).

The sheet is one layer of hexahedral cells through the thickness, the grid of the spring flap in the plane
(``resolution`` nodes per side, two layers), each cell cut into six tetrahedra about its main diagonal.
PyBullet reports no force on anchored nodes; :meth:`FemSheet.elastic_forces` computes the elastic force
on every node with the same stress law from the node positions, as :func:`sim.mechanics.spring_forces`
does for the springs. Soft tissue is near-incompressible; ``nu = 0.45`` is the default (0.5 locks linear
tetrahedra).
"""

from __future__ import annotations

import numpy as np

from psm_control.errors import ConfigurationError
from sim.quiet_pybullet import pybullet as p
from sim.tissue import TissueParams, cached_file

__all__ = ["FEM_POISSON_RATIO", "FemSheet", "bullet_lame_parameters", "plate_mesh"]

#: Poisson's ratio of the FEM reference material.
FEM_POISSON_RATIO = 0.45

# The six tetrahedra of a hexahedron (corners 0-3 bottom, 4-7 top, counter-clockwise) about diagonal 0-6.
_HEX_TETRAS = ((0, 1, 2, 6), (0, 2, 3, 6), (0, 3, 7, 6), (0, 7, 4, 6), (0, 4, 5, 6), (0, 5, 1, 6))


def bullet_lame_parameters(youngs_modulus_pa: float, poisson_ratio: float) -> tuple[float, float]:
    """PyBullet's ``(NeoHookeanMu, NeoHookeanLambda)`` for a material of (E, nu) at small strain."""
    if not 0.0 <= poisson_ratio < 0.5:
        raise ConfigurationError("poisson_ratio", poisson_ratio, "a value in [0, 0.5)")
    mu = youngs_modulus_pa / (2.0 * (1.0 + poisson_ratio))
    lam = youngs_modulus_pa * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio))
    return 4.0 / 3.0 * mu, lam + 5.0 / 6.0 * mu


def plate_mesh(resolution: int, size_m: float, thickness_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (2 n^2, 3) and tetrahedra (6 (n-1)^2, 4) of a square plate centred on the origin.

    Node ``layer * n^2 + row * n + col`` sits at the spring flap's node ``row * n + col``, at
    ``z = -t/2`` (layer 0) or ``+t/2`` (layer 1).
    """
    n = resolution
    xs = np.linspace(-size_m / 2.0, size_m / 2.0, n)
    layers, in_layer = np.divmod(np.arange(2 * n * n), n * n)
    rows, cols = np.divmod(in_layer, n)
    nodes = np.stack([xs[cols], xs[rows], (layers - 0.5) * thickness_m], axis=1)
    tetras = []
    for row in range(n - 1):
        for col in range(n - 1):
            base = row * n + col
            bottom = (base, base + 1, base + n + 1, base + n)
            corners = bottom + tuple(c + n * n for c in bottom)
            tetras += [tuple(corners[i] for i in tetra) for tetra in _HEX_TETRAS]
    return nodes, np.array(tetras, dtype=int)


def _vtk_file(resolution: int, size_m: float, thickness_m: float) -> str:
    def write(path: str) -> None:
        nodes, tetras = plate_mesh(resolution, size_m, thickness_m)
        lines = ["# vtk DataFile Version 2.0", "flap", "ASCII", "DATASET UNSTRUCTURED_GRID"]
        lines += [f"POINTS {len(nodes)} double"] + [f"{x:.9f} {y:.9f} {z:.9f}" for x, y, z in nodes]
        lines += [f"CELLS {len(tetras)} {5 * len(tetras)}"] + [f"4 {a} {b} {c} {d}" for a, b, c, d in tetras]
        lines += [f"CELL_TYPES {len(tetras)}"] + ["10"] * len(tetras)
        with open(path, "w") as f:
            f.write("\n".join(lines) + "\n")

    return cached_file(f"plate_{resolution}_{size_m!r}_{thickness_m!r}.vtk", write)


class FemSheet:
    """The flap's material as a PyBullet FEM plate in one physics client (a deformable world).

    Args:
        client: PyBullet physics client id.
        params: The flap's settings (size, resolution, E, thickness, density; ``damping`` is the
            stiffness-proportional damping time [s] here, PyBullet's ``NeoHookeanDamping``).
        origin: World position of the plate's centre [m].
        poisson_ratio: The material's Poisson's ratio.
    """

    def __init__(
        self, client: int, params: TissueParams, origin: np.ndarray, *, poisson_ratio: float = FEM_POISSON_RATIO
    ) -> None:
        self.client = client
        self.params = params
        thickness_m = params.thickness_mm * 1e-3
        self.mu, self.lam = bullet_lame_parameters(params.youngs_modulus_kpa * 1e3, poisson_ratio)
        vertices, self.tetras = plate_mesh(params.resolution, params.size_m, thickness_m)
        self.rest_positions = vertices + np.asarray(origin, dtype=float)
        self.body_id = p.loadSoftBody(
            _vtk_file(params.resolution, params.size_m, thickness_m),
            basePosition=np.asarray(origin, dtype=float).tolist(),
            mass=params.mass_kg,
            useNeoHookean=1,
            NeoHookeanMu=self.mu,
            NeoHookeanLambda=self.lam,
            NeoHookeanDamping=params.damping,
            useSelfCollision=0,
            frictionCoeff=params.friction,
            collisionMargin=0.0005,
            physicsClientId=client,
        )
        p.changeDynamics(self.body_id, -1, activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING, physicsClientId=client)
        edges = vertices[self.tetras[:, 1:]] - vertices[self.tetras[:, :1]]  # (T, 3 edges, 3)
        rest_shapes = np.transpose(edges, (0, 2, 1))  # columns are the edges
        self._rest_inverse = np.linalg.inv(rest_shapes)
        self._rest_volume = np.abs(np.linalg.det(rest_shapes)) / 6.0
        n = params.resolution
        self.grid_rows, self.grid_cols = np.divmod(np.arange(2 * n * n) % (n * n), n)

    def positions(self) -> np.ndarray:
        """Current node positions (N, 3) in the world [m]."""
        _, nodes = p.getMeshData(self.body_id, -1, flags=p.MESH_DATA_SIMULATION_MESH, physicsClientId=self.client)
        return np.asarray(nodes, dtype=float)

    def elastic_forces(self, positions: np.ndarray) -> np.ndarray:
        """The elastic force (N, 3) [N] the material exerts on every node at ``positions``."""
        edges = positions[self.tetras[:, 1:]] - positions[self.tetras[:, :1]]
        deformation = np.transpose(edges, (0, 2, 1)) @ self._rest_inverse  # F = Ds Dm^-1
        trace = np.einsum("tij,tij->t", deformation, deformation)
        det = np.linalg.det(deformation)
        cofactor = det[:, None, None] * np.transpose(np.linalg.inv(deformation), (0, 2, 1))
        piola = (self.mu * (1.0 - 1.0 / (trace + 1.0)))[:, None, None] * deformation + (
            self.lam * (det - 1.0) - 0.75 * self.mu
        )[:, None, None] * cofactor
        on_123 = -self._rest_volume[:, None, None] * piola @ np.transpose(self._rest_inverse, (0, 2, 1))
        forces = np.zeros_like(positions)
        for corner in range(3):
            np.add.at(forces, self.tetras[:, corner + 1], on_123[:, :, corner])
        np.add.at(forces, self.tetras[:, 0], -on_123.sum(axis=2))
        return forces
