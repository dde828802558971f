"""Preprocessing of raw two-layer counts: smoothing, downsampling, baseline and per-layer scale.

`Preprocessor` holds the whole rule (raw counts -> scaled maps) with its fitted layer scale, so
a saved model carries it; `DownsampleStream` applies the same rule one raw frame at a time.

The study smooths each trial with a moving average of 5 and then averages groups of 5 samples.
Both are linear, so they are applied together as one 9-tap triangular filter evaluated only at
the kept samples (each input frame is read about twice instead of ten times). Baseline
subtraction commutes with them and is done on the (5x fewer) downsampled frames.
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted


def _tap_weights(window: int, factor: int) -> np.ndarray:
    """Integer weights of moving-average(window) followed by block-mean(factor); sum = window*factor."""
    return np.convolve(np.ones(window, dtype=np.int64), np.ones(factor, dtype=np.int64))


def smooth_downsample(x: np.ndarray, window: int = 5, factor: int = 5, chunk: int = 256) -> np.ndarray:
    """Moving average of `window` (centred, edge values repeated) then means of `factor` samples.

    x: (N, ...) along axis 0 -> (N // factor, ...) float32 (float64 if x is float64).
    A trailing remainder of fewer than `factor` samples is dropped. Works in chunks of `chunk`
    output frames so the temporaries stay in cache.
    """
    if window < 1 or window % 2 == 0:
        raise ValueError(f"window={window}: the moving average needs an odd window >= 1")
    if factor < 1:
        raise ValueError(f"factor={factor}: the downsampling factor must be >= 1")
    n = x.shape[0]
    k = n // factor
    dt = np.float64 if x.dtype == np.float64 else np.float32
    out = np.empty((k,) + x.shape[1:], dt)
    if k == 0:
        return out
    h = window // 2
    w = (_tap_weights(window, factor) / (window * factor)).astype(dt)
    n_taps = len(w)
    # Interior outputs have every tap inside x; the few at either end are done from clipped indices.
    i0 = min(k, -(-h // factor))
    i1 = max(i0, min(k, (n - n_taps + h) // factor + 1))
    tmp = np.empty((min(chunk, max(i1 - i0, 1)),) + x.shape[1:], dt)
    for a in range(i0, i1, chunk):
        b = min(i1, a + chunk)
        m, o, t = b - a, out[a:b], tmp[: b - a]
        s = factor * a - h
        np.multiply(x[s:s + factor * (m - 1) + 1:factor], w[0], out=o)
        for j in range(1, n_taps):
            np.multiply(x[s + j:s + j + factor * (m - 1) + 1:factor], w[j], out=t)
            o += t
    edge = np.r_[np.arange(0, i0), np.arange(i1, k)].astype(np.int64)
    if edge.size:
        idx = np.clip(edge[:, None] * factor - h + np.arange(n_taps)[None, :], 0, n - 1)
        out[edge] = np.tensordot(w, x[idx].astype(dt), axes=([0], [1]))
    return out


def trial_baseline(counts: np.ndarray, n_frames: int) -> np.ndarray:
    """Per-taxel baseline: median of the first n_frames raw frames. counts (N, L, 16, 16) -> (L, 16, 16)."""
    if counts.shape[0] == 0:
        raise ValueError("an empty skin stream has no baseline; drop the trial")
    return np.median(counts[: max(1, n_frames)], axis=0).astype(np.float32)


def subtract_baseline(maps: np.ndarray, baseline: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """(maps − baseline) clipped at 0, divided by a per-layer scale, in place when maps is float32.

    maps (K, L, 16, 16) float32, baseline (L, 16, 16), scale (L,) or None.
    """
    maps -= baseline
    np.maximum(maps, 0, out=maps)
    if scale is not None:
        maps *= (1.0 / np.asarray(scale, np.float32))[:, None, None]
    return maps


def layer_scale(maps, percentile: float) -> np.ndarray:
    """Per-layer normalisation: the given percentile of frame totals, (K, L, 16, 16) -> (L,).

    maps may also be a list of per-trial (K_i, L, 16, 16) arrays (the same result as their
    concatenation, without building it).

    After dividing by it, a strongly loaded frame has a total of about 1 in every layer, which puts
    the weaker deep layer on the superficial layer's scale (needed for |p_s − p_d|).
    """
    if isinstance(maps, np.ndarray):
        totals = maps.sum(axis=(-2, -1))  # (K, L)
    else:
        totals = np.concatenate([m.sum(axis=(-2, -1)) for m in maps])
    s = np.percentile(totals, percentile, axis=0)
    return np.where(s > 0, s, 1.0).astype(np.float32)


def preprocess_counts(counts: np.ndarray, window: int = 5, factor: int = 5,
                      baseline_frames: int = 20) -> np.ndarray:
    """Raw counts of one trial (N, L, 16, 16) uint16 -> smoothed, downsampled, baseline-free maps.

    Returns (N // factor, L, 16, 16) float32 in counts above baseline (>= 0), not yet scaled.
    """
    base = trial_baseline(counts, baseline_frames)
    return subtract_baseline(smooth_downsample(counts, window, factor), base)


class Preprocessor(TransformerMixin, BaseEstimator):
    """Raw counts -> maps the models take: the study's preprocessing, fitted (scikit-learn manners).

    Hyperparameters (constructor; get_params / set_params): ma_window, downsample (samples),
    baseline_frames (raw frames at a trial's start whose per-taxel median is its baseline),
    scale_percentile. Fitted: layer_scale_ (L,) counts, the scale_percentile-th percentile of the
    training frames' per-layer totals above baseline; dividing by it puts a strongly loaded frame
    near 1 in every layer.

    `fit` and `transform` take the same input, raw counts: one trial (N, L, 16, 16) uint16, or a
    list of trials (each trial has its own baseline, so trials are never concatenated before this
    step). transform returns the same form: (N // downsample, L, 16, 16) float32 >= 0 per trial.
    A model trained on these maps is tied to this layer_scale_: a new skin (other gains, other
    spacer) means fitting the Preprocessor and the model again on its own campaign.
    """

    def __init__(self, ma_window: int = 5, downsample: int = 5, baseline_frames: int = 20,
                 scale_percentile: float = 99.0) -> None:
        self.ma_window = ma_window
        self.downsample = downsample
        self.baseline_frames = baseline_frames
        self.scale_percentile = scale_percentile

    @classmethod
    def from_config(cls, pp) -> Preprocessor:
        """From a PreprocessConfig (or anything with its fields)."""
        return cls(pp.ma_window, pp.downsample, pp.baseline_frames, pp.scale_percentile)

    def unscaled(self, counts: np.ndarray) -> np.ndarray:
        """One trial's raw counts -> smoothed, downsampled, baseline-free maps in counts (not yet
        divided by the layer scale; needs no fit)."""
        return preprocess_counts(np.asarray(counts), self.ma_window, self.downsample, self.baseline_frames)

    def fit(self, X, y=None) -> Preprocessor:
        """Layer scale from raw counts: one trial (N, L, 16, 16) or a list of trials. y is ignored."""
        del y
        return self.fit_unscaled([self.unscaled(c) for c in _trials(X)])

    def fit_unscaled(self, maps) -> Preprocessor:
        """Layer scale from maps already through `unscaled` ((K, L, 16, 16) or a list of trials):
        the same fit as `fit` on their raw counts, for callers that keep only the reduced maps."""
        self.layer_scale_ = layer_scale(maps, self.scale_percentile)
        return self

    def scale(self, maps: np.ndarray) -> np.ndarray:
        """Divide unscaled float32 maps (K, L, 16, 16) by the layer scale, in place; returns them."""
        maps *= (1.0 / self._scale())[None, :, None, None]
        return maps

    def transform(self, X):
        """Raw counts, one trial (N, L, 16, 16) or a list of trials -> scaled maps in the same form."""
        self._scale()  # not fitted: fail before any work
        if isinstance(X, np.ndarray):
            return self.scale(self.unscaled(X))
        return [self.scale(self.unscaled(c)) for c in X]

    def _scale(self) -> np.ndarray:
        check_is_fitted(self, "layer_scale_",
                        msg="This %(name)s has no layer scale yet: call fit(raw_counts) or load a fitted artifact.")
        return np.asarray(self.layer_scale_, np.float32)

    def to_dict(self) -> dict:
        return {"ma_window": int(self.ma_window), "downsample": int(self.downsample),
                "baseline_frames": int(self.baseline_frames), "scale_percentile": float(self.scale_percentile),
                "layer_scale": [float(v) for v in self._scale()],
                "smoothing": "centred moving average of ma_window (edge values repeated), then means of "
                             "downsample samples: one triangular filter of ma_window+downsample-1 taps",
                "baseline": "per taxel, median of the first baseline_frames raw frames; maps = "
                            "max(filtered - baseline, 0) / layer_scale"}

    @classmethod
    def from_dict(cls, d: dict) -> Preprocessor:
        keys = ("ma_window", "downsample", "baseline_frames", "scale_percentile", "layer_scale")
        missing = [k for k in keys if k not in d]
        if missing:
            raise ValueError(f"preprocess record lacks {', '.join(missing)}: not written by Preprocessor.to_dict; "
                             "re-run the report to write a new artifact")
        obj = cls(d["ma_window"], d["downsample"], d["baseline_frames"], d["scale_percentile"])
        obj.layer_scale_ = np.asarray(d["layer_scale"], np.float32)
        return obj


def _trials(X) -> list[np.ndarray]:
    """One trial (N, L, 16, 16) or a sequence of them -> a list of trials."""
    if isinstance(X, np.ndarray):
        if X.ndim != 4:
            raise ValueError(f"raw counts of shape {X.shape}: expected one trial (N, layers, rows, cols) "
                             "or a list of such trials")
        return [X]
    trials = [np.asarray(c) for c in X]
    if not trials:
        raise ValueError("no trials to fit the layer scale on")
    return trials


class DownsampleStream:
    """The Preprocessor's rule applied one raw frame at a time (a causal view of a centred filter).

    Downsampled frame k is the 9-tap triangular filter (for 5 and 5) centred between raw frames 5k
    and 5k+4, i.e. over raw frames 5k-2 .. 5k+6, the first frame repeated before the start. It is
    complete when raw frame 5k+6 arrives: the stream emits one downsampled frame every 5 raw
    frames, 4 raw frames (9.4 ms at 424 Hz) after the last frame of its block. The baseline (median
    of the first baseline_frames raw frames) is known only after those frames; downsampled frames
    completed before that are held and emitted together then. The end of a trial, where the
    offline filter repeats the last frame, is never emitted (it needs the future).
    push(frame (L, 16, 16) counts, t_ns) -> list of (k, maps (L, 16, 16) float32 scaled, t_ns of
    frame k: the same filter applied to the raw frames' times).
    """

    def __init__(self, pre: Preprocessor) -> None:
        self.pre = pre
        self.factor, self.h = int(pre.downsample), int(pre.ma_window) // 2
        self.w = (_tap_weights(pre.ma_window, pre.downsample) / (pre.ma_window * pre.downsample)).astype(np.float32)
        self.w_t = _tap_weights(pre.ma_window, pre.downsample) / (pre.ma_window * pre.downsample)  # float64
        self.inv_scale = (1.0 / pre._scale())[:, None, None]
        self.reset()

    def reset(self) -> None:
        """Start a new trial: the next frame is raw frame 0 (a new baseline is taken)."""
        self.n = 0  # raw frames seen
        self.k = 0  # next downsampled frame index
        self.recent: dict[int, tuple] = {}  # raw index -> (frame, t_ns), the last n_taps frames and frame 0
        self.first: list[np.ndarray] = []  # raw frames for the baseline, until it is known
        self.baseline: np.ndarray | None = None
        self.pending: list[tuple[int, np.ndarray]] = []

    def push(self, frame: np.ndarray, t_ns: int = 0) -> list[tuple[int, np.ndarray, int]]:
        i = self.n
        self.n += 1
        self.recent[i] = (frame, int(t_ns))
        n_taps = self.w.size
        if i - n_taps > 0:  # frame 0 stays: the first outputs repeat it
            self.recent.pop(i - n_taps, None)
        if self.baseline is None:
            self.first.append(frame)
            if len(self.first) >= max(1, self.pre.baseline_frames):
                self.baseline = np.median(np.stack(self.first), axis=0).astype(np.float32)
                self.first = []
        out = []
        lo = self.factor * self.k - self.h
        if i == lo + n_taps - 1:  # the last tap of frame k has arrived
            taps = [self.recent[max(lo + j, 0)] for j in range(n_taps)]
            o = taps[0][0] * self.w[0]
            for j in range(1, n_taps):
                o += taps[j][0] * self.w[j]
            t0 = taps[0][1]  # relative to the first tap: ns since boot do not fit a float64 mantissa's ns
            t_k = t0 + round(sum(wj * (t - t0) for wj, (_, t) in zip(self.w_t, taps, strict=True)))
            self.pending.append((self.k, o, t_k))
            self.k += 1
        if self.baseline is not None and self.pending:
            for k, o, t_k in self.pending:
                o -= self.baseline
                np.maximum(o, 0, out=o)
                o *= self.inv_scale
                out.append((k, o, t_k))
            self.pending = []
        return out
