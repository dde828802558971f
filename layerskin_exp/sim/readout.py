"""Passive-matrix readout: row multiplexer, column voltage dividers, ADC.

Each layer is a 16x16 network of taxel conductances between 16 row and 16 column lines. The
multiplexer connects one row to the supply through its on-resistance; the other rows float
(a tiny leak to ground keeps the nodal matrix regular); every column goes to ground through its
divider resistor, whose voltage the ADC samples. Current from the driven row finds sneak paths
through pressed taxels on other rows, so a pressed rectangle's fourth corner lights up (ghost).

Nodal analysis: Y (32x32) over rows and columns; with Z = Y^-1, driving row i through g_on
gives V_cols = Vs g_on Z[cols, i] / (1 + g_on Z[i, i]) (Sherman-Morrison on the source branch),
so one factorisation per frame yields all 16 row readings (computed by eliminating the column
nodes first, which leaves a 16x16 symmetric positive-definite system; see
`frame_kernels._column_volts`, which the frame pipeline also calls).
"""

from __future__ import annotations

import numpy as np

from layerskin_exp import rig
from layerskin_exp.sim import frame_kernels as fk
from layerskin_exp.sim.config import ReadoutConfig


class MatrixReadout:
    def __init__(self, cfg: ReadoutConfig, adc_bits: int, n: int = rig.N_TAXELS):
        self.cfg = cfg
        self.n = n
        self.full_scale = float(2**adc_bits - 1)
        self.g_div = 1.0 / (cfg.divider_kohm * 1e3)
        self.g_leak = 1.0 / (cfg.leak_mohm * 1e6)
        self.r_on = cfg.mux_on_ohm
        self.params = fk.transduction_params(None, cfg, adc_bits)

    def column_volts(self, g_s: np.ndarray) -> np.ndarray:
        """Column voltages (M, 16, 16) [driven row, column] for conductances g_s (M, 16, 16)."""
        g = np.ascontiguousarray(g_s, dtype=float)
        out = np.empty_like(g)
        fk.column_volts_batch(g, self.params, out)
        return out

    def counts(self, volts: np.ndarray) -> np.ndarray:
        """Ideal ratiometric conversion (float counts, before offsets, noise and rounding)."""
        return volts / self.cfg.supply_v * self.full_scale
