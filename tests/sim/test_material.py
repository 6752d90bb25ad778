"""The flap's material: the lattice formula, and what PyBullet's sheet does in tension and shear."""

from __future__ import annotations

import itertools

import numpy as np
import pybullet as p
import pytest

from psm_control.errors import ConfigurationError
from sim.fem import FEM_POISSON_RATIO, FemSheet
from sim.material import LATTICE_POISSON_RATIO, lattice_modulus_factor, spring_stiffness_n_per_m
from sim.material_testing import lift, picture_frame_shear, uniaxial_tension
from sim.tissue import TissueParams, grid_mesh


def _lattice_stiffness(resolution: int) -> np.ndarray:
    """Voigt in-plane stiffness of the unit sheet's lattice per unit spring constant, from its triangles.

    A spring of length l along n adds k l^2 v v^T (v = [nx^2, ny^2, nx ny]) to the stiffness of the area it
    spans; each triangle owns half of each of its edges, so an edge on the sheet's border counts half.
    """
    vertices, triangles = grid_mesh(resolution, 1.0)
    stiffness = np.zeros((3, 3))
    for triangle in triangles:
        for a, b in ((triangle[0], triangle[1]), (triangle[1], triangle[2]), (triangle[2], triangle[0])):
            d = vertices[b, :2] - vertices[a, :2]
            n = d / np.linalg.norm(d)
            v = np.array([n[0] ** 2, n[1] ** 2, n[0] * n[1]])
            stiffness += 0.5 * np.dot(d, d) * np.outer(v, v)
    return stiffness


def test_the_lattice_is_isotropic_with_poisson_one_third() -> None:
    """Summed over the mesh's springs, the sheet's stiffness is isotropic, nu = 1/3, E t = 4k/3."""
    c = _lattice_stiffness(9)  # the unit sheet: per unit area, spring constant 1
    assert c[0, 2] == pytest.approx(0.0, abs=1e-12) and c[1, 2] == pytest.approx(0.0, abs=1e-12)
    assert c[0, 0] == pytest.approx(c[1, 1])
    assert c[2, 2] == pytest.approx((c[0, 0] - c[0, 1]) / 2.0)
    assert c[0, 1] / c[0, 0] == pytest.approx(LATTICE_POISSON_RATIO)
    assert (c[0, 0] ** 2 - c[0, 1] ** 2) / c[0, 0] == pytest.approx(4.0 / 3.0)


def test_spring_constant_formula() -> None:
    """k = E t / (4/3 + 1/(n - 1)): 10 kPa x 3 mm on 7 nodes per side is 20 N/m."""
    assert spring_stiffness_n_per_m(10.0, 3.0, 7) == pytest.approx(20.0)
    assert lattice_modulus_factor(7) == pytest.approx(1.5)
    assert TissueParams().spring_stiffness_n_per_m == pytest.approx(20.0)
    assert TissueParams().mass_kg == pytest.approx(1050.0 * 0.08**2 * 0.003)


@pytest.mark.parametrize("field", ["youngs_modulus_kpa", "thickness_mm", "density_kg_m3"])
def test_material_must_be_positive(field: str) -> None:
    """A zero modulus, thickness or density is refused, naming the field."""
    with pytest.raises(ConfigurationError, match=field):
        TissueParams(**{field: 0.0})


@pytest.mark.parametrize(
    ("youngs_kpa", "thickness_mm", "width_mm"), list(itertools.product((1.0, 50.0), (1.0, 5.0), (40.0, 100.0)))
)
def test_uniaxial_force_is_the_closed_form(youngs_kpa: float, thickness_mm: float, width_mm: float) -> None:
    """Pulled to 10 % strain, the sheet's force is E t W eps within 10 %, over E, t and W."""
    params = TissueParams(size_m=width_mm / 1000.0, youngs_modulus_kpa=youngs_kpa, thickness_mm=thickness_mm)
    result = uniaxial_tension(params, strain=0.10)
    assert result.expected_force_n == pytest.approx(youngs_kpa * thickness_mm * width_mm * 1e-3 * 0.10)
    assert abs(result.relative_error) < 0.10
    forces = [force for _, force in result.curve]
    assert all(np.diff(forces) > 0)  # monotone: quasi-static, no oscillation


def test_shear_force_is_the_lattice_shear_modulus() -> None:
    """Picture-frame shear reads G t = k/2, i.e. the closed form times 4 / (3 (4/3 + 1/(n - 1)))."""
    params = TissueParams()
    result = picture_frame_shear(params, shear=0.05)
    lattice = 4.0 / (3.0 * lattice_modulus_factor(params.resolution))
    assert result.force_n == pytest.approx(result.expected_force_n * lattice, rel=0.02)


def test_fem_stress_is_the_materials_at_small_strain() -> None:
    """Uniform uniaxial strain of the FEM plate: in-plane, interior nodes balance; the +x face carries
    (lambda + 2 mu) eps A, the linear material's stress (Bullet's stable Neo-Hookean, reparametrised)."""
    params = TissueParams(youngs_modulus_kpa=10.0, thickness_mm=3.0, resolution=5)
    client = p.connect(p.DIRECT)
    try:
        p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=client)
        sheet = FemSheet(client, params, np.zeros(3))
        strain = 1e-4
        stretched = sheet.rest_positions * np.array([1.0 + strain, 1.0, 1.0])
        forces = sheet.elastic_forces(stretched)
        n = params.resolution
        inner = (sheet.grid_cols > 0) & (sheet.grid_cols < n - 1) & (sheet.grid_rows > 0) & (sheet.grid_rows < n - 1)
        face = sheet.grid_cols == n - 1
        e, nu = 10e3, FEM_POISSON_RATIO
        lam, mu = e * nu / ((1 + nu) * (1 - 2 * nu)), e / (2 * (1 + nu))
        expected = (lam + 2 * mu) * strain * params.size_m * params.thickness_mm * 1e-3
        assert np.abs(forces[inner, :2]).max() < 1e-6 * expected  # z: the faces hold sigma_zz = lambda eps
        assert -forces[face, 0].sum() == pytest.approx(expected, rel=1e-3)
    finally:
        p.disconnect(client)


def test_fem_shear_is_the_closed_form() -> None:
    """Picture-frame shear of the FEM plate (uniform shear) reads G t W gamma within 2 %."""
    result = picture_frame_shear(TissueParams(resolution=5), shear=0.05, model="fem")
    assert abs(result.relative_error) < 0.02


def test_lift_force_rises_with_the_lift() -> None:
    """Lifting the pinned spring flap's free edge: the force on the grasp grows at every step of the lift."""
    curve = lift(TissueParams(), height_m=0.03)
    forces = [force for _, force in curve]
    assert forces[-1] > 0.01 and all(np.diff(forces) > 0)
