"""The flap's material in physical units, and the spring constant of its lattice.

The flap is a mass-spring cloth (:mod:`sim.tissue`): a square grid of nodes whose cells are split by
one diagonal, alternating in a checkerboard, every spring with the same stiffness ``k`` (PyBullet gives a
cloth one spring constant). In the continuum limit this lattice is an isotropic plane-stress sheet:

* a spring of stiffness ``k`` along a unit vector ``n`` over rest length ``l`` adds ``k l^2 n n n n``
  to the stiffness of the area it spans; summed over a cell of side ``a`` (one axial spring each way,
  one diagonal) and averaged over the two diagonal directions, the in-plane stiffness per unit width is
  ``C11 = C22 = 3k/2``, ``C12 = k/2``, ``C66 = k/2`` (Voigt), with no coupling of shear and stretch;
* hence ``E t = (C11^2 - C12^2) / C11 = 4k/3``, Poisson's ratio ``C12 / C11 = 1/3`` (a central-force
  lattice's Cauchy value: a real tissue, near-incompressible, is 0.45-0.5 in 3-D; a membrane's in-plane
  ratio is what this sets) and ``G t = C66 = k/2 = E t / (2 (1 + nu))``.

A finite grid of ``n`` nodes per side adds one thing: the springs along its two free edges belong to one
cell instead of two, so a sheet pulled parallel to them carries ``k`` more per unit strain than the
continuum. The spring constant therefore follows from ``E t = k (4/3 + 1/(n - 1))``
(:func:`spring_stiffness_n_per_m`); ``tissue-retract tissue-test`` measures it in PyBullet (its tests
sweep E, t and W). The one-diagonal grid PyBullet examples use is not isotropic: shear and stretch couple
(``C16 = k/2``), so pulling it shears it; hence the checkerboard.

Presets (:data:`PRESETS`) are literature values for tissues that are retracted; each row names its source
and what kind of measurement it is, because indentation and elastography moduli (1-50 kPa) and in-plane
tensile moduli of the same organ (hundreds of kPa) differ by orders of magnitude.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

from psm_control.errors import ConfigurationError, UnknownVariantError

__all__ = [
    "LATTICE_POISSON_RATIO",
    "MODELS",
    "PRESETS",
    "Model",
    "TissuePreset",
    "lattice_modulus_factor",
    "preset",
    "spring_stiffness_n_per_m",
]

#: In-plane Poisson's ratio of the flap's lattice (see the module docstring).
LATTICE_POISSON_RATIO = 1.0 / 3.0

#: The models of the flap's material: the simulated mass-spring cloth and PyBullet's FEM plate
#: (:mod:`sim.material_testing` tests both).
Model = Literal["spring", "fem"]
MODELS: tuple[Model, ...] = get_args(Model)


def lattice_modulus_factor(resolution: int) -> float:
    """``E t / k`` of a grid of ``resolution`` nodes per side: ``4/3 + 1/(resolution - 1)``."""
    if resolution < 2:
        raise ConfigurationError("resolution", resolution, "an integer >= 2 nodes per side")
    return 4.0 / 3.0 + 1.0 / (resolution - 1)


def spring_stiffness_n_per_m(youngs_modulus_kpa: float, thickness_mm: float, resolution: int) -> float:
    """The spring constant [N/m] that gives the flap's lattice the in-plane stiffness ``E t``."""
    return youngs_modulus_kpa * 1e3 * thickness_mm * 1e-3 / lattice_modulus_factor(resolution)


@dataclass(frozen=True)
class TissuePreset:
    """A tissue's material, from the literature.

    Attributes:
        name: Preset name (``--tissue NAME``).
        youngs_modulus_kpa: Young's modulus [kPa].
        thickness_mm: Thickness of the retracted layer [mm].
        density_kg_m3: Density [kg/m^3].
        measurement: What the modulus is (indentation, elastography, tensile at low strain...).
        source: Where the numbers come from.
    """

    name: str
    youngs_modulus_kpa: float
    thickness_mm: float
    density_kg_m3: float
    measurement: str
    source: str

    def reset_options(self) -> dict[str, float]:
        """The environment's ``reset(options=...)`` that give the flap this material."""
        return {
            "tissue_youngs_modulus_kpa": self.youngs_modulus_kpa,
            "tissue_thickness_mm": self.thickness_mm,
            "tissue_density_kg_m3": self.density_kg_m3,
        }


_PHYS_MED_BIOL_2019 = (
    "Phys Med Biol 2019;64(22):225001, Table 1 (tissue properties from the literature), doi:10.1088/1361-6560/ab5010"
)
_DENSITIES_2012 = "Mech Mater 2012;44:174-188, Table 3 (densities of tissues), doi:10.1016/j.mechmat.2011.08.007"
_NYLUND_2012 = (
    "wall thickness: Nylund K et al., Ultraschall Med 2012;33(7):E225-E232, doi:10.1055/s-0031-1299329 "
    "(jejunum to ileum 0.9-1.2 mm)"
)

#: Literature presets. A thickness marked "chosen" is the retracted layer, not a measurement. Walls and
#: membranes (bowel, gallbladder) are given by their in-plane tensile modulus at low strain, which is what a
#: retraction stretches; bulk organs and fat by their shear modulus (E = 3 G, near-incompressible). No
#: mesentery or peritoneum row: the values found (tens of kPa to MPa, strongly pre-tension dependent) could
#: not be traced to a source to cite.
PRESETS: tuple[TissuePreset, ...] = (
    TissuePreset(
        "liver",
        5.4,
        5.0,
        1060.0,
        "shear modulus 1.8 +- 0.4 kPa (human, quasi-static and elastography), E = 3 G; thickness chosen",
        f"{_PHYS_MED_BIOL_2019}, citing Bamber & Hill 1981 and Palmeri et al. 2008",
    ),
    TissuePreset(
        "fat",
        1.6,
        5.0,
        950.0,
        "neo-Hookean shear modulus 0.53 kPa (porcine subdermal, indentation and inverse FEA), E = 3 G; "
        "thickness chosen",
        "Sims AM et al., Biomech Model Mechanobiol 2010;9:703-711, doi:10.1007/s10237-010-0207-9; "
        f"density: {_DENSITIES_2012}",
    ),
    TissuePreset(
        "small-bowel",
        180.0,
        1.0,
        1050.0,
        "planar biaxial tension, low-strain modulus, circumferential (porcine; 307 kPa longitudinal)",
        f"Terry BS et al., Int J Exp Comput Biomech 2014;2(4); {_NYLUND_2012}; density: soft tissue, {_DENSITIES_2012}",
    ),
    TissuePreset(
        "gallbladder",
        255.0,
        3.0,
        1060.0,
        "shear modulus 85 kPa from tensile tests (human), E = 3 G; thickness: the normal wall is <= 3 mm",
        f"Karimi A et al., J Med Eng Technol 2017, doi:10.1080/03091902.2017.1366561, via {_PHYS_MED_BIOL_2019}",
    ),
)


def preset(name: str) -> TissuePreset:
    """The preset called ``name``.

    Raises:
        UnknownVariantError: Listing the preset names.
    """
    for candidate in PRESETS:
        if candidate.name == name:
            return candidate
    raise UnknownVariantError("tissue preset", name, [p.name for p in PRESETS])
