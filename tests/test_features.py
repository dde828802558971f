"""Per-frame features against closed forms: a point load, symmetric maps, rotated ellipses."""

import numpy as np
import pytest

from layerskin_exp.config import SkinConfig
from layerskin_exp.features import (
    centre_of_pressure,
    interlayer_shift,
    layer_features,
    pca_angle,
    total_pressure,
)

SKIN = SkinConfig()
X = SKIN.taxel_centres_mm()


def _gaussian(cx, cy, sx, sy, theta):
    """Anisotropic Gaussian map (16, 16), major axis at angle theta from +x, on taxel centres."""
    yy, xx = np.meshgrid(X, X, indexing="ij")
    dx, dy = xx - cx, yy - cy
    c, s = np.cos(theta), np.sin(theta)
    u, v = c * dx + s * dy, -s * dx + c * dy
    return np.exp(-0.5 * ((u / sx) ** 2 + (v / sy) ** 2))


def test_point_load_cop_is_the_taxel_centre_row_is_y_column_is_x():
    m = np.zeros((16, 16))
    m[3, 12] = 2.0  # row 3 -> y, column 12 -> x
    c = centre_of_pressure(m, SKIN, eps=0.0)
    assert c == pytest.approx([X[12], X[3]])
    assert total_pressure(m) == pytest.approx(2.0)


def test_cop_matches_weighted_mean_and_eps_shrinks_towards_origin():
    rng = np.random.default_rng(1)
    maps = rng.random((7, 3, 16, 16))
    yy, xx = np.meshgrid(X, X, indexing="ij")
    p = maps.sum(axis=(-2, -1))
    ref = np.stack([(maps * xx).sum((-2, -1)) / (0.5 + p), (maps * yy).sum((-2, -1)) / (0.5 + p)], -1)
    np.testing.assert_allclose(centre_of_pressure(maps, SKIN, eps=0.5), ref, rtol=1e-12)
    assert centre_of_pressure(np.zeros((16, 16)), SKIN) == pytest.approx([0, 0])


@pytest.mark.parametrize("theta", [-1.2, -0.5, 0.0, 0.3, 0.9, 1.4])
def test_pca_angle_recovers_ellipse_orientation(theta):
    m = _gaussian(1.0, -2.0, 4.0, 1.5, theta)
    assert pca_angle(m, SKIN, eps=0.0) == pytest.approx(theta, abs=0.02)


def test_pca_angle_matches_numpy_weighted_covariance():
    rng = np.random.default_rng(2)
    m = rng.random((16, 16)) ** 4
    yy, xx = np.meshgrid(X, X, indexing="ij")
    c = np.cov(np.stack([xx.ravel(), yy.ravel()]), aweights=m.ravel(), bias=True)
    ref = 0.5 * np.arctan2(2 * c[0, 1], c[0, 0] - c[1, 1])
    assert pca_angle(m, SKIN, eps=0.0) == pytest.approx(ref, abs=1e-12)


def test_layer_features_batch_equals_per_frame_and_shift_is_difference():
    rng = np.random.default_rng(3)
    s, d = rng.random((2, 5, 16, 16))
    f = layer_features(s, SKIN)
    for i in range(5):
        g = layer_features(s[i], SKIN)
        assert f["total"][i] == pytest.approx(g["total"])
        np.testing.assert_allclose(f["cop_mm"][i], g["cop_mm"])
        assert f["angle_rad"][i] == pytest.approx(g["angle_rad"])
    np.testing.assert_allclose(interlayer_shift(s, d, SKIN),
                               centre_of_pressure(s, SKIN) - centre_of_pressure(d, SKIN))


def test_shifted_map_moves_cop_by_the_shift():
    a = _gaussian(0.0, 0.0, 2.0, 2.0, 0.0)
    b = _gaussian(1.5, -3.0, 2.0, 2.0, 0.0)
    np.testing.assert_allclose(interlayer_shift(b, a, SKIN, eps=0.0), [1.5, -3.0], atol=1e-3)
