"""Trials, not frames: the trial-level split and the windows that never cross a trial."""

from __future__ import annotations

import numpy as np


def split_trials(trial_ids, fractions=(0.70, 0.15, 0.15), seed: int = 0) -> tuple[np.ndarray, ...]:
    """Shuffle distinct trial ids with a fixed seed and cut them 70/15/15 (train, val, test).

    Returns three sorted arrays of trial ids; every trial is in exactly one. With fewer than
    three trials the later parts may be empty.
    """
    ids = np.unique(np.asarray(trial_ids))
    rng = np.random.default_rng(seed)
    perm = rng.permutation(ids)
    n = len(ids)
    n_val = int(round(fractions[1] * n))
    n_test = int(round(fractions[2] * n))
    if n >= 3:
        n_val, n_test = max(1, n_val), max(1, n_test)
    n_train = n - n_val - n_test
    return (np.sort(perm[:n_train]), np.sort(perm[n_train:n_train + n_val]), np.sort(perm[n_train + n_val:]))


def trial_starts(trials: np.ndarray) -> np.ndarray:
    """For every frame, the index of the first frame of its trial. trials (N,) contiguous ids."""
    trials = np.asarray(trials)
    new = np.r_[True, trials[1:] != trials[:-1]]
    return np.maximum.accumulate(np.where(new, np.arange(len(trials)), 0))


def window_indices(ends: np.ndarray, starts: np.ndarray, seq_len: int) -> np.ndarray:
    """(B, T) frame indices of the windows ending at `ends`; frames before a trial's start repeat it."""
    idx = ends[:, None] - (seq_len - 1) + np.arange(seq_len)[None, :]
    return np.maximum(idx, starts[ends][:, None])
