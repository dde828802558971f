"""A small fitted estimator on closed-form raw counts, shared by the estimation tests."""

import numpy as np
import pytest

from layerskin_exp.estimation import CnnGruForceModel, Estimator, Preprocessor, SlipDetector
from layerskin_exp.estimation.config import CnnConfig

YY, XX = np.mgrid[0:16, 0:16]


def raw_trial(rng, n=230, amp=600.0):
    """(n, 2, 16, 16) uint16 counts: a Gaussian press that moves, after 30 unloaded frames; and
    the force (n, 3) N it stands for (Fz ~ amplitude, Fx ~ superficial/deep offset)."""
    s = np.linspace(0, 1, n)
    load = amp * np.interp(s, [0, 0.13, 0.5, 1], [0, 0, 1, 0.3]) * rng.uniform(0.6, 1.4)
    shift = 2.0 * np.sin(2 * np.pi * s * rng.uniform(0.5, 2))
    cx, cy = rng.uniform(5, 10, 2)
    sup = load[:, None, None] * np.exp(-((XX - cx - shift[:, None, None]) ** 2 + (YY - cy) ** 2) / 6)
    deep = 0.5 * load[:, None, None] * np.exp(-((XX - cx) ** 2 + (YY - cy) ** 2) / 10)
    counts = np.stack([sup, deep], axis=1) + 100 + rng.normal(0, 2, (n, 2, 16, 16))
    force = np.column_stack([0.002 * shift * load, 0 * load, load / 150])
    return np.clip(counts, 0, 4095).astype(np.uint16), force


@pytest.fixture(scope="session")
def fitted_estimator():
    rng = np.random.default_rng(7)
    raw = [raw_trial(rng) for _ in range(8)]
    pre = Preprocessor().fit([c for c, _ in raw])
    maps = pre.transform([c for c, _ in raw])
    X = np.concatenate(maps)
    y = np.concatenate([f[: len(f) // 5 * 5].reshape(-1, 5, 3).mean(axis=1) for _, f in raw]).astype(np.float32)
    trials = np.concatenate([np.full(len(m), i) for i, m in enumerate(maps)])
    model = CnnGruForceModel("T-s5", CnnConfig(max_epochs=2, patience=2, batch_size=64, segment_windows=16,
                                                device="cpu")).fit(X, y, trials)
    # A detector on the inter-layer cue, fitted on made-up slip times: only its arithmetic is tested here.
    sig = [np.abs(m.sum(axis=(-2, -1))[:, 0] - m.sum(axis=(-2, -1))[:, 1]) for m in maps]
    t_s = [np.arange(len(m)) / 84.8 for m in maps]
    det = SlipDetector(84.8).fit(sig, t_s, [np.array([0.2, 0.4])] * len(sig))
    return Estimator(pre, model, det, "interlayer"), raw
