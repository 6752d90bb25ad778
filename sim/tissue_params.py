"""The flap's settings and its named grasp sites, without PyBullet.

:class:`TissueParams` and :data:`SITE_NAMES` are what the commands' arguments and checks need of the flap
(defaults, choices); :mod:`sim.tissue` builds the flap from them in PyBullet and re-exports both. Kept apart
so that a command can refuse a mistyped option before the simulation loads.
"""

from __future__ import annotations

from dataclasses import dataclass

from psm_control.errors import ConfigurationError
from sim.material import spring_stiffness_n_per_m

__all__ = ["SITE_NAMES", "TissueParams"]

#: Grasp sites along the free edge, as in the paper's Task III.
SITE_NAMES = ("centre", "left", "right")


@dataclass(frozen=True)
class TissueParams:
    """Physical and visual settings of the flap.

    Attributes:
        size_m: Side length of the square flap [m].
        resolution: Nodes per side (>= 4); the default 7 gives a 13 mm node spacing at 8 cm.
        youngs_modulus_kpa: Young's modulus of the tissue [kPa] (in-plane, at small strain).
        thickness_mm: Thickness of the flap [mm].
        density_kg_m3: Density [kg/m^3] (soft tissue: about 1050).
        damping: Spring damping stiffness [N s/m].
        friction: Contact friction of the flap against rigid bodies.
        rgba: Display colour (multiplies the texture).
        texture_seed: Seed of the procedural texture (:func:`sim.tissue.texture_image`); ``None`` draws the flap
            in the flat colour. Only the rendering depends on it.
        texture_path: An image file (PNG or JPEG) shown on the flap instead of the procedural texture,
            e.g. a photo of a phantom; it spans the flat flap once, its top row along the free edge.
        mark_sites: Ink a dark dot (2 mm radius) on each grasp site, as a surgeon's marker would.
        site_offset_m: The sites' offset from their named places in the flap's plane (x, y) [m], where
            the dots go.
        site_inset_m: Distance of the grasp sites in from the free edge [m].
        site_spacing_m: Distance of the left/right sites from the centre site [m].
    """

    size_m: float = 0.08
    resolution: int = 7
    youngs_modulus_kpa: float = 10.0
    thickness_mm: float = 3.0
    density_kg_m3: float = 1050.0
    damping: float = 0.05
    friction: float = 0.5
    rgba: tuple[float, float, float, float] = (0.85, 0.42, 0.42, 1.0)
    texture_seed: int | None = None
    texture_path: str | None = None
    mark_sites: bool = False
    site_offset_m: tuple[float, float] = (0.0, 0.0)
    site_inset_m: float = 0.004
    site_spacing_m: float = 0.022

    def __post_init__(self) -> None:
        if self.resolution < 4:
            raise ConfigurationError("resolution", self.resolution, "an integer >= 4 nodes per side")
        for name in ("size_m", "youngs_modulus_kpa", "thickness_mm", "density_kg_m3"):
            if not getattr(self, name) > 0:
                raise ConfigurationError(name, getattr(self, name), "a positive number")
        if self.damping < 0:
            raise ConfigurationError("damping", self.damping, "a non-negative number")

    @property
    def mass_kg(self) -> float:
        """Total mass [kg]: density x area x thickness (8 x 8 x 0.3 cm at 1050 kg/m^3 is 20 g)."""
        return self.density_kg_m3 * self.size_m**2 * self.thickness_mm * 1e-3

    @property
    def spring_stiffness_n_per_m(self) -> float:
        """Stiffness of every spring of the lattice [N/m], from E and t (:mod:`sim.material`)."""
        return spring_stiffness_n_per_m(self.youngs_modulus_kpa, self.thickness_mm, self.resolution)
