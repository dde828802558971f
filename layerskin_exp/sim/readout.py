"""Passive-matrix readout: row multiplexer, column voltage dividers, ADC.

Each layer is a 16x16 network of taxel conductances between 16 row and 16 column lines. The
multiplexer connects one row to the supply through its on-resistance; the other rows float
(a tiny leak to ground keeps the nodal matrix regular); every column goes to ground through its
divider resistor, whose voltage the ADC samples. Current from the driven row finds sneak paths
through pressed taxels on other rows, so a pressed rectangle's fourth corner lights up (ghost).

Nodal analysis: Y (32x32) over rows and columns; with Z = Y^-1, driving row i through g_on
gives V_cols = Vs g_on Z[cols, i] / (1 + g_on Z[i, i]) (Sherman-Morrison on the source branch),
so one batched inverse per frame yields all 16 row readings (computed by eliminating the
column nodes first, which leaves a 16x16 inverse).
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.sim.config import ReadoutConfig


class MatrixReadout:
    def __init__(self, cfg: ReadoutConfig, adc_bits: int, n: int = 16):
        self.cfg = cfg
        self.n = n
        self.full_scale = float(2**adc_bits - 1)
        self.g_div = 1.0 / (cfg.divider_kohm * 1e3)
        self.g_leak = 1.0 / (cfg.leak_mohm * 1e6)
        self.r_on = cfg.mux_on_ohm

    def column_volts(self, g_s: np.ndarray) -> np.ndarray:
        """Column voltages (M, 16, 16) [driven row, column] for conductances g_s (M, 16, 16)."""
        vs = self.cfg.supply_v
        if not self.cfg.crosstalk:
            # each taxel alone in series with the mux and its divider
            r_div = 1.0 / self.g_div
            return vs * r_div / (self.r_on + 1.0 / g_s + r_div)
        # Block elimination of the column nodes (diagonal block Dc): the row-node Schur complement
        # S = Dr - G Dc^-1 G^T gives Z_rows = S^-1 and Z[cols, rows] = Dc^-1 G^T S^-1, so only a
        # 16x16 inverse per frame is needed.
        d_r = g_s.sum(axis=2) + self.g_leak  # (M, rows)
        d_c = g_s.sum(axis=1) + self.g_div  # (M, cols)
        g_over = g_s / d_c[:, None, :]
        s_mat = -g_over @ np.swapaxes(g_s, 1, 2)
        n = self.n
        s_mat.reshape(len(s_mat), n * n)[:, ::n + 1] += d_r  # the diagonal, as a strided view
        z_rr = np.linalg.inv(s_mat)
        z_rc = z_rr @ g_over  # [m, driven row i, column j] = Z[n + j, i] (S is symmetric)
        z_ii = z_rr.reshape(len(z_rr), n * n)[:, ::n + 1][:, :, None]
        if self.r_on > 0:
            g_on = 1.0 / self.r_on
            return vs * g_on * z_rc / (1.0 + g_on * z_ii)
        return vs * z_rc / z_ii

    def counts(self, volts: np.ndarray) -> np.ndarray:
        """Ideal ratiometric conversion (float counts, before offsets, noise and rounding)."""
        return volts / self.cfg.supply_v * self.full_scale
