"""Force-sensing-resistor transduction of one layer: pressure -> taxel conductance.

Conductance rises as a power of pressure (carbon-particle contacts percolating through the
Velostat) and saturates as the contact spots merge:
    G(p) = gain_ij (G_floor + G_sat x / (1 + x)),  x = (p / p_sat)^n.
The gain of each taxel is lognormal (fixed per seed) with two parts (`taxel_gains`): a smooth
field over the sheet (Velostat thickness and carbon loading, lamination pressure: they vary
over millimetres, so neighbouring taxels share them) and an independent part per taxel (the
contact resistance between each electrode crossing and the Velostat). A contact loads many
taxels at once, so its summed response averages the per-crossing part; and the loaded taxels sit
on the flat part of the readout divider, which compresses the smooth part too (`validate`
measures what is left: little, next to where the contact sits on the grid).
Two slow effects of the polymer come first, on the pressure the Velostat feels:
- hysteresis as a rate-independent play operator of relative width w: loading reads
  p (1 - w), unloading holds the value until p (1 + w) falls below it;
- creep: a fraction c of the response settles with time constant tau (first-order lag
  lag_k = lag_{k-1} + (1 - e^{-dt_k / tau}) (play_k - lag_{k-1})).
The arithmetic runs in the compiled kernels of `frame_kernels` (the frame pipeline calls them
per taxel inside one kernel; the functions here apply them to whole arrays).
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.sim import frame_kernels as fk
from layerskin_exp.sim.config import FSRConfig


class FSRLayer:
    """Transduction state of one 16x16 layer (hysteresis and creep memories)."""

    def __init__(self, cfg: FSRConfig, shape: tuple[int, int], rng: np.random.Generator):
        self.cfg = cfg
        self.gain = taxel_gains(rng, cfg, shape)
        self.g_sat_s = 1.0 / (cfg.saturated_kohm * 1e3)
        self.g_floor_s = 1.0 / (cfg.floor_mohm * 1e6)
        self.play = np.zeros(shape)
        self.lag = np.zeros(shape)
        self.params = fk.transduction_params(cfg, None)

    def conductance_s(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """Static conductance law (siemens) for pressures (..., 16, 16), no memory."""
        return conductance_layers((self,), np.asarray(pressure_kpa, dtype=float)[..., None, :, :])[..., 0, :, :]

    def advance(self, pressure_kpa: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
        """Run the memories over N successive frames; returns the effective pressure (N, 16, 16).

        pressure_kpa: (N, 16, 16) at successive sampling instants; dt_s: (N,) time since the
        previous sample (the first relative to the last call).
        """
        return advance_layers((self,), pressure_kpa[:, None], dt_s)[:, 0]


def taxel_gains(rng: np.random.Generator, cfg: FSRConfig, shape: tuple[int, int],
                pitch_mm: float = 1.5) -> np.ndarray:
    """Mean-one lognormal gains (shape): exp(s_sheet G + s_taxel e - (s_sheet^2 + s_taxel^2) / 2)
    with G a unit-variance Gaussian field of correlation length `sheet_correlation_mm` (white
    noise smoothed by a Gaussian kernel, drawn on a padded grid so the edges are like the
    middle) and e independent per taxel; s = sqrt(log(1 + cv^2)) for each part's CV."""
    from scipy.ndimage import gaussian_filter

    s_sheet = np.sqrt(np.log1p(cfg.sheet_gain_cv**2))
    s_taxel = np.sqrt(np.log1p(cfg.gain_cv**2))
    field = np.zeros(shape)
    if s_sheet > 0:
        sigma = cfg.sheet_correlation_mm / pitch_mm  # kernel width in taxels
        pad = int(np.ceil(3 * sigma))
        white = rng.standard_normal((shape[0] + 2 * pad, shape[1] + 2 * pad))
        smooth = gaussian_filter(white, sigma, mode="wrap")[pad:pad + shape[0], pad:pad + shape[1]]
        # a Gaussian kernel of width sigma leaves white noise with variance 1 / (4 pi sigma^2)
        field = smooth * np.sqrt(4 * np.pi * sigma * sigma) if sigma > 0 else smooth
    log_gain = s_sheet * field + s_taxel * rng.standard_normal(shape) - 0.5 * (s_sheet**2 + s_taxel**2)
    return np.exp(log_gain)


def conductance_layers(layers, pressure_kpa: np.ndarray, gain: np.ndarray | None = None) -> np.ndarray:
    """Conductance (siemens) of several layers at once: pressure (..., L, 16, 16), one FSRLayer
    per L. gain: the layers' gains stacked (L, 16, 16), if the caller keeps them."""
    if gain is None:
        gain = np.stack([np.broadcast_to(layer.gain, layers[0].play.shape) for layer in layers])
    p = np.ascontiguousarray(pressure_kpa, dtype=float)
    shape = p.shape
    p = p.reshape((-1,) + shape[-3:])
    out = np.empty_like(p)
    fk.conductance_kernel(p, np.ascontiguousarray(gain, dtype=float), layers[0].params, out)
    return out.reshape(shape)


def advance_layers(layers, pressure_kpa: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """Hysteresis and creep of several layers (same FSRConfig) over N successive frames at once.

    pressure_kpa: (N, L, 16, 16), one FSRLayer per L; dt_s: (N,). Returns the effective
    pressure (N, L, 16, 16) and updates each layer's memories (in place).
    """
    cfg = layers[0].cfg
    p = np.ascontiguousarray(pressure_kpa, dtype=float)
    play = np.stack([layer.play for layer in layers])
    lag = np.stack([layer.lag for layer in layers])
    eff = np.empty_like(p)
    fk.fsr_advance_kernel(p, np.ascontiguousarray(dt_s, dtype=float).reshape(-1), play, lag,
                          cfg.hysteresis, cfg.creep, cfg.creep_s, eff)
    for k, layer in enumerate(layers):
        layer.play[...] = play[k]
        layer.lag[...] = lag[k]
    return eff
