"""Preprocessing against direct scipy/numpy computations of the same definitions."""

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from layerskin_exp.config import SkinConfig
from layerskin_exp.estimation.preprocess import (
    Preprocessor,
    layer_scale,
    preprocess_counts,
    smooth_downsample,
)
from layerskin_exp.features import layer_features, two_layer_features


def _reference(x, window, factor):
    ma = uniform_filter1d(x.astype(np.float64), size=window, axis=0, mode="nearest")
    k = x.shape[0] // factor
    return ma[: k * factor].reshape((k, factor) + x.shape[1:]).mean(axis=1)


@pytest.mark.parametrize("n", [1, 4, 5, 9, 13, 57, 2003])
@pytest.mark.parametrize("window,factor", [(5, 5), (3, 4), (1, 1), (7, 2)])
def test_smooth_downsample_is_moving_average_then_block_mean(n, window, factor):
    rng = np.random.default_rng(n)
    x = rng.integers(0, 4096, (n, 2, 3), dtype=np.uint16)
    got = smooth_downsample(x, window, factor, chunk=16)
    np.testing.assert_allclose(got, _reference(x, window, factor), rtol=1e-5, atol=1e-3)


def test_smooth_downsample_rejects_even_window():
    with pytest.raises(ValueError, match="window=4"):
        smooth_downsample(np.zeros((10, 2)), 4, 5)


def test_preprocess_removes_baseline_and_clips_noise():
    rng = np.random.default_rng(0)
    base = rng.integers(50, 300, (2, 16, 16))
    counts = np.repeat(base[None], 100, axis=0).astype(np.uint16)
    counts[60:, 0, 5, 6] += 1000
    maps = preprocess_counts(counts, 5, 5, baseline_frames=20)
    assert maps.shape == (20, 2, 16, 16)
    assert maps.min() >= 0
    assert maps[:11].max() < 1e-3  # before the load (frames < 55 raw) nothing is left
    assert maps[-1, 0, 5, 6] == pytest.approx(1000)
    assert maps[-1, 1].max() < 1e-3


def test_two_layer_features_match_layer_features_and_scale_normalises():
    rng = np.random.default_rng(5)
    maps = rng.random((30, 2, 16, 16)).astype(np.float32)
    maps[:, 1] *= 0.2
    s = layer_scale(maps, 100.0)
    assert maps[:, 1].sum((-2, -1)).max() / s[1] == pytest.approx(1.0)
    f = two_layer_features(maps, SkinConfig())
    g = layer_features(maps[:, 1], SkinConfig())
    np.testing.assert_allclose(f["p_d"], g["total"], rtol=1e-6)
    np.testing.assert_allclose(f["cop_d"], g["cop_mm"], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(f["angle_d"], g["angle_rad"], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(f["dc"], f["cop_s"] - f["cop_d"])


def test_layer_scale_of_trial_list_equals_that_of_their_concatenation():
    rng = np.random.default_rng(5)
    trials = [rng.gamma(2.0, 3.0, (n, 2, 16, 16)).astype(np.float32) for n in (7, 1, 40, 13)]
    for q in (50.0, 99.0, 100.0):
        np.testing.assert_array_equal(layer_scale(trials, q), layer_scale(np.concatenate(trials), q))
    totals = np.concatenate(trials).sum(axis=(-2, -1))
    np.testing.assert_allclose(layer_scale(trials, 99.0), np.percentile(totals, 99.0, axis=0), rtol=1e-6)


def _raw_trials(seed=3, n=(120, 87, 200)):
    """Raw counts of a few trials: a flat baseline per trial, then a load on a few taxels."""
    rng = np.random.default_rng(seed)
    out = []
    for k in n:
        c = np.repeat(rng.integers(80, 300, (1, 2, 16, 16)), k, axis=0)
        c[40:, 0, 3:6, 4:8] += rng.integers(200, 1500)
        c[40:, 1, 4:7, 5:8] += rng.integers(50, 400)
        out.append((c + rng.integers(0, 5, c.shape)).astype(np.uint16))
    return out


def test_preprocessor_fit_and_transform_take_raw_counts():
    raw = _raw_trials()
    pre = Preprocessor(scale_percentile=99.0).fit(raw)
    # independent of the class: per trial, the documented rule; the scale from those maps' totals
    unscaled = [preprocess_counts(c, 5, 5, 20) for c in raw]
    totals = np.concatenate([m.sum(axis=(-2, -1)) for m in unscaled])
    np.testing.assert_allclose(pre.layer_scale_, np.percentile(totals, 99.0, axis=0), rtol=1e-6)
    maps = pre.transform(raw)
    assert isinstance(maps, list) and len(maps) == len(raw)
    for m, u in zip(maps, unscaled, strict=True):
        np.testing.assert_allclose(m, u / pre.layer_scale_[None, :, None, None], rtol=1e-6)
    np.testing.assert_array_equal(pre.transform(raw[1]), maps[1])  # one trial in, one trial out
    np.testing.assert_array_equal(pre.fit_transform(raw)[0], maps[0])
    # the same fit from maps already reduced (the report keeps only those)
    np.testing.assert_array_equal(Preprocessor().fit_unscaled(unscaled).layer_scale_, pre.layer_scale_)


def test_preprocessor_params_come_from_the_constructor():
    pre = Preprocessor(ma_window=3, baseline_frames=10)
    assert pre.get_params() == {"ma_window": 3, "downsample": 5, "baseline_frames": 10, "scale_percentile": 99.0}
    pre.set_params(downsample=2)
    assert pre.downsample == 2
    c = clone(pre)
    assert c.get_params() == pre.get_params() and not hasattr(c, "layer_scale_")
    assert pre.fit(_raw_trials()).transform(_raw_trials()[0]).shape == (120 // 2, 2, 16, 16)


def test_preprocessor_not_fitted_and_bad_input_say_what_to_do():
    with pytest.raises(NotFittedError, match="call fit"):
        Preprocessor().transform(_raw_trials()[0])
    with pytest.raises(ValueError, match=r"shape \(16, 16\)"):
        Preprocessor().fit(np.zeros((16, 16), np.uint16))
    with pytest.raises(ValueError, match="lacks layer_scale"):
        Preprocessor.from_dict({"ma_window": 5, "downsample": 5, "baseline_frames": 20, "scale_percentile": 99.0})
