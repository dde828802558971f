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
from numba import njit

from layerskin_exp.sim import mechanics as mk
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
        self.reseed(rng)

    def reseed(self, rng: np.random.Generator) -> None:
        """New noise and bias-drift draws from rng; the bias reached so far stays."""
        self.rng = rng
        self._noise = np.empty((0, 6))  # drawn, not yet used: noise (K, 6), drift steps (K, 3)
        self._drift = np.empty((0, 3))

    def _peek(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Noise (n, 6) and bias-drift steps (n, 3) of the next n samples, without using them up.
        Drawn in blocks of 1024 (one generator call each for noise, then drift)."""
        while len(self._noise) < n:
            self._noise = np.concatenate((self._noise, self.rng.standard_normal((1024, 6)) * self.noise_std))
            self._drift = np.concatenate((self._drift, self.rng.standard_normal((1024, 3)) * self._drift_std_per_sample))
        return self._noise[:n], self._drift[:n]

    def readings(self, recs: np.ndarray, held: np.ndarray) -> np.ndarray:
        """(N, 6) the next N raw samples [Fx, Fy, Fz (N), Mx, My, Mz (N m)]: sample i reads the
        load of step record recs[held[i]] (mechanics' step layout) + bias + noise, with the bias
        after its own drift step. Nothing is used up until consume()."""
        n = len(held)
        noise, drift = self._peek(n)
        out, self._bias_path = np.empty((n, 6)), np.empty((n, 3))
        _readings(recs, held, self.cfg.sensor_depth_mm * 1e-3, self.bias, noise, drift, out, self._bias_path)
        return out

    def consume(self, n: int) -> None:
        """The first n samples of the last readings() were taken: move past their draws."""
        if n > 0:
            self.bias[:3] = self._bias_path[n - 1]
            self._noise, self._drift = self._noise[n:], self._drift[n:]


@njit(cache=True, nogil=True)
def _readings(recs, held, depth_m, bias, noise, drift, out, bias_path):
    """Loads of contact states on the sensor plus bias and noise (see FTSynth.readings). The
    sensor origin lies depth_m below the skin centre; torques are those of the applied force
    about it (lever arm to the contact point, z up, the compressive force pointing down) plus
    the contact's own twisting moment."""
    bx, by, bz = bias[0], bias[1], bias[2]
    for i in range(held.shape[0]):
        r = recs[held[i]]
        fx, fy, fz = r[mk.S_FX], r[mk.S_FY], r[mk.S_FZ]
        rx, ry, gz = r[mk.S_CX] * 1e-3, r[mk.S_CY] * 1e-3, -fz
        bx += drift[i, 0]
        by += drift[i, 1]
        bz += drift[i, 2]
        bias_path[i, 0], bias_path[i, 1], bias_path[i, 2] = bx, by, bz
        out[i, 0] = fx + bx + noise[i, 0]
        out[i, 1] = fy + by + noise[i, 1]
        out[i, 2] = fz + bz + noise[i, 2]
        out[i, 3] = ry * gz - depth_m * fy + bias[3] + noise[i, 3]
        out[i, 4] = depth_m * fx - rx * gz + bias[4] + noise[i, 4]
        out[i, 5] = rx * fy - ry * fx + r[mk.S_TORQUE] * 1e-3 + bias[5] + noise[i, 5]
