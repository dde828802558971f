"""Regression metrics against their definitions."""

import numpy as np
import pytest

from analysis.metrics import mae, r2_score


def test_metrics_match_definitions():
    y = np.array([[1.0, 2.0], [2.0, 4.0], [3.0, 9.0]])
    p = np.array([[1.0, 3.0], [2.5, 4.0], [2.0, 8.0]])
    r2 = r2_score(y, p)
    assert r2[0] == pytest.approx(1 - (0.25 + 1) / 2)
    np.testing.assert_allclose(mae(y, p), [0.5, 2 / 3])
