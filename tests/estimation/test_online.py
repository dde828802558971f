"""The live path reproduces the offline one: same frames, same preprocessing, same numbers."""

import numpy as np
import pytest
import torch
from scipy.signal import find_peaks

from layerskin_exp.estimation import DownsampleStream, Estimator, OnlineEstimator
from layerskin_exp.estimation.online import GruHeads
from layerskin_exp.estimation.preprocess import smooth_downsample

DT_NS = 2_360_000


def _replay(online, counts, t0_ns=10**9):
    """Every new estimate of a raw trial fed frame by frame: {frame k: Estimate}."""
    out = {}
    for i, frame in enumerate(counts):
        e = online.update(frame[0], frame[1], t0_ns + i * DT_NS)
        if e is not None and e.new:
            out[e.frame] = e
    return out


def test_downsample_stream_equals_the_offline_preprocessing(fitted_estimator):
    est, raw = fitted_estimator
    counts = raw[0][0]
    t_ns = 10**9 + np.arange(len(counts)) * DT_NS
    offline = est.preprocessor.transform(counts)
    stream = DownsampleStream(est.preprocessor)
    got = {}
    for frame, t in zip(counts, t_ns, strict=True):
        for k, maps, t_k in stream.push(frame, t):
            got[k] = (maps, t_k)
    k_all = sorted(got)
    # Every frame but the last, whose offline filter repeats the trial's final sample (future).
    assert k_all == list(range(len(offline) - 1))
    np.testing.assert_allclose(np.stack([got[k][0] for k in k_all]), offline[:-1], rtol=1e-5, atol=1e-6)
    # Its time is the filter applied to the frames' times, as the report times its frames.
    t_off = smooth_downsample(t_ns.astype(np.float64), 5, 5)
    np.testing.assert_allclose([got[k][1] for k in k_all], t_off[:-1], rtol=0, atol=1)
    np.testing.assert_array_equal([got[k][1] for k in k_all[1:]], t_ns[2 + 5 * np.array(k_all[1:])])


def test_gru_heads_in_numpy_equal_torch(fitted_estimator):
    est, _ = fitted_estimator
    model = est.force_model.model_
    heads = GruHeads(model)
    seq = torch.randn(1, 5, 64)
    with torch.no_grad():
        ref = model.heads(seq)[0].numpy()
    got = heads.run([heads.project(x) for x in seq[0].numpy()])
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("backend", ["torch", "onnx"])
def test_replaying_a_trial_gives_the_offline_force_and_slip_score(fitted_estimator, tmp_path, backend):
    est, raw = fitted_estimator
    path = est.save(tmp_path / "T-s5.pt")
    online = OnlineEstimator.from_artifact(path, threads=None, backend=backend)
    for counts, _ in raw[:2]:
        online.reset()
        got = _replay(online, counts)
        force = est.force_from_counts(counts)
        score = est.slip_score_from_counts(counts)
        # Frames 0..2 complete before the 20-frame baseline is known; they are computed together
        # and only the latest is returned. The last needs the future.
        k = np.array(sorted(got))
        assert k[0] == 2 and k[-1] == len(force) - 2 and np.all(np.diff(k) == 1)
        np.testing.assert_allclose(np.stack([got[i].force_n for i in k]), force[k], rtol=0, atol=1e-4)
        # float32 maps, then a float64 filter: differences of ~1e-7 N-equivalent, here in MAD units
        np.testing.assert_allclose([got[i].slip_score for i in k], score[k], rtol=1e-5, atol=1e-4)
        # A slip is reported at the frame after a score peak at or above the threshold.
        thr = est.slip_detector.threshold_
        peaks = find_peaks(score)[0]
        peaks = peaks[(score[peaks] >= thr) & (np.abs(score[peaks] - thr) > 1e-3)]
        assert peaks.size > 0
        reported = {i - 1 for i in k if got[i].slip}
        assert {p for p in peaks if k[0] < p + 1 <= k[-1]} == reported


def test_between_downsampled_frames_the_latest_estimate_is_held(fitted_estimator):
    est, raw = fitted_estimator
    online = OnlineEstimator(est, threads=None, backend="torch")
    counts = raw[0][0]
    outs = [online.update(f[0], f[1], i * DT_NS) for i, f in enumerate(counts[:40])]
    assert all(o is None for o in outs[:19])  # no baseline yet
    new = [i for i, o in enumerate(outs) if o is not None and o.new]
    assert new == [19, 21, 26, 31, 36]  # baseline at raw 19 (frames 0-2), then frame k at raw 5k + 6
    assert outs[22].frame == outs[21].frame and not outs[22].new


def test_loading_a_bare_checkpoint_says_what_is_missing(fitted_estimator, tmp_path):
    est, _ = fitted_estimator
    path = tmp_path / "bare.pt"
    torch.save(est.force_model.state(), path)
    with pytest.raises(ValueError, match="preprocessing"):
        Estimator.load(path)
    with pytest.raises(FileNotFoundError, match="no such estimator"):
        Estimator.load(tmp_path / "missing.pt")


def test_artifact_round_trip_keeps_everything_from_counts_to_newtons(fitted_estimator, tmp_path):
    est, raw = fitted_estimator
    back = Estimator.load(est.save(tmp_path / "a.pt"))
    counts = raw[3][0]
    np.testing.assert_array_equal(back.preprocessor.layer_scale_, est.preprocessor.layer_scale_)
    np.testing.assert_allclose(back.force_from_counts(counts), est.force_from_counts(counts), rtol=0, atol=1e-6)
    np.testing.assert_allclose(back.slip_score_from_counts(counts), est.slip_score_from_counts(counts))
