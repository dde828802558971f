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

from layerskin_exp.sim.clocks import lognormal_unit_mean
from layerskin_exp.sim.config import FSRConfig


class FSRLayer:
    """Transduction state of one 16x16 layer (hysteresis and creep memories)."""

    def __init__(self, cfg: FSRConfig, shape: tuple[int, int], rng: np.random.Generator):
        self.cfg = cfg
        self.gain = lognormal_unit_mean(rng, cfg.gain_cv, shape)
        self.g_sat_s = 1.0 / (cfg.saturated_kohm * 1e3)
        self.g_floor_s = 1.0 / (cfg.floor_mohm * 1e6)
        self.play = np.zeros(shape)
        self.lag = np.zeros(shape)

    def conductance_s(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """Static conductance law (siemens) for pressures (..., 16, 16), no memory."""
        return _conductance(pressure_kpa, self.gain, self.cfg, self.g_floor_s, self.g_sat_s)

    def advance(self, pressure_kpa: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
        """Run the memories over N successive frames; returns the effective pressure (N, 16, 16).

        pressure_kpa: (N, 16, 16) at successive sampling instants; dt_s: (N,) time since the
        previous sample (the first relative to the last call).
        """
        return advance_layers((self,), pressure_kpa[:, None], dt_s)[:, 0]


def _conductance(pressure_kpa, gain, cfg, g_floor_s, g_sat_s):
    """gain (G_floor + G_sat x / (1 + x)); the power law only where the pressure is positive."""
    if cfg.exponent > 0 and pressure_kpa.size and pressure_kpa.min() >= 0.0:
        # no negative pressures: x(0) = 0 gives the floor exactly, no masking needed
        x = pressure_kpa / cfg.saturation_kpa
        x **= cfg.exponent
        sat = x * g_sat_s
        sat /= 1.0 + x
        sat += g_floor_s
        return gain * sat
    pos = pressure_kpa > 0.0
    x = (pressure_kpa[pos] / cfg.saturation_kpa) ** cfg.exponent
    sat = np.zeros(pressure_kpa.shape)
    sat[pos] = g_sat_s * x / (1.0 + x)
    sat += g_floor_s
    return gain * sat


def conductance_layers(layers, pressure_kpa: np.ndarray, gain: np.ndarray | None = None) -> np.ndarray:
    """Conductance (siemens) of several layers at once: pressure (N, L, 16, 16), one FSRLayer per L.
    gain: the layers' gains stacked (L, 16, 16), if the caller keeps them."""
    if gain is None:
        gain = np.stack([layer.gain for layer in layers])
    first = layers[0]
    return _conductance(pressure_kpa, gain, first.cfg, first.g_floor_s, first.g_sat_s)


_CHUNK = 256  # frames per closed-form creep block (keeps the (chunk, chunk) matrix small)
_GEMM_SERIAL = 262144  # m*n*k up to which OpenBLAS stays on one thread (threads stall on a busy host)


def _product(mat: np.ndarray, x: np.ndarray) -> np.ndarray:
    """mat (n, n) @ x (n, m) as column blocks small enough for single-threaded GEMMs."""
    cols = max(_GEMM_SERIAL // max(mat.shape[0] * mat.shape[1], 1), 1)
    if x.shape[1] <= cols:
        return mat @ x
    return np.concatenate([mat @ x[:, c:c + cols] for c in range(0, x.shape[1], cols)], axis=1)


def advance_layers(layers, pressure_kpa: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """Hysteresis and creep of several layers (same FSRConfig) over N successive frames at once.

    pressure_kpa: (N, L, 16, 16), one FSRLayer per L; dt_s: (N,). Returns the effective
    pressure (N, L, 16, 16) and updates each layer's memories. The play operator runs frame by
    frame (two ufuncs per frame for all layers); the creep lag, a linear first-order filter, is
    its closed form lag_k = e^{-c_k} lag_0 + sum_{j<=k} alpha_j e^{-(c_k - c_j)} play_j with
    c = cumsum(dt) / tau, one small matrix product per block.
    """
    cfg = layers[0].cfg
    w, c = cfg.hysteresis, cfg.creep
    p = np.maximum(pressure_kpa, 0.0)
    lo, hi = p * (1.0 - w), p * (1.0 + w)
    plays = np.empty_like(p)
    lags = np.empty_like(p)
    play = np.stack([layer.play for layer in layers])
    lag = np.stack([layer.lag for layer in layers])
    dt = np.maximum(np.asarray(dt_s, dtype=float), 0.0) / cfg.creep_s
    alpha = 1.0 - np.exp(-dt)
    for lo_k, hi_k, out_k in zip(lo, hi, plays, strict=True):  # views: no indexing per frame
        np.maximum(play, lo_k, out=out_k)
        play = np.minimum(out_k, hi_k, out=out_k)
    for a in range(0, p.shape[0], _CHUNK):
        b = min(a + _CHUNK, p.shape[0])
        cum = np.cumsum(dt[a:b])
        gap = cum[:, None] - cum[None, :]
        # lower triangle; above it gap < 0, or gap = 0 with dt = 0 so alpha_j = 0: exact zeros
        mat = np.where(gap >= 0.0, alpha[a:b][None, :] * np.exp(-np.maximum(gap, 0.0)), 0.0)
        blk = _product(mat, plays[a:b].reshape(b - a, -1)).reshape(plays[a:b].shape)
        blk += np.exp(-cum)[(slice(None),) + (None,) * lag.ndim] * lag
        lags[a:b] = blk
        lag = blk[-1]
    if p.shape[0]:
        play_all, lag_all = plays[-1].copy(), lags[-1].copy()  # (L, ...): each layer keeps a view
        for n, layer in enumerate(layers):
            layer.play, layer.lag = play_all[n], lag_all[n]
    return (1.0 - c) * plays + c * lags
