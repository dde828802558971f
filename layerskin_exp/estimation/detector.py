"""A causal slip detector: what the offline cue pipeline becomes when it must run live.

The offline score (`slip.cue_score`) filters forwards and backwards, differentiates with
centred differences, smooths with a centred window and normalises by statistics of the very
trial it scores; none of that exists at the moment a frame arrives. Here every step uses only
the past: a Butterworth band-pass run forwards with its state (started at the steady state of
the first sample, so a loaded start is not a step), a backward difference, the RMS of the last
`envelope_s`, and a normalisation (x − median)/MAD whose median and MAD were frozen when the
detector was fitted. The threshold and the latency offset are fitted on training trials to
maximise trial-macro F1, exactly as the study's offline settings are.

`score_samples` (whole signal) and `stream().update` (one sample at a time) compute the same
numbers (tested).
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, find_peaks, sosfilt, sosfilt_zi
from sklearn.exceptions import NotFittedError

from layerskin_exp.estimation.config import SlipConfig
from layerskin_exp.estimation.slip import CueTrial, _best, f1_score, f1_table, match_events


class SlipDetector:
    """Causal slip detector on one tactile cue sampled uniformly at fs_hz.

    Hyperparameters: fs_hz, band_hz, band_order, envelope_s, tolerance_s (event matching),
    offsets_s (latency offsets tried), n_thresholds. Fitted: median_, mad_ (envelope statistics
    of the training trials), threshold_ (score units), offset_s_ (added to event times), f1_
    (training trial-macro F1).
    """

    def __init__(self, fs_hz: float, band_hz=(0.3, 12.0), band_order: int = 2, envelope_s: float = 0.060,
                 tolerance_s: float = 0.100, offsets_s=(-0.2, 0.2, 0.01), n_thresholds: int = 40) -> None:
        self.fs_hz = float(fs_hz)
        self.band_hz = tuple(float(v) for v in band_hz)
        self.band_order = int(band_order)
        self.envelope_s = float(envelope_s)
        self.tolerance_s = float(tolerance_s)
        self.offsets_s = tuple(float(v) for v in offsets_s)
        self.n_thresholds = int(n_thresholds)

    @classmethod
    def from_config(cls, cfg: SlipConfig, fs_hz: float) -> SlipDetector:
        return cls(fs_hz, cfg.band_hz, cfg.band_order, cfg.envelope_s, cfg.tolerance_s,
                   (cfg.offset_min_s, cfg.offset_max_s, cfg.offset_step_s), cfg.n_thresholds)

    def get_params(self) -> dict:
        return {"fs_hz": self.fs_hz, "band_hz": list(self.band_hz), "band_order": self.band_order,
                "envelope_s": self.envelope_s, "tolerance_s": self.tolerance_s, "offsets_s": list(self.offsets_s),
                "n_thresholds": self.n_thresholds}

    # -- the causal score --------------------------------------------------------------------
    def sos(self) -> np.ndarray:
        lo, hi = self.band_hz
        return butter(self.band_order, [lo, min(hi, 0.45 * self.fs_hz)], btype="band", fs=self.fs_hz, output="sos")

    def window(self) -> int:
        return max(1, int(round(self.envelope_s * self.fs_hz)))

    def envelope(self, signal) -> np.ndarray:
        """(N,) cue -> (N,) RMS envelope of the band-passed backward difference (cue units / s)."""
        x = np.asarray(signal, np.float64)
        if x.size == 0:
            return x.copy()
        sos = self.sos()
        y = sosfilt(sos, x, zi=sosfilt_zi(sos) * x[0])[0]
        d2 = (np.diff(y, prepend=y[0]) * self.fs_hz) ** 2
        w = self.window()
        c = np.cumsum(np.r_[np.zeros(w), d2])  # zeros before the start: the first windows are partly empty
        return np.sqrt(np.maximum(c[w:] - c[:-w], 0.0) / w)

    def score_samples(self, signal) -> np.ndarray:
        """(N,) cue -> (N,) slip score in units of the training envelope's MAD."""
        self._check_fitted()
        return (self.envelope(signal) - self.median_) / self.mad_

    def _candidates(self, signal, t_s) -> tuple[np.ndarray, np.ndarray]:
        s = self.score_samples(signal)
        idx, _ = find_peaks(s)
        return np.asarray(t_s, np.float64)[idx], s[idx]

    # -- fitting -----------------------------------------------------------------------------
    def fit(self, signals: list, t_s: list, truths: list) -> SlipDetector:
        """Per training trial: cue (N_i,), its times (N_i,) s, vision slip times (E_i,) s."""
        if not signals:
            raise ValueError("SlipDetector.fit needs at least one training trial")
        env = np.concatenate([self.envelope(s) for s in signals])
        self.median_ = float(np.median(env))
        mad = float(np.median(np.abs(env - self.median_)))
        self.mad_ = mad if mad > 0 else 1.0
        trials = [CueTrial(*self._candidates(s, t), np.asarray(e, np.float64), 0)
                  for s, t, e in zip(signals, t_s, truths, strict=True)]
        scores = np.concatenate([tr.cand_score for tr in trials] + [np.zeros(1)])
        self.thresholds_ = np.unique(np.quantile(scores, np.linspace(0.0, 1.0, self.n_thresholds)))
        offsets = self.offset_grid()
        table = f1_table(trials, offsets, self.thresholds_, self.tolerance_s)
        j, k = _best(table.mean(axis=0))
        self.offset_s_, self.threshold_ = float(offsets[j]), float(self.thresholds_[k])
        self.f1_ = float(table[:, j, k].mean())
        return self

    def offset_grid(self) -> np.ndarray:
        lo, hi, step = self.offsets_s
        return np.arange(lo, hi + 1e-9, step)

    def _check_fitted(self) -> None:
        if not hasattr(self, "median_"):
            raise NotFittedError("This SlipDetector is not fitted yet: call fit(signals, t_s, truths) or load an "
                                 "artifact.")

    # -- using it ----------------------------------------------------------------------------
    def events(self, signal, t_s, threshold: float | None = None) -> np.ndarray:
        """Detected slip times (E,) s: score peaks at or above the threshold, plus the latency offset."""
        ct, cs = self._candidates(signal, t_s)
        return ct[cs >= (self.threshold_ if threshold is None else threshold)] + self.offset_s_

    def score(self, signals: list, t_s: list, truths: list) -> float:
        """Trial-macro F1 of the fitted detector on these trials (events matched within ±tolerance_s)."""
        f1 = [f1_score(*match_events(self.events(s, t), e, self.tolerance_s))
              for s, t, e in zip(signals, t_s, truths, strict=True)]
        return float(np.mean(f1)) if f1 else float("nan")

    def stream(self) -> SlipStream:
        self._check_fitted()
        return SlipStream(self)

    def to_dict(self) -> dict:
        self._check_fitted()
        return {**self.get_params(), "median": self.median_, "mad": self.mad_, "threshold": self.threshold_,
                "offset_s": self.offset_s_, "train_f1": self.f1_}

    @classmethod
    def from_dict(cls, d: dict) -> SlipDetector:
        obj = cls(d["fs_hz"], d["band_hz"], d["band_order"], d["envelope_s"], d["tolerance_s"], d["offsets_s"],
                  d["n_thresholds"])
        obj.median_, obj.mad_, obj.threshold_ = float(d["median"]), float(d["mad"]), float(d["threshold"])
        obj.offset_s_, obj.f1_ = float(d["offset_s"]), float(d.get("train_f1", float("nan")))
        return obj


class SlipStream:
    """The detector one sample at a time: update(x) -> (score, slip).

    slip is True at the sample that confirms a detected event: the score has just fallen after a
    local maximum (a plateau counts once, at its middle, as scipy's find_peaks takes it) at or
    above the threshold; the event itself was one sample (or half a plateau) earlier. The events
    are those of `SlipDetector.events` on the whole signal (tested).
    The band-pass is scipy's transposed direct form II, section by section, with its state kept
    between samples; the envelope keeps the last `window` squared differences.
    """

    def __init__(self, det: SlipDetector) -> None:
        self.det = det
        self.sos = [tuple(float(v) for v in row) for row in det.sos()]
        self.zi_unit = sosfilt_zi(det.sos())
        self.fs, self.w = det.fs_hz, det.window()
        self.median, self.inv_mad, self.threshold = det.median_, 1.0 / det.mad_, det.threshold_
        self.reset()

    def reset(self) -> None:
        self.state: list[list[float]] | None = None
        self.prev_y = 0.0
        self.ring = [0.0] * self.w
        self.i = 0
        self.prev_s: float | None = None
        self.rise_at: int | None = None  # where the score last rose: a peak's plateau starts there
        self.last_peak: int | None = None  # sample index of the last confirmed event

    def update(self, x: float) -> tuple[float, bool]:
        x = float(x)
        if self.state is None:
            self.state = [[float(a) * x, float(b) * x] for a, b in self.zi_unit]
            first = True
        else:
            first = False
        y = x
        for (b0, b1, b2, _a0, a1, a2), z in zip(self.sos, self.state, strict=True):
            out = b0 * y + z[0]
            z[0] = b1 * y - a1 * out + z[1]
            z[1] = b2 * y - a2 * out
            y = out
        d = 0.0 if first else (y - self.prev_y) * self.fs
        self.prev_y = y
        self.ring[self.i % self.w] = d * d
        self.i += 1
        env = (sum(self.ring) / self.w) ** 0.5
        s = (env - self.median) * self.inv_mad
        n, prev, event = self.i - 1, self.prev_s, False
        if prev is not None:
            if s > prev:
                self.rise_at = n
            elif s < prev and self.rise_at is not None:
                event = prev >= self.threshold
                if event:
                    self.last_peak = (self.rise_at + n - 1) // 2
                self.rise_at = None
        self.prev_s = s
        return s, event
