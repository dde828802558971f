"""Characterisation against constructed campaigns with known gains, shifts and heights."""

import numpy as np
import pytest

from analysis.characterization import (
    PressTrial,
    cop_shift_at_shear,
    effective_heights,
    repeatability,
    response_at,
    slide_loads,
    uniformity,
)
from analysis.config import CharacterizationConfig

CFG = CharacterizationConfig(n_bootstrap=999)


def _press(pos, gain, peak=4.0, n=200):
    up = np.linspace(0, peak, n)
    fz = np.r_[up, up[::-1]]
    return PressTrial(pos, fz, gain * np.r_[up, 0.8 * up[::-1]] * 100)  # unloading hysteresis ignored


def test_response_is_read_on_the_loading_ramp():
    p = _press(0, 1.0)
    assert response_at(p, 2.0) == pytest.approx(200.0, rel=1e-3)
    assert np.isnan(response_at(p, 5.0))


def test_uniformity_cv_equals_gain_spread_with_bootstrap_ci():
    rng = np.random.default_rng(0)
    gains = rng.normal(1.0, 0.15, 60)
    presses = [_press(i, g) for i, g in enumerate(gains) for _ in range(3)]
    res = uniformity(presses, CFG)
    assert res["cv"] == pytest.approx(np.std(gains, ddof=1) / np.mean(gains), rel=1e-3)
    assert res["ci_low"] < res["cv"] < res["ci_high"]
    assert res["n_positions"] == 60


def test_repeatability_median_cv_and_position_exclusion():
    presses = []
    for pos in range(5):
        for g in (0.9, 1.0, 1.1):
            presses.append(_press(pos, g))
    presses += [_press(9, 1.0, peak=0.2), _press(9, 1.1, peak=3.0)]  # a press below 0.3 N excludes position 9
    res = repeatability(presses, CFG)
    assert res["n_positions"] == 5
    assert res["median_cv"] == pytest.approx(np.std([0.9, 1, 1.1], ddof=1), rel=1e-6)


def test_slide_loads_are_the_normal_load_at_shear_and_the_shear_reached():
    shear = [np.linspace(0, 2.0, 101), np.linspace(0, 1.2, 61)]  # the second slide never reaches 1.5 N
    fz = [np.where(shear[0] >= 1.5, 4.0, 3.0), np.full(61, 9.0)]
    res = slide_loads(shear, fz)
    assert res["fz_at_shear_n"] == 4.0 and res["n_frames_at_shear"] == 26
    assert res["median_max_shear_n"] == pytest.approx(1.6) and res["n_trials"] == 2
    assert slide_loads([np.linspace(0, 1.0, 5)], [np.ones(5)])["fz_at_shear_n"] is None
    assert slide_loads([], [])["n_trials"] == 0


def test_cop_shift_in_band_uses_trial_medians():
    shear = [np.linspace(0, 2.05, 100), np.linspace(0, 2.05, 100), np.linspace(0, 1.5, 50)]
    dc = [np.column_stack([s * 1.0, s * 0.0]) for s in shear[:2]] + [np.zeros((50, 2))]
    dc[1] = dc[1] * 2
    res = cop_shift_at_shear(shear, dc, CFG)
    assert res["n_trials"] == 2
    assert res["median_mm"] == pytest.approx(np.mean([2.0, 4.0]), abs=0.05)


def test_effective_heights_recover_load_dependent_h():
    rng = np.random.default_rng(1)
    fz = rng.uniform(0.5, 6.5, 5000)
    h = 1.0 + 0.6 * fz  # h grows with load
    f_shear = rng.uniform(-2, 2, (5000, 2))
    dc = -f_shear * h[:, None] / fz[:, None]  # exact moment balance: deep CoP moves with the shear
    res = effective_heights(fz, dc, f_shear, CFG)
    for b in res["bins"]:
        mid = 1.0 + 0.6 * (b["fz_low_n"] + b["fz_high_n"]) / 2
        assert b["h_x_mm"] == pytest.approx(mid, rel=0.15)
    assert res["bins"][0]["r2_x"] > 0.9
    assert res["bins"][0]["h_y_mm"] < res["bins"][-1]["h_y_mm"]
