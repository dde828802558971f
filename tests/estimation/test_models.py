"""Force models: the linear fit against a closed form, the CNN-GRU's shapes, training and checkpoints."""

import numpy as np
import pytest
import torch
from sklearn.exceptions import NotFittedError

from layerskin_exp.estimation.cnn import (
    CnnGru,
    CnnGruForceModel,
    batch_forward,
    input_channels,
    naive_plan,
    plan_epoch,
    segment_batches,
    shared_plan,
    weighted_smooth_l1,
)
from layerskin_exp.estimation.config import CnnConfig
from layerskin_exp.estimation.linear import LinearForceModel, linear_features
from layerskin_exp.estimation.splits import split_trials, trial_starts, window_indices


def test_linear_model_recovers_exact_coefficients():
    rng = np.random.default_rng(0)
    dc = rng.normal(size=(200, 2))
    ps, pd = rng.random(200), rng.random(200)
    X = linear_features(dc, ps, pd)
    np.testing.assert_allclose(X[:, 4], dc[:, 0] * (ps + pd) / 2)
    coef = rng.normal(size=(6, 3))
    y = X @ coef + np.array([0.1, -0.2, 0.3])
    m = LinearForceModel().fit(X, y)
    np.testing.assert_allclose(m.coef_[:6], coef, atol=1e-9)
    np.testing.assert_allclose(m.predict(X), y, atol=1e-9)


def test_split_is_by_trial_disjoint_and_seeded():
    ids = np.repeat(np.arange(40), 7)
    a = split_trials(ids, seed=3)
    b = split_trials(ids, seed=3)
    assert [len(s) for s in a] == [28, 6, 6]
    assert set(np.concatenate(a)) == set(range(40))
    assert not set(a[0]) & set(a[2])
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_windows_repeat_trial_start_and_never_cross_trials():
    trials = np.array([0, 0, 0, 1, 1, 1, 1])
    st = trial_starts(trials)
    np.testing.assert_array_equal(st, [0, 0, 0, 3, 3, 3, 3])
    w = window_indices(np.arange(7), st, 3)
    np.testing.assert_array_equal(w[3], [3, 3, 3])
    np.testing.assert_array_equal(w[5], [3, 4, 5])
    np.testing.assert_array_equal(w[1], [0, 0, 1])


def test_architecture_shapes():
    m = CnnGru(3)
    assert m.encode(torch.zeros(7, 3, 16, 16)).shape == (7, 64)
    assert m(torch.zeros(4, 5, 3, 16, 16)).shape == (4, 3)
    assert m.encoder[7].in_features == 4096
    assert input_channels(np.ones((2, 2, 16, 16)), "T").shape == (2, 3, 16, 16)


def test_shared_encoding_gives_the_same_loss_and_gradients_as_naive_batching():
    torch.manual_seed(0)
    rng = np.random.default_rng(0)
    trials = np.repeat(np.arange(4), 50)
    st = trial_starts(trials)
    x = torch.randn(len(trials), 3, 16, 16)
    y = torch.randn(len(trials), 3)
    model = CnnGru(3, dropout=0.0)
    w = torch.tensor([1.0, 2.0, 0.5])
    batches = segment_batches(np.arange(len(trials)), st, 16, 64, rng)
    assert all(len(b) <= 64 for b in batches)
    ends = batches[0]
    grads = []
    for plan in (naive_plan, shared_plan):
        model.zero_grad()
        fidx, pos = plan(ends, st, 5)
        loss = weighted_smooth_l1(batch_forward(model, x, fidx, pos), y[ends], w, 1.0)
        loss.backward()
        grads.append((loss.item(), [p.grad.clone() for p in model.parameters()], len(fidx)))
    assert grads[0][0] == pytest.approx(grads[1][0], rel=1e-5)
    for a, b in zip(grads[0][1], grads[1][1], strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
    assert grads[1][2] < grads[0][2] / 3  # shared plan encodes far fewer frames


def _toy_data(n_trials=12, n=40, seed=0):
    """Maps whose blob amplitude sets Fz and superficial/deep offset sets Fx."""
    rng = np.random.default_rng(seed)
    X = np.zeros((n_trials * n, 2, 16, 16), np.float32)
    y = np.zeros((n_trials * n, 3), np.float32)
    for k in range(n_trials):
        amp = np.abs(np.sin(np.linspace(0, np.pi, n))) * rng.uniform(0.5, 1.5)
        shift = rng.integers(-3, 4)
        for i in range(n):
            X[k * n + i, 0, 6:9, 6 + shift:9 + shift] = amp[i]
            X[k * n + i, 1, 6:9, 6:9] = amp[i] * 0.8
        y[k * n:(k + 1) * n] = np.column_stack([shift * amp * 0.3, 0 * amp, amp * 4])
    return X, y, np.repeat(np.arange(n_trials), n)


def test_cnn_trains_loss_decreases_and_checkpoint_round_trips(tmp_path):
    X, y, trials = _toy_data()
    cfg = CnnConfig(max_epochs=3, patience=3, batch_size=64, segment_windows=16, torch_threads=1, lr=2e-3)
    m = CnnGruForceModel("T-s5", cfg).fit(X, y, trials)
    assert len(m.history) == 3
    assert m.history[-1]["train_loss"] < m.history[0]["train_loss"]
    pred = m.predict(X, trials)
    assert pred.shape == (len(X), 3)
    path = tmp_path / "t-s5.pt"
    torch.save(m.state(), path)
    ck = torch.load(path, weights_only=True)
    assert set(ck) >= {"state_dict", "config", "norm"}
    m2 = CnnGruForceModel.from_state(ck, device="cpu")
    np.testing.assert_allclose(m2.predict(X, trials), pred, rtol=1e-5, atol=1e-5)


def test_fit_leaves_global_torch_state_alone_and_is_reproducible():
    X, y, trials = _toy_data(n_trials=6, n=20)
    cfg = CnnConfig(max_epochs=1, patience=1, batch_size=32, segment_windows=8)
    torch.manual_seed(123)
    before = torch.get_rng_state()
    threads = torch.get_num_threads()
    a = CnnGruForceModel("T-s5", cfg).fit(X, y, trials)
    assert torch.equal(torch.get_rng_state(), before)
    assert torch.get_num_threads() == threads
    b = CnnGruForceModel("T-s5", cfg).fit(X, y, trials)
    assert a.history == b.history
    np.testing.assert_array_equal(a.predict(X, trials), b.predict(X, trials))


def test_epoch_plan_slices_are_each_batch_shared_plan():
    rng = np.random.default_rng(1)
    trials = np.repeat(np.arange(5), 37)
    st = trial_starts(trials)
    batches = segment_batches(np.arange(len(trials)), st, 8, 32, rng)
    fidx, pos, ends, fb, wb = plan_epoch(batches, st, 5)
    for b, e in enumerate(batches):
        f_ref, p_ref = shared_plan(e, st, 5)
        np.testing.assert_array_equal(fidx[fb[b]:fb[b + 1]], f_ref)
        np.testing.assert_array_equal(pos[wb[b]:wb[b + 1]], p_ref)
        np.testing.assert_array_equal(ends[wb[b]:wb[b + 1]], e)
        # every window's frames, gathered through the plan, are the window itself
        np.testing.assert_array_equal(f_ref[p_ref], window_indices(e, st, 5))


def test_predict_before_fit_names_the_fix():
    with pytest.raises(NotFittedError, match="fit"):
        CnnGruForceModel("S-s1").predict(np.zeros((2, 2, 16, 16)))


@pytest.mark.parametrize("schedule,expected", [("constant", [1e-9] * 4), ("plateau", [1e-9, 1e-9, 5e-10, 2.5e-10])])
def test_plateau_schedule_halves_lr_after_epochs_without_improvement(schedule, expected):
    # lr so small that the validation loss cannot improve by the 1e-6 that counts as better
    X, y, trials = _toy_data(n_trials=6, n=20)
    cfg = CnnConfig(max_epochs=4, patience=10, batch_size=32, segment_windows=8, lr=1e-9, lr_schedule=schedule,
                    lr_plateau_patience=0)
    m = CnnGruForceModel("T-s1", cfg).fit(X, y, trials)
    np.testing.assert_allclose([h["lr"] for h in m.history], expected)


def test_bad_schedule_names_the_key():
    with pytest.raises(ValueError, match="analysis.cnn.lr_schedule"):
        CnnConfig(lr_schedule="cosine")


def test_cnn_params_come_from_the_constructor():
    m = CnnGruForceModel("T-s5", CnnConfig(max_epochs=2))
    assert set(m.get_params()) == {"configuration", "config", "progress"}
    m.set_params(configuration="S-s1")
    assert (m.layers, m.seq_len) == ("S", 1)


def test_prediction_does_not_depend_on_the_inference_chunk():
    """Validation and predict encode frames in chunks (PREDICT_CHUNK); chunk edges must not show.
    120 frames in chunks of 7 put chunk edges inside trials' windows."""
    X, y, trials = _toy_data(n_trials=6, n=20)
    m = CnnGruForceModel("T-s5", CnnConfig(max_epochs=1, batch_size=64, segment_windows=16)).fit(X, y, trials)
    x = torch.as_tensor(m._inputs(X))
    win = torch.as_tensor(window_indices(np.arange(len(X)), trial_starts(trials), m.seq_len))
    whole = m._predict_tensor(x, win, chunk=len(X))
    np.testing.assert_allclose(m._predict_tensor(x, win, chunk=7).numpy(), whole.numpy(), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(m._predict_tensor(x, win).numpy(), whole.numpy(), rtol=1e-5, atol=1e-5)
