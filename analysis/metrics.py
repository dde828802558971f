"""Regression metrics and the trial-level split."""

from __future__ import annotations

import numpy as np


def r2_score(y_true: np.ndarray, y_pred: np.ndarray) -> np.ndarray:
    """Coefficient of determination per column. (N,) or (N, K) -> scalar or (K,)."""
    y_true = np.asarray(y_true, np.float64)
    y_pred = np.asarray(y_pred, np.float64)
    ss_res = ((y_true - y_pred) ** 2).sum(axis=0)
    ss_tot = ((y_true - y_true.mean(axis=0)) ** 2).sum(axis=0)
    return 1.0 - ss_res / np.where(ss_tot > 0, ss_tot, np.nan)


def mae(y_true: np.ndarray, y_pred: np.ndarray) -> np.ndarray:
    """Mean absolute error per column."""
    return np.abs(np.asarray(y_true, np.float64) - np.asarray(y_pred, np.float64)).mean(axis=0)


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
