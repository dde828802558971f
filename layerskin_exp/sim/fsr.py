"""Force-sensing-resistor transduction of one layer: pressure -> taxel conductance.

Conductance rises as a power of pressure (carbon-particle contacts percolating through the
Velostat) and saturates as the contact spots merge:
    G(p) = gain_ij (G_floor + G_sat x / (1 + x)),  x = (p / p_sat)^n.
The gain of each taxel is lognormal (fixed per seed): sheet thickness and lamination vary.
Two slow effects of the polymer come first, on the pressure the Velostat feels:
- hysteresis as a rate-independent play operator of relative width w: loading reads
  p (1 - w), unloading holds the value until p (1 + w) falls below it;
- creep: a fraction c of the response settles with time constant tau (first-order lag).
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.sim.config import FSRConfig


class FSRLayer:
    """Transduction state of one 16x16 layer (hysteresis and creep memories)."""

    def __init__(self, cfg: FSRConfig, shape: tuple[int, int], rng: np.random.Generator):
        self.cfg = cfg
        sigma = cfg.gain_sigma
        # mean-one lognormal gains
        self.gain = np.exp(rng.normal(-0.5 * sigma**2, sigma, size=shape)) if sigma > 0 else np.ones(shape)
        self.g_sat_s = 1.0 / (cfg.saturated_kohm * 1e3)
        self.g_floor_s = 1.0 / (cfg.floor_mohm * 1e6)
        self.play = np.zeros(shape)
        self.lag = np.zeros(shape)

    def conductance_s(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """Static conductance law (siemens) for pressures (..., 16, 16), no memory."""
        x = (np.maximum(pressure_kpa, 0.0) / self.cfg.saturation_kpa) ** self.cfg.exponent
        return self.gain * (self.g_floor_s + self.g_sat_s * x / (1.0 + x))

    def advance(self, pressure_kpa: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
        """Run the memories over N successive frames; returns the effective pressure (N, 16, 16).

        pressure_kpa: (N, 16, 16) at successive sampling instants; dt_s: (N,) time since the
        previous sample (the first relative to the last call).
        """
        w, c = self.cfg.hysteresis, self.cfg.creep
        alpha = 1.0 - np.exp(-np.maximum(dt_s, 0.0) / self.cfg.creep_s)
        out = np.empty_like(pressure_kpa)
        play, lag = self.play, self.lag
        for k in range(pressure_kpa.shape[0]):
            p = np.maximum(pressure_kpa[k], 0.0)
            play = np.clip(play, p * (1.0 - w), p * (1.0 + w))
            lag = lag + alpha[k] * (play - lag)
            out[k] = (1.0 - c) * play + c * lag
        self.play, self.lag = play, lag
        return out
