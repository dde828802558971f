"""The lattice spacer: its compression law, shear stiffness and cell pattern.

The spacer is the nonlinear foundation under the superficial laminate (`laminate`): each column
carries the pressure of its own compression, the walls bulge into the voids and touch at the
densification strain e_d = 1 - solid fraction; beyond that the column is squeezed solid silicone.
Its transverse shear modulus stays the open lattice's while the walls buckle and rises to the
solid's once they touch.
Lengths mm, pressures kPa, stiffness per area kPa/mm.
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.sim.spacer_config import SpacerConfig

_SOLID_STRAIN_CAP = 0.85  # beyond this the squeezed-solid law continues with its tangent (no pole)
_TRANSITION = 0.02  # strain width over which the walls come into contact (smooth onset)


class SpacerLaw:
    """Pressure and shear stiffness of the spacer as functions of its local compression.

    Below the densification strain e_d the open lattice carries p = E_lat e. Beyond it the
    walls have filled the voids and the column is a thin layer of solid silicone of height
    (1 - e_d) h, squeezed between the layers. A bonded incompressible layer of current
    thickness t loaded over a half-width L compresses with E_s (1 + 2 S^2), shape factor
    S = L / 2t (Gent & Lindley), and stiffens at finite strain:
    p += E_s (1 + 2 S(e)^2) es / (1 - es), es = (e - e_d) / (1 - e_d), t = h (1 - e).
    """

    def __init__(self, cfg: SpacerConfig):
        self.cfg = cfg
        self.h_mm = cfg.thickness_mm
        self.e_lat_kpa = cfg.lattice_modulus_kpa
        self.e_solid_kpa = cfg.modulus_kpa
        self.conf_len_mm = cfg.confinement_length_mm
        self.e_d = cfg.densification_strain
        self.g_open_kpa = cfg.shear_modulus_kpa
        self.g_solid_kpa = cfg.solid_shear_modulus_kpa

    def _solid_strain(self, e):
        x = (e - self.e_d) / _TRANSITION
        over = _TRANSITION * np.logaddexp(0.0, x)  # softplus: smooth onset of wall contact
        return over / (1.0 - self.e_d)

    def _squeezed(self, e):
        es = self._solid_strain(e)
        cap = _SOLID_STRAIN_CAP
        finite = np.where(es <= cap, es / (1.0 - np.minimum(es, cap)),
                          cap / (1.0 - cap) + (es - cap) / (1.0 - cap) ** 2)
        t_mm = self.h_mm * np.maximum(1.0 - e, 0.05)
        shape = self.conf_len_mm / (2.0 * t_mm)
        return (1.0 + 2.0 * shape**2) * finite

    def pressure_kpa(self, compression_mm):
        """Normal pressure (kPa) carried by a column compressed by `compression_mm` (>= 0)."""
        e = np.clip(np.asarray(compression_mm, dtype=float) / self.h_mm, 0.0, None)
        squeezed = self._squeezed(e) - self._squeezed(0.0)  # zero at rest
        return self.e_lat_kpa * e + self.e_solid_kpa * squeezed

    def shear_stiffness_kpa_per_mm(self, compression_mm):
        """Tangential stiffness per unit area, kPa/mm: the open lattice's G over its unloaded
        height h, plus what the walls add as they come into contact, G_s - G over the current
        thickness h (1 - e).

        Before densification the compressed lattice's walls have buckled (the plateau of a
        honeycomb crushed out of plane, Gibson & Ashby ch. 4): they fold but keep their length and
        bend, so the open cells shear over the walls' height, not over the squeezed gap; the 3D
        model's lattice field shears so (its tangent under the cap 0.5-0.9 mu / H from 0.83 to 3 N,
        where G / h(1 - e) gives 2.5 mu / H: tests/sim/test_spacer_shear.py). G rises towards the
        solid's only as the walls touch, with the squeezed solid's strain beyond e_d, and that
        squeezed solid shears over what is left of the gap.
        """
        e = np.clip(np.asarray(compression_mm, dtype=float) / self.h_mm, 0.0, 0.95)
        closure = np.clip(self._solid_strain(e) - self._solid_strain(0.0), 0.0, 1.0)
        return self.g_open_kpa / self.h_mm + (self.g_solid_kpa - self.g_open_kpa) * closure / (self.h_mm * (1.0 - e))


def hex_cell_pattern(x_mm: np.ndarray, y_mm: np.ndarray, cell_mm: float, contrast: float) -> np.ndarray:
    """Fixed multiplicative load pattern of a hexagonal lattice of pitch `cell_mm`, mean 1.

    Three plane waves at 120 deg form the hexagonal cell pattern; load concentrates on the walls
    (where the sum is low the cell centre is open). Returns a factor in [1 - 2c, 1 + c], mean 1 (contrast < 0.5 keeps it positive).
    """
    k = 4.0 * np.pi / (np.sqrt(3.0) * cell_mm)  # reciprocal-lattice wave number of the hex pitch
    s = np.zeros(np.broadcast(x_mm, y_mm).shape)
    for ang in (0.0, 2.0 * np.pi / 3.0, 4.0 * np.pi / 3.0):
        s = s + np.cos(k * (np.cos(ang) * x_mm + np.sin(ang) * y_mm))
    # s ranges over [-1.5, 3] with zero mean over a cell: 3 at the cell centres (voids), low on
    # the walls, which carry the load. Mean of the returned factor is exactly 1.
    return 1.0 - contrast * s / 1.5
