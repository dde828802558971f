"""Regression metrics (scikit-learn's, per column)."""

from __future__ import annotations

import numpy as np
from sklearn import metrics as skm


def r2_score(y_true: np.ndarray, y_pred: np.ndarray) -> np.ndarray:
    """Coefficient of determination per column: (N,) -> scalar, (N, K) -> (K,).

    A constant reference column has no defined R²: NaN there (sklearn would report 0 or 1).
    """
    y_true = np.asarray(y_true, np.float64)
    y_pred = np.asarray(y_pred, np.float64)
    r2 = np.atleast_1d(skm.r2_score(y_true, y_pred, multioutput="raw_values", force_finite=False))
    r2 = np.where(np.ptp(y_true.reshape(len(y_true), -1), axis=0) > 0, r2, np.nan)
    return r2 if y_true.ndim > 1 else r2[0]


def mae(y_true: np.ndarray, y_pred: np.ndarray) -> np.ndarray:
    """Mean absolute error per column: (N,) -> scalar, (N, K) -> (K,)."""
    y_true = np.asarray(y_true, np.float64)
    out = skm.mean_absolute_error(y_true, np.asarray(y_pred, np.float64), multioutput="raw_values")
    return out if y_true.ndim > 1 else out[0]
