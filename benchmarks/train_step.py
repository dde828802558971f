"""T-s5 training throughput on CPU: naive window batching vs encoding each frame once per batch.

(a) naive: every window's T frames go through the encoder separately (B·T encodings per batch);
(b) shared: a batch is a few contiguous segments of windows and each distinct frame is encoded
    once (≈ B + segments·(T−1) encodings). Same loss and gradients (tests/estimation/test_models.py).
"""

from __future__ import annotations

import time

import numpy as np
import torch

from layerskin_exp.estimation.cnn import (
    CnnGru,
    batch_forward,
    naive_plan,
    segment_batches,
    shared_plan,
    weighted_smooth_l1,
)
from layerskin_exp.estimation.splits import trial_starts


def _samples_per_s(plan, model, opt, x, y, batches, starts, seq_len, w) -> float:
    n = 0
    t0 = time.perf_counter()
    for ends in batches:
        fidx, pos = plan(ends, starts, seq_len)
        loss = weighted_smooth_l1(batch_forward(model, x, fidx, pos), y[torch.as_tensor(ends)], w, 1.0)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        n += len(ends)
    return n / (time.perf_counter() - t0)


def run(n_batches: int = 6, threads: int = 1) -> dict:
    torch.set_num_threads(threads)
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    trials = np.repeat(np.arange(20), 400)  # 20 trials of 400 downsampled frames
    starts = trial_starts(trials)
    x = torch.randn(len(trials), 3, 16, 16)
    y = torch.randn(len(trials), 3)
    w = torch.ones(3)
    model = CnnGru(3)
    opt = torch.optim.Adam(model.parameters(), lr=3e-4)
    batches = segment_batches(np.arange(len(trials)), starts, 64, 256, rng)[: n_batches + 1]
    _samples_per_s(shared_plan, model, opt, x, y, batches[:1], starts, 5, w)  # warm-up
    naive = _samples_per_s(naive_plan, model, opt, x, y, batches[1:], starts, 5, w)
    shared = _samples_per_s(shared_plan, model, opt, x, y, batches[1:], starts, 5, w)
    return {"threads": threads, "batch_size": 256, "seq_len": 5,
            "naive_samples_per_s": round(naive, 1), "shared_samples_per_s": round(shared, 1),
            "speedup": round(shared / naive, 2), "target_speedup": 4.0}


if __name__ == "__main__":
    print(run())
