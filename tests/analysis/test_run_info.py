"""Training-state and caveat rules read from a saved history, and the force ranges."""

import numpy as np
import pytest

from analysis.run_info import convergence_caveats, force_ranges, training_state


def _hist(*val):
    return [{"epoch": i, "train_loss": v, "val_loss": v} for i, v in enumerate(val)]


def test_early_stopping_is_read_from_the_history_with_the_fit_rule():
    st = training_state(_hist(1.0, 0.5, 0.6, 0.7), max_epochs=10, patience=2)
    assert st == {"epochs": 4, "max_epochs": 10, "best_epoch": 2, "best_val_loss": 0.5, "early_stopped": True}
    # A drop of less than 1e-6 is not an improvement (same rule as CnnGruForceModel.fit).
    assert training_state(_hist(1.0, 1.0 - 1e-7), max_epochs=5, patience=1)["early_stopped"]


def test_a_model_still_improving_at_the_epoch_cap_is_flagged():
    st = training_state(_hist(1.0, 0.8, 0.6), max_epochs=3, patience=2)
    assert not st["early_stopped"]
    why = convergence_caveats(st, {"Fx": 0.9, "Fy": 0.9, "Fz": 0.9}, {"Fx": 0.5, "Fy": 0.5, "Fz": 0.9})
    assert len(why) == 1 and "epoch cap" in why[0]


def test_a_model_far_below_the_linear_baseline_is_flagged_and_a_good_one_is_not():
    st = training_state(_hist(1.0, 0.5, 0.6), max_epochs=10, patience=1)
    lin = {"Fx": 0.95, "Fy": 0.95, "Fz": 0.95}
    assert "linear baseline" in convergence_caveats(st, {"Fx": 0.2, "Fy": 0.3, "Fz": 0.9}, lin)[0]
    assert convergence_caveats(st, {"Fx": 0.9, "Fy": 0.9, "Fz": 0.95}, lin) == []


def test_force_ranges_cover_all_frames_and_the_test_shear_percentiles():
    f = np.zeros((200, 3))
    f[:100, 0] = np.linspace(-2, 2, 100)
    f[100:, 1] = np.linspace(0, 3, 100)
    f[:, 2] = -np.linspace(0, 6, 200)
    test = np.zeros(200, bool)
    test[100:] = True
    r = force_ranges(f, test)
    assert r["Fx"] == {"min_n": -2.0, "max_n": 2.0} and r["Fz"]["min_n"] == -6.0
    assert r["test_shear_p5_p95_n"] == pytest.approx(np.percentile(np.linspace(0, 3, 100), [5, 95]))
