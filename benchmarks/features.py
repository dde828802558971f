"""Preprocessing + features throughput (raw two-layer frames per second, one core).

Vectorised path: `smooth_downsample` (one 9-tap filter at the kept samples), baseline and scale,
then both layers' moments from one matrix product. Baseline: a per-frame Python loop doing the
same arithmetic frame by frame (moving average, block mean, then features per kept frame).
"""

from __future__ import annotations

import os
import time

import numpy as np

from layerskin_exp.config import SkinConfig
from layerskin_exp.estimation.preprocess import smooth_downsample, subtract_baseline
from layerskin_exp.features import layer_features, two_layer_features


def _vectorised(counts, base, scale, skin):
    maps = subtract_baseline(smooth_downsample(counts, 5, 5), base, scale)
    return two_layer_features(maps, skin)


def _naive(counts, base, scale, skin):
    n = counts.shape[0]
    x = counts.astype(np.float32)
    out = []
    for k in range(n // 5):
        acc = np.zeros(counts.shape[1:], np.float32)
        for i in range(5 * k, 5 * k + 5):
            lo, hi = max(0, i - 2), min(n - 1, i + 2)
            win = [x[min(max(j, lo), hi)] for j in range(i - 2, i + 3)]
            acc += sum(win) / 5
        m = np.maximum(acc / 5 - base, 0) / scale[:, None, None]
        out.append((layer_features(m[0], skin), layer_features(m[1], skin)))
    return out


def run(n_frames: int = 400_000, n_naive: int = 5_000) -> dict:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    skin = SkinConfig()
    rng = np.random.default_rng(0)
    counts = rng.integers(0, 4096, (n_frames, 2, 16, 16), dtype=np.uint16)
    base = np.full((2, 16, 16), 200, np.float32)
    scale = np.array([1e5, 5e4], np.float32)
    _vectorised(counts[:10_000], base, scale, skin)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        _vectorised(counts, base, scale, skin)
        best = min(best, time.perf_counter() - t0)
    t0 = time.perf_counter()
    _naive(counts[:n_naive], base, scale, skin)
    naive = n_naive / (time.perf_counter() - t0)
    fast = n_frames / best
    return {"frames_per_s": round(fast), "naive_loop_frames_per_s": round(naive),
            "speedup": round(fast / naive, 1), "target_frames_per_s": 1_000_000,
            "note": "one frame = one two-layer 2x16x16 uint16 scan; BLAS threads as set by OMP_NUM_THREADS"}


if __name__ == "__main__":
    print(run())
