"""The study's physics-inspired linear baseline for three-axis force."""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils.validation import check_is_fitted


def linear_features(dc_mm: np.ndarray, p_s: np.ndarray, p_d: np.ndarray) -> np.ndarray:
    """φ = [Δx, Δy, p_s, p_d, Δx·p̄, Δy·p̄] with p̄ = (p_s + p_d)/2.

    dc_mm (N, 2) inter-layer CoP shift, p_s, p_d (N,) layer totals -> (N, 6).
    """
    pbar = 0.5 * (p_s + p_d)
    return np.column_stack([dc_mm[:, 0], dc_mm[:, 1], p_s, p_d, dc_mm[:, 0] * pbar, dc_mm[:, 1] * pbar])


def layer_features(cop_mm: np.ndarray, p: np.ndarray) -> np.ndarray:
    """One layer's own moments in the baseline's form: φ = [c_x, c_y, p, c_x·p, c_y·p].

    cop_mm (N, 2) the layer's CoP in its own taxel frame, p (N,) its total -> (N, 5). What a linear
    model can read from a single layer's map, the baseline a single-layer CNN (S-, D-) is held to:
    without the other layer it has no inter-layer shift to read."""
    return np.column_stack([cop_mm[:, 0], cop_mm[:, 1], p, cop_mm[:, 0] * p, cop_mm[:, 1] * p])


class LinearForceModel(RegressorMixin, BaseEstimator):
    """Per-axis least squares with an intercept on the six features (numpy.linalg.lstsq).

    fit(X (N, 6), y (N, 3) N) / predict(X (N, 6)) -> (N, 3) N. coef_: (7, 3), last row intercept.
    """

    @staticmethod
    def _design(X: np.ndarray) -> np.ndarray:
        X = np.asarray(X, np.float64)
        return np.column_stack([X, np.ones(len(X))])

    def fit(self, X: np.ndarray, y: np.ndarray) -> LinearForceModel:
        if len(X) != len(y):
            raise ValueError(f"X has {len(X)} rows but y has {len(y)}; they must be the same frames")
        # One lstsq solves every axis at once; each column is its own independent fit.
        self.coef_ = np.linalg.lstsq(self._design(X), np.asarray(y, np.float64), rcond=None)[0]
        return self

    def predict(self, X: np.ndarray) -> np.ndarray:
        check_is_fitted(self, "coef_", msg="This %(name)s is not fitted yet: call fit(X, y) first.")
        return self._design(X) @ self.coef_
