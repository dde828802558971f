"""Slip-event detection offline: vision ground truth, acausal cue scores, matching, LOTO settings.

The causal detector that can run live is `layerskin_exp.estimation.detector.SlipDetector`.

All times are in seconds on the session's common timeline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import butter, find_peaks, sosfiltfilt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching

from layerskin_exp.estimation.config import SlipConfig


def _sorted_finite(x) -> np.ndarray:
    a = np.asarray(x, np.float64).ravel()
    return np.sort(a[~np.isnan(a)])


def match_events(detected, truth, tolerance: float) -> tuple[int, int, int]:
    """Maximum one-to-one matching of detected to true event times within ±tolerance s.

    Returns (tp, fp, fn). Maximum, not greedy-nearest: a detection between two true events is
    given to whichever leaves the most pairs matched. Events on a line with a symmetric window
    form a convex bipartite graph (each detection reaches a contiguous run of the sorted truths,
    and both ends of that run move forward with the detection), where one sweep in time order is
    a maximum matching: the earliest detection takes the earliest true event in its reach, and
    an event out of reach of the current detection is out of reach of every later one on that
    side. tests/estimation/test_slip.py checks it against scipy's linear_sum_assignment.
    """
    d, t = _sorted_finite(detected), _sorted_finite(truth)
    n_d, n_t = int(np.asarray(detected).size), int(np.asarray(truth).size)
    tp = i = j = 0
    while i < d.size and j < t.size:
        if d[i] - t[j] > tolerance:  # truth j is before every remaining detection's window
            j += 1
        elif t[j] - d[i] > tolerance:  # detection i reaches no remaining truth
            i += 1
        else:
            tp, i, j = tp + 1, i + 1, j + 1
    return tp, n_d - tp, n_t - tp


def matched_pairs(detected, truth, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (into detected, into truth) of a maximum one-to-one matching within ±tolerance."""
    d = np.asarray(detected, np.float64).ravel()
    t = np.asarray(truth, np.float64).ravel()
    if d.size == 0 or t.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rows, cols = np.nonzero(np.abs(d[:, None] - t[None, :]) <= tolerance)
    graph = csr_matrix((np.ones(rows.size), (rows, cols)), shape=(d.size, t.size))
    m = maximum_bipartite_matching(graph, perm_type="column")
    di = np.flatnonzero(m >= 0)
    return di, m[di]


def f1_score(tp: int, fp: int, fn: int) -> float:
    """2TP / (2TP + FP + FN); 1.0 when there was nothing to find and nothing was found."""
    den = 2 * tp + fp + fn
    return 1.0 if den == 0 else 2.0 * tp / den


def resample_uniform(t_s: np.ndarray, x: np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of x(t_s) onto a uniform grid at rate_hz spanning t_s."""
    t_s = np.asarray(t_s, np.float64)
    if t_s.size < 2:
        return t_s.copy(), np.asarray(x, np.float64).copy()
    grid = np.arange(t_s[0], t_s[-1], 1.0 / rate_hz)
    return grid, np.interp(grid, t_s, x)


def _mad(x: np.ndarray) -> float:
    return float(np.median(np.abs(x - np.median(x))))


def _filter_ok(sos: np.ndarray, n: int) -> bool:
    return n > 3 * (2 * sos.shape[0] + 1)  # sosfiltfilt's default padding needs this many samples


def vision_slip_events(t_s: np.ndarray, signal: np.ndarray, cfg: SlipConfig | None = None) -> np.ndarray:
    """Ground-truth slip times from a vision displacement (mm) or angle (°) sampled at t_s.

    Resampled onto a uniform grid at cfg.vision_rate_hz, Butterworth low-pass (cfg.truth_order,
    cfg.truth_lowpass_hz, zero phase), differentiated; peaks of |v| above
    median(|v|) + 1.4826·MAD(|v|) at least cfg.truth_min_interval_s apart. Returns (E,) s.
    """
    cfg = cfg or SlipConfig()
    grid, x = resample_uniform(t_s, signal, cfg.vision_rate_hz)
    fs = cfg.vision_rate_hz
    sos = butter(cfg.truth_order, min(cfg.truth_lowpass_hz, 0.45 * fs), btype="low", fs=fs, output="sos")
    if not _filter_ok(sos, grid.size):
        return np.zeros(0)
    speed = np.abs(np.gradient(sosfiltfilt(sos, x), 1.0 / fs))
    thr = np.median(speed) + cfg.truth_mad_k * _mad(speed)
    peaks, _ = find_peaks(speed, height=thr, distance=max(1, int(round(cfg.truth_min_interval_s * fs))))
    return grid[peaks]


def cue_score(signal: np.ndarray, fs_hz: float, cfg: SlipConfig | None = None) -> np.ndarray:
    """Slip score of a tactile cue sampled uniformly at fs_hz: (N,) -> (N,) in MAD units.

    Band-pass (zero phase) → derivative → RMS envelope over cfg.envelope_s → (x − median)/MAD.
    """
    cfg = cfg or SlipConfig()
    x = np.asarray(signal, np.float64)
    lo, hi = cfg.band_hz
    hi = min(hi, 0.45 * fs_hz)
    sos = butter(cfg.band_order, [lo, hi], btype="band", fs=fs_hz, output="sos")
    if not _filter_ok(sos, x.size):
        return np.zeros_like(x)
    deriv = np.gradient(sosfiltfilt(sos, x), 1.0 / fs_hz)
    env = np.sqrt(uniform_filter1d(deriv * deriv, size=max(1, int(round(cfg.envelope_s * fs_hz))), mode="nearest"))
    mad = _mad(env)
    return (env - np.median(env)) / (mad if mad > 0 else 1.0)


def candidates(t_s: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local maxima of a score: (times (M,) s, heights (M,))."""
    idx, _ = find_peaks(score)
    return np.asarray(t_s)[idx], score[idx]


@dataclass
class CueTrial:
    """One trial's candidates and truth for one cue."""

    cand_t_s: np.ndarray
    cand_score: np.ndarray
    truth_t_s: np.ndarray
    group: object  # grip depth


def f1_table(trials: list[CueTrial], offsets_s: np.ndarray, thresholds: np.ndarray,
             tolerance_s: float) -> np.ndarray:
    """F1[trial, offset, threshold] of detections cand_t + offset for cand_score >= threshold.

    Equal to f1_score(*match_events(...)) cell by cell: the same time-ordered sweep as
    match_events, run for every (trial, offset, threshold) cell at once with numpy. Candidates of
    all trials are concatenated in time order; per threshold, a next-candidate table skips those
    below it. Every step moves each live cell's detection or truth pointer forward, so the loop
    runs at most (candidates + truths) of the longest trial times.
    """
    offsets_s = np.asarray(offsets_s, np.float64).ravel()
    thresholds = np.asarray(thresholds, np.float64).ravel()
    n_tr, n_off, n_th = len(trials), offsets_s.size, thresholds.size
    out = np.zeros((n_tr, n_off, n_th))
    if out.size == 0:
        return out
    cand_t, cand_s, c_lo, truth, e_lo = [], [], [0], [], [0]
    for tr in trials:
        ct = np.asarray(tr.cand_t_s, np.float64).ravel()
        order = np.argsort(ct, kind="stable")
        cand_t.append(ct[order])
        cand_s.append(np.asarray(tr.cand_score, np.float64).ravel()[order])
        c_lo.append(c_lo[-1] + ct.size)
        truth.append(_sorted_finite(tr.truth_t_s))
        e_lo.append(e_lo[-1] + truth[-1].size)
    c_t, c_s, e_t = np.concatenate(cand_t), np.concatenate(cand_s), np.concatenate(truth)
    c_lo, e_lo = np.asarray(c_lo), np.asarray(e_lo)
    n_c = c_t.size
    sel = c_s[None, :] >= thresholds[:, None]  # (K, C) detections per threshold
    cum = np.c_[np.zeros((n_th, 1), np.int64), np.cumsum(sel, axis=1)]
    n_det = cum[:, c_lo[1:]] - cum[:, c_lo[:-1]]  # (K, trials) detections per threshold and trial
    n_truth = np.diff(e_lo)
    # nxt[k, c]: the first candidate at or after c that is a detection at threshold k (NaN times
    # never match, so they are skipped too but still counted as detections), else past the end.
    usable = sel & ~np.isnan(c_t)[None, :]
    pos = np.where(usable, np.arange(n_c)[None, :], n_c)
    nxt = np.c_[np.minimum.accumulate(pos[:, ::-1], axis=1)[:, ::-1], np.full((n_th, 1), n_c)].ravel()
    # One cell per (trial, offset, threshold): pointers into the concatenated candidates/truths.
    tri, off, thr = (a.ravel() for a in np.meshgrid(np.arange(n_tr), np.arange(n_off), np.arange(n_th),
                                                    indexing="ij"))
    c_end, e_end = c_lo[1:][tri], e_lo[1:][tri]
    row = thr * (n_c + 1)
    i = np.minimum(nxt[row + c_lo[:-1][tri]], c_end)
    j = e_lo[:-1][tri].copy()
    tp = np.zeros(tri.size, np.int64)
    live = np.flatnonzero((i < c_end) & (j < e_end))
    while live.size:
        il, jl = i[live], j[live]
        d = c_t[il] + offsets_s[off[live]]  # the same float sum as cand_t + offset
        t = e_t[jl]
        skip_t = d - t > tolerance_s
        skip_d = ~skip_t & (t - d > tolerance_s)
        hit = ~skip_t & ~skip_d
        adv_d = ~skip_t
        i[live[adv_d]] = np.minimum(nxt[row[live[adv_d]] + il[adv_d] + 1], c_end[live[adv_d]])
        j[live[~skip_d]] = jl[~skip_d] + 1
        tp[live[hit]] += 1
        live = live[(i[live] < c_end[live]) & (j[live] < e_end[live])]
    fp = n_det[thr, tri] - tp
    fn = n_truth[tri] - tp
    den = 2 * tp + fp + fn
    f1 = np.where(den == 0, 1.0, 2.0 * tp / np.maximum(den, 1))
    out[:] = f1.reshape(n_tr, n_off, n_th)
    return out


def _best(mean_f1: np.ndarray) -> tuple[int, int]:
    """(offset index, threshold index) of the best mean F1 [offset, threshold].

    Ties form plateaus (between two candidate scores; across the ±tolerance): take the middle
    best threshold (the widest margin to both sides), then the middle tied offset there, which
    centres the tactile events on the vision events.
    """
    best = mean_f1.max()
    ks = np.flatnonzero((mean_f1 >= best - 1e-12).any(axis=0))
    k = int(ks[len(ks) // 2])
    tied = np.flatnonzero(mean_f1[:, k] >= best - 1e-12)
    return int(tied[len(tied) // 2]), k


def evaluate_loto(trials: list[CueTrial], cfg: SlipConfig | None = None) -> dict:
    """Trial-macro F1 under leave-one-trial-out for the Global, Grip and Oracle settings.

    Global: offset and threshold maximising mean F1 over all other trials. Grip: over the other
    trials of the same grip depth (Global's choice when there are none). Oracle: the Grip offset
    with the threshold that maximises the held-out trial's own F1 (label-informed upper bound).
    """
    cfg = cfg or SlipConfig()
    n = len(trials)
    if n < 2:
        raise ValueError(f"{n} trial(s): leave-one-trial-out needs at least two")
    offsets = np.arange(cfg.offset_min_s, cfg.offset_max_s + 1e-9, cfg.offset_step_s)
    scores = np.concatenate([t.cand_score for t in trials]) if trials else np.zeros(0)
    if scores.size == 0:
        scores = np.zeros(1)
    thresholds = np.unique(np.quantile(scores, np.linspace(0.0, 1.0, cfg.n_thresholds)))
    table = f1_table(trials, offsets, thresholds, cfg.tolerance_s)
    groups = np.array([t.group for t in trials])
    res = {"global": [], "grip": [], "oracle": []}
    chosen_offsets, grip_choice = [], []
    for i in range(n):
        others = np.arange(n) != i
        jg, kg = _best(table[others].mean(axis=0))
        res["global"].append(table[i, jg, kg])
        same = others & (groups == groups[i])
        if same.any():
            jp, kp = _best(table[same].mean(axis=0))
        else:
            jp, kp = jg, kg
        res["grip"].append(table[i, jp, kp])
        res["oracle"].append(table[i, jp].max())
        chosen_offsets.append(offsets[jp])
        grip_choice.append((float(offsets[jp]), float(thresholds[kp])))
    out = {k: float(np.mean(v)) for k, v in res.items()}
    out["per_trial"] = {k: [float(x) for x in v] for k, v in res.items()}
    out["median_offset_s"] = float(np.median(chosen_offsets))
    out["grip_choice"] = grip_choice  # per held-out trial: (offset s, threshold) of the Grip setting
    out["n_trials"] = n
    out["n_truth_events"] = int(sum(t.truth_t_s.size for t in trials))
    return out


def detect(cand_t_s: np.ndarray, cand_score: np.ndarray, threshold: float, offset_s: float) -> np.ndarray:
    """Detected event times: candidates at or above threshold, shifted by the latency offset."""
    return cand_t_s[cand_score >= threshold] + offset_s
