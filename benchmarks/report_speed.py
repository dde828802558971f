"""Report hot spot: the slip F1 table.

Slip F1 table — what evaluate_loto fills once per (motion, cue): F1 for every (trial, latency
offset, threshold) cell, at the full campaign's size per trial (~600 candidates, ~150 vision
events over 67 s, 41 offsets, 40 thresholds). Fast path: layerskin_exp.estimation.slip.f1_table (one
time-ordered sweep for all cells at once). Baseline, measured in the same run on the same trials:
the previous code, one maximum matching (scipy linear_sum_assignment on the within-tolerance pair
matrix) per cell.
(The report's other stages: see the commit history of analysis/sessions.py and report.py for
full-campaign timings; loading is dominated by layerskin_exp.log, timed by benchmarks/log_read.)
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import linear_sum_assignment

from layerskin_exp.estimation.config import SlipConfig
from layerskin_exp.estimation.slip import CueTrial, f1_score, f1_table


def _match_hungarian(d, t, tol):
    if d.size == 0 or t.size == 0:
        return 0, d.size, t.size
    ok = np.abs(d[:, None] - t[None, :]) <= tol
    ok = ok[ok.any(axis=1)][:, ok.any(axis=0)]
    tp = 0
    if ok.size:
        r, c = linear_sum_assignment(ok, maximize=True)
        tp = int(ok[r, c].sum())
    return tp, d.size - tp, t.size - tp


def _f1_table_cells(trials, offsets, thresholds, tol):
    out = np.zeros((len(trials), len(offsets), len(thresholds)))
    for i, tr in enumerate(trials):
        for k, th in enumerate(thresholds):
            det = tr.cand_t_s[tr.cand_score >= th]
            for j, off in enumerate(offsets):
                out[i, j, k] = f1_score(*_match_hungarian(det + off, tr.truth_t_s, tol))
    return out


def _trials(n, rng, duration_s=67.0, n_truth=150, n_noise=450):
    trials = []
    for _ in range(n):
        truth = np.sort(rng.uniform(0, duration_s, n_truth))
        hit = truth[rng.random(n_truth) < 0.8]  # 80 % of slips felt, ~60 ms before vision sees them
        cand_t = np.sort(np.r_[hit - 0.06 + rng.normal(0, 0.03, hit.size), rng.uniform(0, duration_s, n_noise)])
        cand_s = rng.gamma(1.5, 2.0, cand_t.size)
        trials.append(CueTrial(cand_t, cand_s, truth, 12.0))
    return trials


def _best_of(fn, repeats):
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def run(n_trials: int = 28, n_baseline_trials: int = 4) -> dict:
    cfg = SlipConfig()
    rng = np.random.default_rng(0)
    trials = _trials(n_trials, rng)
    offsets = np.arange(cfg.offset_min_s, cfg.offset_max_s + 1e-9, cfg.offset_step_s)
    scores = np.concatenate([t.cand_score for t in trials])
    thresholds = np.unique(np.quantile(scores, np.linspace(0, 1, cfg.n_thresholds)))
    fast_s, table = _best_of(lambda: f1_table(trials, offsets, thresholds, cfg.tolerance_s), 3)
    sub = trials[:n_baseline_trials]
    base_s, ref = _best_of(lambda: _f1_table_cells(sub, offsets, thresholds, cfg.tolerance_s), 1)
    identical = bool(np.array_equal(table[:n_baseline_trials], ref))
    cells = len(offsets) * len(thresholds)
    return {
        "slip_f1_table": {
            "trials": n_trials, "cells_per_trial": cells,
            "candidates_per_trial": int(np.mean([t.cand_t_s.size for t in trials])),
            "truth_events_per_trial": int(np.mean([t.truth_t_s.size for t in trials])),
            "sweep_s": fast_s, "sweep_ms_per_trial": 1e3 * fast_s / n_trials,
            "baseline_hungarian_ms_per_trial": 1e3 * base_s / n_baseline_trials,
            "speedup": (base_s / n_baseline_trials) / (fast_s / n_trials),
            "identical_to_baseline": identical,
        },
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
