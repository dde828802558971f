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


def _features(n=600, seed=0):
    """Synthetic per-layer moments: the force is linear in the superficial layer's CoP and total
    (so its own linear model reads it) and the deep layer's moments are noise."""
    rng = np.random.default_rng(seed)
    cop_s, cop_d = rng.uniform(-8, 8, (n, 2)), rng.uniform(-8, 8, (n, 2))
    p_s, p_d = rng.uniform(1, 5, n), rng.uniform(1, 5, n)
    y = np.column_stack([0.3 * cop_s[:, 0], -0.2 * cop_s[:, 1], -p_s]) + 0.01 * rng.standard_normal((n, 3))
    f = {"cop_s": cop_s, "cop_d": cop_d, "p_s": p_s, "p_d": p_d}
    m_tr = np.arange(n) < 400
    return f, y, m_tr, ~m_tr


def test_a_single_layer_cnn_is_held_to_the_linear_model_of_its_own_layer():
    from analysis.sections.force import _same_inputs_baseline

    f, y, m_tr, m_te = _features()
    two_layer = {"Fx": 0.5, "Fy": 0.5, "Fz": 0.5}
    name, r2 = _same_inputs_baseline("T-s5", f, y, m_tr, m_te, two_layer)
    assert (name, r2) == ("the linear baseline", two_layer)
    sup_name, sup = _same_inputs_baseline("S-s5", f, y, m_tr, m_te, two_layer)
    assert "superficial" in sup_name and min(sup.values()) > 0.99
    deep_name, deep = _same_inputs_baseline("D-s5", f, y, m_tr, m_te, two_layer)
    assert "deep" in deep_name and max(deep.values()) < 0.1
    st = training_state(_hist(1.0, 0.5, 0.6), max_epochs=10, patience=1)
    # a superficial CNN that learned less than its own layer's linear model is flagged, naming it
    why = convergence_caveats(st, {"Fx": 0.5, "Fy": 0.5, "Fz": 0.9}, sup, sup_name)
    assert len(why) == 1 and "far below the linear model of the superficial layer's moments" in why[0]
    # a deep CNN that reads no force from noise is not a training failure: its own baseline reads none either
    assert convergence_caveats(st, {"Fx": 0.0, "Fy": 0.0, "Fz": 0.05}, deep, deep_name) == []
