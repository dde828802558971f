"""The spacer lattice's parameters (`sim.spacer`), below both the skin's config (`config.SimConfig`)
and the spacer's law (`spacer.SpacerLaw`), which the config's sheet rigidity reaches through
`laminate`: kept apart so the three import no circle."""

from __future__ import annotations

import math
from dataclasses import dataclass

from layerskin_exp.config import require

# A regular hexagonal honeycomb has its walls in three directions. Cut along one of them, two
# thirds of the wall material crosses the cut (the walls at +-60 deg) and one third lies along it.
CROSSING_SHARE = 2.0 / 3.0


def positive(value: float, key: str, what: str = "must be > 0") -> None:
    require(value is not None and value > 0, key, value, what)


@dataclass
class SpacerConfig:
    """The compliant lattice between the two FSR layers.

    Ecoflex 00-10 has a 100 % modulus of 55 kPa (Smooth-On datasheet) and an initial Young's
    modulus of roughly 40-55 kPa; 10 % thinner lowers it, hence 35 kPa for the solid walls.
    A hexagonal honeycomb of cell pitch `cell_mm` and wall thickness `wall_mm` has solid fraction
    2t/P (1 - t/2P); loaded along its prism axis its modulus is fraction x E and its transverse
    shear modulus about half the solid's shear modulus times the fraction (Gibson & Ashby).
    """

    modulus_kpa: float = 35.0  # Young's modulus of the (thinned) solid silicone
    poisson: float = 0.49  # silicone is nearly incompressible
    thickness_mm: float = 2.5  # lattice height
    cell_mm: float = 2.0  # hexagonal cell pitch (the "feature size")
    wall_mm: float = 0.5  # wall thickness of the lattice
    width_mm: float = 26.0  # side of the square spacer pad (24 mm array + border)
    confinement_length_mm: float = 2.0  # half-width of the squeezed region (~ indenter radius), sets S
    lattice_contrast: float = 0.25  # relative depth of the cell pattern seen by the deep layer
    # width of the pad's solid silicone rim at its sides; 0: the lattice runs out to them (the
    # study describes a lattice; the 3D reference has no rim); None: what the lattice leaves beyond
    # its last full wall (`lattice_rim_mm`, as the reference's section is built)
    rim_mm: float | None = 0.0

    def __post_init__(self) -> None:
        positive(self.modulus_kpa, "sim.spacer.modulus_kpa", "Young's modulus must be > 0 kPa")
        require(0 <= self.poisson < 0.5, "sim.spacer.poisson", self.poisson, "must lie in [0, 0.5)")
        positive(self.thickness_mm, "sim.spacer.thickness_mm", "spacer height must be > 0 mm")
        positive(self.cell_mm, "sim.spacer.cell_mm", "lattice cell pitch must be > 0 mm")
        require(self.wall_mm is not None and 0 < self.wall_mm < self.cell_mm, "sim.spacer.wall_mm", self.wall_mm,
                "wall thickness must be > 0 and smaller than the cell pitch")
        positive(self.width_mm, "sim.spacer.width_mm", "pad side must be > 0 mm")
        positive(self.confinement_length_mm, "sim.spacer.confinement_length_mm", "must be > 0 mm")
        require(self.lattice_contrast is not None and 0 <= self.lattice_contrast < 0.5,
                "sim.spacer.lattice_contrast", self.lattice_contrast, "must lie in [0, 0.5) to keep the load positive")
        require(self.rim_mm is None or 0 <= self.rim_mm < 0.5 * self.width_mm, "sim.spacer.rim_mm", self.rim_mm,
                f"the solid rim's width must lie in [0, {0.5 * self.width_mm:g}) mm (half the pad's side), "
                "or null for what the lattice leaves beyond its last full wall")

    @property
    def solid_fraction(self) -> float:
        """Relative density of the hexagonal honeycomb (0..1)."""
        r = self.wall_mm / self.cell_mm
        return min(2.0 * r * (1.0 - 0.5 * r), 0.95)

    @property
    def densification_strain(self) -> float:
        """Compressive strain at which the bulging walls fill the voids (1 - solid fraction)."""
        return 1.0 - self.solid_fraction

    @property
    def lattice_modulus_kpa(self) -> float:
        """Out-of-plane (prism-axis) modulus of the lattice, kPa."""
        return self.solid_fraction * self.modulus_kpa

    @property
    def shear_modulus_kpa(self) -> float:
        """Transverse shear modulus of the open lattice, kPa (~ fraction/2 x solid G)."""
        return 0.5 * self.solid_fraction * self.solid_shear_modulus_kpa

    @property
    def solid_shear_modulus_kpa(self) -> float:
        return self.modulus_kpa / (2.0 * (1.0 + self.poisson))

    @property
    def section_wall_mm(self) -> float:
        """Width of a wall crossing a straight cut through the lattice, as a plane-strain wall:
        the crossing walls' share of the material over a cell, times (1 - nu^2) (a plane-strain
        wall is that much stiffer in compression)."""
        return CROSSING_SHARE * self.solid_fraction * self.cell_mm * (1.0 - self.poisson ** 2)

    @property
    def lattice_rim_mm(self) -> float:
        """What the lattice leaves as solid rim: the silicone between the outer face of the last
        full wall (walls centred on multiples of the cell pitch from the pad's centre) and the
        pad's side, 0.78 mm for the study's design. The reference's section is built so."""
        half, w = 0.5 * self.width_mm, self.section_wall_mm
        k_last = math.floor((half - 0.5 * w) / self.cell_mm + 1e-9)
        return half - (k_last * self.cell_mm + 0.5 * w)

    @property
    def rim_width_mm(self) -> float:
        """The pad's solid rim as the fast model's foundation and side load take it: `rim_mm`, or
        `lattice_rim_mm` where that is None. Whether the study's cast pad has such a border, and
        how wide, the study does not say; `rim_mm=0` is a pad whose lattice runs out to its sides."""
        return self.lattice_rim_mm if self.rim_mm is None else float(self.rim_mm)
