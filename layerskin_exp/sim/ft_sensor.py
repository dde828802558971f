"""The six-axis F/T reference under the skin (ATI Mini40-like): what it reads for a contact state.

It carries the whole load on the skin. Frame: origin `sensor_depth_mm` below the skin centre,
x and y along the skin's axes; force reported as the load the indenter applies, with Fz
positive in compression (the skin model's convention); torques are those of that load about
the sensor origin (z-up right-handed lever arm), plus the contact's own twisting moment.
Readings add an untared bias that drifts slowly (random walk) and white noise at the
datasheet resolution.
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.sim.rig_config import ForceTorqueConfig


class FTSynth:
    """Turns contact states into raw F/T readings (before any tare)."""

    def __init__(self, cfg: ForceTorqueConfig, rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.rng = rng
        self.bias = np.concatenate((rng.uniform(-cfg.bias_force_max_n, cfg.bias_force_max_n, 3),
                                    rng.uniform(-cfg.bias_torque_max_nm, cfg.bias_torque_max_nm, 3)))
        self.noise_std = np.array(list(cfg.force_noise_n) + list(cfg.torque_noise_nm), dtype=float)
        self._drift_std_per_sample = cfg.bias_drift_n_per_s * np.sqrt(1.0 / cfg.rate_hz)
        self._noise_block = np.empty((0, 6))
        self._k = 0

    def reseed(self, rng: np.random.Generator) -> None:
        """New noise and bias-drift draws from rng; the bias reached so far stays."""
        self.rng = rng
        self._noise_block = np.empty((0, 6))
        self._k = 0

    def _noise(self) -> np.ndarray:
        if self._k >= len(self._noise_block):  # draw in blocks: one generator call per 1024 samples
            self._noise_block = self.rng.standard_normal((1024, 6)) * self.noise_std
            self._drift_block = self.rng.standard_normal((1024, 3)) * self._drift_std_per_sample
            self._k = 0
        k = self._k
        self._k += 1
        self.bias[:3] += self._drift_block[k]
        return self._noise_block[k]

    def load(self, force_n: np.ndarray, torque_z_nmm: float, contact_xy_mm: np.ndarray) -> np.ndarray:
        """(6,) noiseless wrench [Fx, Fy, Fz, Mx, My, Mz] (N, N·m) of a contact load on the sensor."""
        fx, fy, fz = float(force_n[0]), float(force_n[1]), float(force_n[2])
        # Lever arm from the sensor origin to the contact point (m), z up; the applied force in
        # that z-up frame points down when compressive.
        rx, ry, rz = contact_xy_mm[0] * 1e-3, contact_xy_mm[1] * 1e-3, self.cfg.sensor_depth_mm * 1e-3
        gx, gy, gz = fx, fy, -fz
        mx = ry * gz - rz * gy
        my = rz * gx - rx * gz
        mz = rx * gy - ry * gx + torque_z_nmm * 1e-3
        return np.array([fx, fy, fz, mx, my, mz])

    def reading(self, force_n: np.ndarray, torque_z_nmm: float, contact_xy_mm: np.ndarray) -> np.ndarray:
        """(6,) one raw sample: load + bias + noise."""
        return self.reading_of_load(self.load(force_n, torque_z_nmm, contact_xy_mm))

    def reading_of_load(self, load: np.ndarray) -> np.ndarray:
        """(6,) one raw sample of a noiseless wrench `load` (6,): load + bias + noise (the bias
        before this sample's drift step)."""
        return load + self.bias + self._noise()
