"""Sensor characterisation from the calibration campaign (press and slide trials).

- Uniformity: per press, the summed positive response of both layers interpolated at a matched
  normal load on the loading ramp; per position, the mean over its presses; CV across positions
  with a bootstrap CI (scipy.stats.bootstrap, resampling positions).
- Repeatability: per position whose presses all exceed `min_shared_load_n`, the CV across its
  presses at each load of the shared interval [min_shared_load_n, smallest press peak], averaged
  over that interval; the median over positions.
- Inter-layer CoP shift at a shear band: per slide trial, the median |Δc| over frames whose
  |(Fx, Fy)| lies in the band; median and 10th–90th percentiles over trials.
- Effective heights: the moment balance F_shear·h ≈ F_z·Δc fitted as F_shear = k·(F_z·Δc) + b,
  h = 1/k (mm), with the fit's R², over all slide frames in contact and within normal-load bins.
- Slide loads: the median normal load over slide frames with |(Fx, Fy)| >= 1.5 N (the normal load
  while the shear is applied), and the median over slides of the largest shear each reached
  (the definitions of the design map and the sensitivity screen).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import bootstrap, linregress

from analysis.config import CharacterizationConfig
from analysis.markdown import counted


@dataclass
class PressTrial:
    """fz_n (N,) reference normal load; response (N,) summed positive response of both layers."""

    position: int
    fz_n: np.ndarray
    response: np.ndarray


def loading_curve(fz_n: np.ndarray, response: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The loading ramp (start to peak load) as a monotone load axis with its responses."""
    k = int(np.argmax(fz_n)) + 1
    load = np.maximum.accumulate(fz_n[:k])
    keep = np.r_[True, np.diff(load) > 0]
    return load[keep], response[:k][keep]


def response_at(trial: PressTrial, load_n) -> np.ndarray:
    """Response interpolated at the given load(s) on the loading ramp; NaN beyond its range."""
    load, resp = loading_curve(trial.fz_n, trial.response)
    return np.interp(load_n, load, resp, left=np.nan, right=np.nan)


def _cv(x, axis=-1):
    return np.std(x, axis=axis, ddof=1) / np.mean(x, axis=axis)


def uniformity(presses: list[PressTrial], cfg: CharacterizationConfig) -> dict:
    """CV across positions of the response at the matched load, with a bootstrap CI."""
    by_pos: dict[int, list[float]] = {}
    for p in presses:
        v = float(response_at(p, cfg.matched_load_n))
        if np.isfinite(v):
            by_pos.setdefault(p.position, []).append(v)
    means = np.array([np.mean(v) for v in by_pos.values()])
    out = {"matched_load_n": cfg.matched_load_n, "n_positions": int(means.size)}
    if means.size < 3:
        return {**out, "cv": None, "reason": f"{counted(means.size, 'position')} reached {cfg.matched_load_n} N; need >= 3"}
    ci = bootstrap((means,), _cv, n_resamples=cfg.n_bootstrap, confidence_level=cfg.confidence,
                   method="percentile", random_state=np.random.default_rng(cfg.seed)).confidence_interval
    return {**out, "cv": float(_cv(means)), "ci_low": float(ci.low), "ci_high": float(ci.high)}


def repeatability(presses: list[PressTrial], cfg: CharacterizationConfig, n_grid: int = 50) -> dict:
    """Median over positions of the within-position CV across presses on their shared load interval."""
    by_pos: dict[int, list[PressTrial]] = {}
    for p in presses:
        by_pos.setdefault(p.position, []).append(p)
    cvs = []
    for trials in by_pos.values():
        if len(trials) < 2:
            continue
        top = min(float(np.max(t.fz_n)) for t in trials)
        if top <= cfg.min_shared_load_n:
            continue
        grid = np.linspace(cfg.min_shared_load_n, top, n_grid)
        resp = np.stack([response_at(t, grid) for t in trials])  # (presses, grid)
        ok = np.all(np.isfinite(resp), axis=0) & np.all(resp > 0, axis=0)
        if ok.any():
            cvs.append(float(np.mean(_cv(resp[:, ok], axis=0))))
    if not cvs:
        return {"median_cv": None, "n_positions": 0,
                "reason": f"no position has all presses above {cfg.min_shared_load_n} N"}
    return {"median_cv": float(np.median(cvs)), "n_positions": len(cvs)}


def cop_shift_at_shear(shear_n: list[np.ndarray], dc_mm: list[np.ndarray], cfg: CharacterizationConfig) -> dict:
    """Trial-wise median |Δc| over frames with |F_shear| in the band; summary over trials (mm)."""
    lo, hi = cfg.shear_band_n
    per_trial = []
    for s, d in zip(shear_n, dc_mm, strict=True):
        m = (s >= lo) & (s <= hi)
        if m.any():
            per_trial.append(float(np.median(np.linalg.norm(d[m], axis=1))))
    if not per_trial:
        return {"median_mm": None, "n_trials": 0, "reason": f"no slide reached {lo}-{hi} N shear"}
    v = np.array(per_trial)
    return {"median_mm": float(np.median(v)), "p10_mm": float(np.percentile(v, 10)),
            "p90_mm": float(np.percentile(v, 90)), "n_trials": int(v.size)}


def slide_loads(shear_n: list[np.ndarray], fz_n: list[np.ndarray], shear_at_n: float = 1.5) -> dict:
    """Normal load while the shear is applied and the shear the slides reached, per slide trial
    arrays of |F_xy| and F_z (N)."""
    if not shear_n:
        return {"fz_at_shear_n": None, "median_max_shear_n": None, "n_trials": 0, "reason": "no slide trials"}
    s, fz = np.concatenate(shear_n), np.concatenate(fz_n)
    at = s >= shear_at_n
    reached = [float(np.max(x)) for x in shear_n if x.size]
    return {"shear_at_n": shear_at_n, "fz_at_shear_n": float(np.median(fz[at])) if at.any() else None,
            "n_frames_at_shear": int(at.sum()),
            "median_max_shear_n": float(np.median(reached)) if reached else None,
            "n_trials": len(shear_n)}


def _height_fit(fz, dc, f_shear) -> dict:
    """F_shear = k·(F_z·Δc) + b per axis; h = -1/k in mm.

    Sign: shear drags the load path, so the deep-layer CoP moves along the applied shear while
    the superficial CoP (in its own taxel frame) stays with the contact; Δc = c_s - c_d therefore
    points against the shear on the skin, and the moment balance reads F_t·h = -F_z·Δc. With that
    sign a physical (positive) height comes out positive; a negative h flags a sign problem in
    the force reference or the layer frames.
    """
    out = {"n_frames": int(fz.size)}
    for i, ax in enumerate("xy"):
        u = fz * dc[:, i]
        if fz.size < 3 or np.ptp(u) == 0:
            out[f"h_{ax}_mm"], out[f"r2_{ax}"] = None, None
            continue
        fit = linregress(u, f_shear[:, i])
        out[f"h_{ax}_mm"] = float(-1.0 / fit.slope) if fit.slope != 0 else None
        out[f"r2_{ax}"] = float(fit.rvalue ** 2)
    return out


def effective_heights(fz_n: np.ndarray, dc_mm: np.ndarray, f_shear_n: np.ndarray,
                      cfg: CharacterizationConfig) -> dict:
    """Overall and per normal-load bin. fz_n (N,), dc_mm (N, 2), f_shear_n (N, 2) (Fx, Fy)."""
    m = fz_n >= cfg.min_fz_n
    res = {"overall": _height_fit(fz_n[m], dc_mm[m], f_shear_n[m]), "bins": []}
    e = cfg.fz_bins_n
    for lo, hi in zip(e[:-1], e[1:], strict=True):
        b = (fz_n >= lo) & (fz_n < hi)
        res["bins"].append({"fz_low_n": lo, "fz_high_n": hi, **_height_fit(fz_n[b], dc_mm[b], f_shear_n[b])})
    return res
