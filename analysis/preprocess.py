"""Preprocessing of raw two-layer counts: smoothing, downsampling, baseline and per-layer scale.

The study smooths each trial with a moving average of 5 and then averages groups of 5 samples.
Both are linear, so they are applied together as one 9-tap triangular filter evaluated only at
the kept samples (each input frame is read about twice instead of ten times). Baseline
subtraction commutes with them and is done on the (5x fewer) downsampled frames.
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.features import DEFAULT_EPS, moments


def _tap_weights(window: int, factor: int) -> np.ndarray:
    """Integer weights of moving-average(window) followed by block-mean(factor); sum = window*factor."""
    return np.convolve(np.ones(window, dtype=np.int64), np.ones(factor, dtype=np.int64))


def smooth_downsample(x: np.ndarray, window: int = 5, factor: int = 5, chunk: int = 256) -> np.ndarray:
    """Moving average of `window` (centred, edge values repeated) then means of `factor` samples.

    x: (N, ...) along axis 0 -> (N // factor, ...) float32 (float64 if x is float64).
    A trailing remainder of fewer than `factor` samples is dropped. Works in chunks of `chunk`
    output frames so the temporaries stay in cache.
    """
    if window < 1 or window % 2 == 0:
        raise ValueError(f"window={window}: the moving average needs an odd window >= 1")
    if factor < 1:
        raise ValueError(f"factor={factor}: the downsampling factor must be >= 1")
    n = x.shape[0]
    k = n // factor
    dt = np.float64 if x.dtype == np.float64 else np.float32
    out = np.empty((k,) + x.shape[1:], dt)
    if k == 0:
        return out
    h = window // 2
    w = (_tap_weights(window, factor) / (window * factor)).astype(dt)
    n_taps = len(w)
    # Interior outputs have every tap inside x; the few at either end are done from clipped indices.
    i0 = min(k, -(-h // factor))
    i1 = max(i0, min(k, (n - n_taps + h) // factor + 1))
    tmp = np.empty((min(chunk, max(i1 - i0, 1)),) + x.shape[1:], dt)
    for a in range(i0, i1, chunk):
        b = min(i1, a + chunk)
        m, o, t = b - a, out[a:b], tmp[: b - a]
        s = factor * a - h
        np.multiply(x[s:s + factor * (m - 1) + 1:factor], w[0], out=o)
        for j in range(1, n_taps):
            np.multiply(x[s + j:s + j + factor * (m - 1) + 1:factor], w[j], out=t)
            o += t
    edge = np.r_[np.arange(0, i0), np.arange(i1, k)].astype(np.int64)
    if edge.size:
        idx = np.clip(edge[:, None] * factor - h + np.arange(n_taps)[None, :], 0, n - 1)
        out[edge] = np.tensordot(w, x[idx].astype(dt), axes=([0], [1]))
    return out


def trial_baseline(counts: np.ndarray, n_frames: int) -> np.ndarray:
    """Per-taxel baseline: median of the first n_frames raw frames. counts (N, L, 16, 16) -> (L, 16, 16)."""
    if counts.shape[0] == 0:
        raise ValueError("an empty skin stream has no baseline; drop the trial")
    return np.median(counts[: max(1, n_frames)], axis=0).astype(np.float32)


def subtract_baseline(maps: np.ndarray, baseline: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """(maps − baseline) clipped at 0, divided by a per-layer scale, in place when maps is float32.

    maps (K, L, 16, 16) float32, baseline (L, 16, 16), scale (L,) or None.
    """
    maps -= baseline
    np.maximum(maps, 0, out=maps)
    if scale is not None:
        maps *= (1.0 / np.asarray(scale, np.float32))[:, None, None]
    return maps


def layer_scale(maps, percentile: float) -> np.ndarray:
    """Per-layer normalisation: the given percentile of frame totals, (K, L, 16, 16) -> (L,).

    maps may also be a list of per-trial (K_i, L, 16, 16) arrays (the same result as their
    concatenation, without building it).

    After dividing by it, a strongly loaded frame has a total of about 1 in every layer, which puts
    the weaker deep layer on the superficial layer's scale (needed for |p_s − p_d|).
    """
    if isinstance(maps, np.ndarray):
        totals = maps.sum(axis=(-2, -1))  # (K, L)
    else:
        totals = np.concatenate([m.sum(axis=(-2, -1)) for m in maps])
    s = np.percentile(totals, percentile, axis=0)
    return np.where(s > 0, s, 1.0).astype(np.float32)


def preprocess_counts(counts: np.ndarray, window: int = 5, factor: int = 5,
                      baseline_frames: int = 20) -> np.ndarray:
    """Raw counts of one trial (N, L, 16, 16) uint16 -> smoothed, downsampled, baseline-free maps.

    Returns (N // factor, L, 16, 16) float32 in counts above baseline (>= 0), not yet scaled.
    """
    base = trial_baseline(counts, baseline_frames)
    return subtract_baseline(smooth_downsample(counts, window, factor), base)


def two_layer_features(maps: np.ndarray, skin=None, eps: float = DEFAULT_EPS) -> dict[str, np.ndarray]:
    """Features of both layers of preprocessed maps (K, 2, 16, 16), [superficial, deep].

    Returns per-layer totals p_s, p_d (K,), CoPs cop_s, cop_d (K, 2) mm, angles angle_s, angle_d
    (K,) rad, and the inter-layer shift dc = cop_s − cop_d (K, 2) mm.
    """
    m = moments(maps, skin)  # fields (K, 2)
    d = eps + m.total
    cx, cy = m.sx / d, m.sy / d
    cxx = m.sxx / d - cx * cx
    cyy = m.syy / d - cy * cy
    cxy = m.sxy / d - cx * cy
    ang = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    cop = np.stack([cx, cy], axis=-1)  # (K, 2 layers, 2)
    return {"p_s": m.total[:, 0], "p_d": m.total[:, 1], "cop_s": cop[:, 0], "cop_d": cop[:, 1],
            "angle_s": ang[:, 0], "angle_d": ang[:, 1], "dc": cop[:, 0] - cop[:, 1]}
