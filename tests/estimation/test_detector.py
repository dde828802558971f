"""The causal slip detector: causal, streamable, and fitted like the study's offline settings."""

import numpy as np
import pytest
from scipy.signal import butter, lfilter, lfilter_zi
from sklearn.exceptions import NotFittedError

from layerskin_exp.estimation import SlipDetector

FS = 84.8


def _trial(rng, slips, duration=8.0, lead_s=0.05):
    """A cue with a sharp step at each slip (the tactile event leads vision by lead_s), plus noise."""
    t = np.arange(0, duration, 1 / FS)
    x = 1.0 + 0.002 * rng.normal(size=t.size)
    for s in slips:
        x += 0.3 * (t >= s - lead_s)
    return t, x


def _fitted(rng, n=4):
    trials = []
    for _ in range(n):
        slips = np.sort(rng.uniform(0.5, 7.5, 5))
        slips = slips[np.r_[True, np.diff(slips) > 0.4]]
        trials.append((*_trial(rng, slips), slips))
    # Many noise candidates: a fine threshold grid reaches the gap between noise and slips.
    det = SlipDetector(FS, n_thresholds=400).fit([x for _, x, _ in trials], [t for t, _, _ in trials], [s for _, _, s in trials])
    return det, trials


def test_score_of_the_past_does_not_change_with_the_future():
    rng = np.random.default_rng(0)
    det, trials = _fitted(rng)
    t, x, _ = trials[0]
    a = det.score_samples(x)
    y = x.copy()
    y[300:] += rng.normal(0, 1, y.size - 300)
    np.testing.assert_array_equal(det.score_samples(y)[:300], a[:300])


def test_stream_equals_whole_signal_score():
    rng = np.random.default_rng(1)
    det, trials = _fitted(rng)
    _, x, _ = trials[1]
    x = np.r_[x, np.full(5, x[-1])]  # flat at the end: the last peak falls and is confirmed
    x[200:204] = x[199] + 0.5  # a pulse in the cue: one more event
    st = det.stream()
    got = np.array([st.update(v) for v in x], dtype=object)
    np.testing.assert_allclose(got[:, 0].astype(float), det.score_samples(x), rtol=1e-9, atol=1e-9)
    # Events confirmed live are the offline events; each confirmed within one sample past its peak
    # (or its plateau's end).
    peaks = []
    for n in np.flatnonzero(got[:, 1].astype(bool)):
        st2 = det.stream()
        for v in x[: n + 1]:
            st2.update(v)
        peaks.append(st2.last_peak)
    assert len(peaks) >= 3
    t = np.arange(x.size) / FS
    np.testing.assert_allclose(t[peaks] + det.offset_s_, det.events(x, t), atol=1e-12)


def test_envelope_against_an_independent_causal_computation():
    """lfilter in transfer-function form, a loop for the difference and the trailing RMS."""
    rng = np.random.default_rng(2)
    x = np.cumsum(rng.normal(size=400)) + 5
    det = SlipDetector(FS)
    b, a = butter(2, [0.3, 12.0], btype="band", fs=FS)
    y = lfilter(b, a, x, zi=lfilter_zi(b, a) * x[0])[0]
    w = int(round(0.06 * FS))
    d = np.r_[0.0, np.diff(y)] * FS
    env = np.array([np.sqrt(np.sum(d[max(0, n - w + 1):n + 1] ** 2) / w) for n in range(x.size)])
    np.testing.assert_allclose(det.envelope(x), env, rtol=1e-6, atol=1e-9)


def test_fit_finds_the_slips_and_learns_the_latency_and_round_trips():
    rng = np.random.default_rng(3)
    det, trials = _fitted(rng)
    assert det.f1_ == pytest.approx(1.0)
    # The cue steps 50 ms before the slip and the causal band-pass delays its peak: with the
    # fitted offset, the detections land on the slips.
    t, x, s = trials[0]
    assert np.abs(det.events(x, t) - s).max() < 0.03
    held = [_trial(rng, s) + (s,) for s in ([1.0, 3.0, 5.5], [2.0, 2.6, 6.0])]
    assert det.score([x for _, x, _ in held], [t for t, _, _ in held], [s for _, _, s in held]) == pytest.approx(1.0)
    back = SlipDetector.from_dict(det.to_dict())
    t, x, _ = held[0]
    np.testing.assert_array_equal(back.events(x, t), det.events(x, t))


def test_unfitted_detector_says_to_fit():
    with pytest.raises(NotFittedError, match="fit"):
        SlipDetector(FS).score_samples(np.zeros(10))
