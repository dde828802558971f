"""`python -m analysis.design_map sweep_dir=DIR [out=DIR]`: the spacer design map of a design sweep
(a Hydra app on conf/design_map.yaml, schema `analysis.config.DesignMapConfig`).

Reads every design folder of a force-calibration sweep (`<sweep_dir>/force_calibration/<design>/`,
one per design x bracket, as `python -m protocols.force_calibration -m +design=... +bracket=...`
writes them), measures each design's outcomes from its sessions and writes design_map.json,
design_map.md and design_map.png to `out` (default `<sweep_dir>/design_map`).

Per design and bracket (definitions; every number is measured on the campaign's sessions):
- shift per newton (mm/N): slope of the inter-layer CoP shift along the applied shear,
  d = -Δc·ŝ (Δc = c_s - c_d), against |F_xy| over slide frames with |F_xy| <=
  `sensitivity_max_shear_n`, within each normal-load bin; the headline value is the bin holding
  the slides' preload (where they apply their shear). Its sign says which layer's CoP leads along
  the shear: positive, the deep layer's (the study's moment-balance picture, Δc against the
  shear, see characterization._height_fit); negative, the superficial layer's (its pattern leans
  ahead of the contact faster than the deep pattern follows). Either is a signal a reader
  resolves, so designs rank by its magnitude and the shear range uses |slope|; the sign is a
  result the map reports, not an assumption it makes.
- shear range (N): low = the smallest shear distinguishable from zero-shear noise,
  `noise_sigmas` x the rms inter-layer shift of press frames (no shear, F_z >= 1 N) / the shift
  per newton; high = the smallest of (a) where the shift saturates (the local slope of the
  binned median shift falls below `saturation_ratio` x the small-shear slope), (b) the median of
  the largest shear each slide reached before it stopped (the friction bound where slides slip to
  the edge, the normal-force limit where the guard trips, the protocol's stop otherwise);
  `limited_by` says which.
- normal range before densification (N): the press's normal load when the indenter has travelled
  e_d x h + t_cover past first contact (e_d = 1 - solid fraction, h the spacer height, t_cover the
  cover's thickness, from the session's config): the spacer's cells have closed under the tip.
- the split of every estimator below: grouped by position, `folds` folds (GroupKFold; one
  position per fold when the campaign has no more positions than folds); each R² is of the pooled
  out-of-position predictions (not the report's 70/15/15 trial split, which puts frames of one
  position in train and test: a sweep's campaigns are small, and a design is judged on positions
  it has not seen).
- linear shear R²: the study's linear model (estimation.linear), mean of Fx and Fy.
- T-s5 shear R²: the two-layer five-frame CNN-GRU (estimation.cnn, the report's T-s5) trained per
  fold on the same split with the sweep's preset `cnn` (far smaller than the report's: the
  README gives its cost), early stopping on 15 % of the training trials; `ts5_training` holds
  each fold's epochs and the report's convergence flag (analysis.run_info): a model that stopped
  at the epoch cap still improving, or fell far below the linear baseline, is marked
  unconverged in the map, never dropped.
- superficial shear R²: a ridge probe on the 7 x 7 superficial patch around the superficial CoP
  (normalised by its total, plus the total), same split: the shear information of the
  superficial layer alone.
- position CV: characterization.uniformity at 2 N (the report's definition).
A ranking is stated only where it holds in every bracket; the brackets and the measurement that
would settle each are in layerskin_exp/sim/brackets.yaml.
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from analysis.config import DesignMapConfig
from analysis.markdown import json_safe
from layerskin_exp.cli import hydra_main, refuse, run_command
from layerskin_exp.config import ConfigError, retired_message, validate
from layerskin_exp.estimation.config import CnnConfig
from layerskin_exp.sim.config import load_brackets

# The measurement's stack (scipy.stats, scikit-learn, torch) is imported where a map is measured,
# not for --help or a refused command line (benchmarks/cli_help).

STUDY_DESIGN = "study"
# The headline outcomes a designer ranks by: key in the outcome dict, label, larger is better.
# A signed outcome in MAGNITUDE ranks by its absolute value (the shift's sign names the leading layer).
RANKED = (("shift_per_n_mm", "|shift per newton| at the slides' preload (mm/N)", True), ("shear_high_n", "shear range top (N)", True),
          ("dynamic_range", "shear dynamic range (high/low)", True), ("linear_r2_shear", "linear shear R²", True),
          ("ts5_r2_shear", "T-s5 shear R² (the sweep's training preset)", True),
          ("densification_n", "normal range before densification (N)", True))
MAGNITUDE = frozenset({"shift_per_n_mm"})


# ---------------------------------------------------------------------------- one campaign
@dataclass
class TrialExtras:
    """What the analysis loader does not keep: the stop reason and the press's travel-load curve."""

    stop: str | None
    travel_mm: np.ndarray | None = None  # loading ramp, from first contact
    fz_n: np.ndarray | None = None


def _extras(path: Path, kind: str) -> TrialExtras:
    from layerskin_exp.log import load_session

    s = load_session(path, streams={"stage", "wrench", "events"}, warn=False)
    ev = s.streams.get("events") or {"kind": [], "message": []}
    stops = [m for k, m in zip(ev["kind"], ev["message"], strict=True) if k == "stop"]
    out = TrialExtras(stops[-1] if stops else None)  # a slide whose preload stopped short logs that stop first
    stage, w = s.streams.get("stage"), s.streams.get("wrench")
    if kind != "press" or stage is None or w is None or len(stage["t_ns"]) < 2:
        return out
    z = np.interp(w["t_ns"], stage["t_ns"], stage["position_mm"][:, 2])
    ramp = loading_ramp(z, w["force_n"][:, 2])
    if ramp is not None:
        out.travel_mm, out.fz_n = ramp
    return out


def loading_ramp(z_mm: np.ndarray, fz_n: np.ndarray, touch_n: float = 0.05):
    """(travel from first contact (mm), F_z (N)) of a press's loading ramp up to its peak, or None.
    First contact is where F_z rises through touch_n for the last time before the peak: the
    reading before the trial's tare (taken at the clearance height, in the air) carries the
    sensor's offset and may sit above touch_n."""
    k = int(np.argmax(fz_n))
    if fz_n[k] < touch_n:
        return None
    below = np.flatnonzero(fz_n[: k + 1] < touch_n)
    i0 = int(below[-1]) + 1 if below.size else 0
    return z_mm[i0] - z_mm[i0:k + 1], fz_n[i0:k + 1]


def _patches(maps_s: np.ndarray, cop_mm: np.ndarray, pitch_mm: float, half: int = 3) -> np.ndarray:
    """(K, (2 half + 1)^2 + 1): the superficial patch around the CoP, normalised, and its total."""
    n = maps_s.shape[-1]
    pad = np.pad(maps_s, ((0, 0), (half, half), (half, half)))
    ij = np.clip(np.round(cop_mm / pitch_mm + (n - 1) / 2).astype(int), 0, n - 1)  # (K, 2) x, y -> col, row
    rows = ij[:, 1][:, None] + np.arange(2 * half + 1)[None, :]
    cols = ij[:, 0][:, None] + np.arange(2 * half + 1)[None, :]
    p = pad[np.arange(len(maps_s))[:, None, None], rows[:, :, None], cols[:, None, :]].reshape(len(maps_s), -1)
    tot = p.sum(1, keepdims=True)
    return np.column_stack([p / np.maximum(tot, 1e-9), tot[:, 0]])


def position_folds(groups: np.ndarray, folds: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, test) frame indices, grouped by position: no position is in both parts of a fold.

    GroupKFold with min(folds, positions) folds (one position per fold when there are no more
    positions than folds); [] with fewer than two positions."""
    from sklearn.model_selection import GroupKFold

    n = np.unique(groups).size
    if n < 2:
        return []
    return list(GroupKFold(n_splits=min(max(2, folds), n)).split(np.zeros(len(groups)), groups=groups))


def _grouped(X: np.ndarray, y: np.ndarray, splits: list, model_factory) -> np.ndarray | None:
    """Out-of-position predictions over the folds, or None without folds."""
    if not splits:
        return None
    pred = np.empty_like(y, dtype=float)
    for tr, te in splits:
        pred[te] = model_factory().fit(X[tr], y[tr]).predict(X[te])
    return pred


def _r2_axes(y: np.ndarray, pred: np.ndarray | None) -> dict:
    from analysis.metrics import r2_score

    r2 = r2_score(y, pred) if pred is not None else [None] * 3
    return {ax: (None if v is None or not np.isfinite(v) else float(v)) for ax, v in zip("xyz", r2, strict=True)}


def _shear(r2: dict) -> float | None:
    v = [r2[a] for a in "xy" if r2.get(a) is not None]
    return float(np.mean(v)) if v else None


def ts5_outcomes(X: np.ndarray, y: np.ndarray, trial: np.ndarray, splits: list, cnn: CnnConfig,
                 linear_r2: dict) -> dict:
    """The T-s5 CNN-GRU on the position folds: pooled R², and each fold's training state with the
    report's convergence flag (the caveats of every fold, the R² one on the pooled predictions)."""
    import time

    from analysis.run_info import convergence_caveats, training_state
    from layerskin_exp.estimation.cnn import CnnGruForceModel

    if not splits:
        return {"ts5_r2": _r2_axes(y, None), "ts5_r2_shear": None, "ts5_training": None}
    pred = np.empty_like(y, dtype=float)
    folds, t0 = [], time.process_time()
    for tr, te in splits:
        model = CnnGruForceModel("T-s5", cnn).fit(X[tr], y[tr], trial[tr])
        pred[te] = model.predict(X[te], trial[te])
        folds.append(training_state(model.history, cnn.max_epochs, cnn.patience))
    r2 = _r2_axes(y, pred)
    caveats = []
    for i, st in enumerate(folds):
        caveats += [f"fold {i + 1}: {c}" for c in convergence_caveats(st, {}, None)]
    caveats += convergence_caveats({"early_stopped": True, "epochs": 0, "max_epochs": 1},
                                   {f"F{a}": v for a, v in r2.items()}, {f"F{a}": v for a, v in linear_r2.items()})
    return {"ts5_r2": r2, "ts5_r2_shear": _shear(r2),
            "ts5_training": {"folds": folds, "caveats": caveats, "converged": not caveats,
                             "cpu_s": time.process_time() - t0, "steps_per_epoch": -(-cnn.max_train_windows // cnn.batch_size)
                             if cnn.max_train_windows else None}}


def _ridge():
    from sklearn.linear_model import Ridge
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    return make_pipeline(StandardScaler(), Ridge(alpha=10.0))


def _slope(x: np.ndarray, y: np.ndarray, min_frames: int) -> float | None:
    from scipy.stats import linregress

    if x.size < min_frames or np.ptp(x) == 0:
        return None
    return float(linregress(x, y).slope)


def _saturation(shear: np.ndarray, d_par: np.ndarray, k0: float, cfg: DesignMapConfig) -> float | None:
    """Shear (N) where the binned median shift's local slope falls below saturation_ratio x k0
    (either sign: the shift is taken along its own small-shear slope)."""
    if k0 is None or k0 == 0:
        return None
    d_par, k0 = d_par * np.sign(k0), abs(k0)
    edges = np.arange(0.0, shear.max() + 0.2, 0.2)
    centres, med = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (shear >= lo) & (shear < hi)
        if m.sum() >= max(5, cfg.min_frames // 3):
            centres.append(0.5 * (lo + hi))
            med.append(float(np.median(d_par[m])))
    c, v = np.array(centres), np.array(med)
    for i in range(len(c) - 2):
        if c[i] >= 0.5 and (v[i + 2] - v[i]) / (c[i + 2] - c[i]) < cfg.saturation_ratio * k0:
            return float(c[i])
    return None


def campaign_outcomes(root: Path, cfg: DesignMapConfig, pitch_mm: float = 1.5) -> dict:
    """Every outcome of one design's campaign folder (see the module docstring)."""
    from analysis.characterization import PressTrial, cop_shift_at_shear, uniformity
    from analysis.metrics import r2_score
    from analysis.sessions import load_campaign
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.estimation.linear import LinearForceModel, linear_features
    from layerskin_exp.features import two_layer_features
    from layerskin_exp.log import load_session
    from layerskin_exp.sim.config import SpacerConfig

    camp = load_campaign(root, cfg.preprocess, cfg.progress)
    cal = camp.calibration
    if not cal:
        return {"error": f"no complete force_calibration sessions under {root}"}
    first = load_session(Path(root) / cal[0].name, streams=set(), warn=False).metadata
    config = first.get("config", {})
    spacer_keys = config.get("sim", {}).get("spacer", {})
    old = next((f"sim.spacer.{k}" for k in spacer_keys if retired_message(f"sim.spacer.{k}")), None)
    if old:  # a campaign recorded under a retired key: its design is not the one the key now names
        raise ConfigError(f"{root}: recorded with {retired_message(old)}; rerun the sweep to map it")
    spacer = SpacerConfig(**spacer_keys)
    skin = SkinConfig(**{k: v for k, v in config.get("skin", {}).items() if k in SkinConfig.__dataclass_fields__})
    pitch_mm = getattr(skin, "pitch_mm", pitch_mm)
    X = np.concatenate([t.maps for t in cal])
    f = two_layer_features(X, skin, cfg.preprocess.eps)
    bounds = np.cumsum([0] + [len(t.t_s) for t in cal])
    extras = {t.name: _extras(Path(root) / t.name, t.labels.get("kind")) for t in cal}
    out: dict = {"design_id": Path(root).name, "config": config,
                 "overrides": (first.get("provenance") or {}).get("overrides") or [],
                 "n_positions": len({t.labels.get("position_index") for t in cal}),
                 "n_press": sum(t.labels.get("kind") == "press" for t in cal),
                 "n_slide": sum(t.labels.get("kind") == "slide" for t in cal)}
    presses, slides = [], []
    for i, t in enumerate(cal):
        sl = slice(bounds[i], bounds[i + 1])
        (presses if t.labels.get("kind") == "press" else slides).append((i, sl))
    # -- shear sensitivity per normal-load bin
    fz = np.concatenate([cal[i].force_n[:, 2] for i, _ in slides]) if slides else np.zeros(0)
    fs = np.concatenate([cal[i].force_n[:, :2] for i, _ in slides]) if slides else np.zeros((0, 2))
    dc = np.concatenate([f["dc"][sl] for _, sl in slides]) if slides else np.zeros((0, 2))
    shear = np.linalg.norm(fs, axis=1)
    unit = fs / np.maximum(shear, 1e-9)[:, None]
    d_par = -np.sum(dc * unit, axis=1)
    small = (shear <= cfg.sensitivity_max_shear_n) & (fz >= cfg.fz_bins_n[0])
    by_bin = {}
    e = cfg.fz_bins_n
    for lo, hi in zip(e[:-1], e[1:], strict=True):
        m = small & (fz >= lo) & (fz < hi)
        by_bin[f"{lo:g}-{hi:g}"] = {"slope_mm_per_n": _slope(shear[m], d_par[m], cfg.min_frames), "frames": int(m.sum())}
    # The headline: the bin holding the slide's preload, where the slides apply their shear. Pooled
    # over loads, low-load frames dominate a stiff stack's fit (there the moment balance alone moves
    # the deep CoP by F_xy h / F_z), so a pooled slope mixes loads a designer would compare apart.
    preload = float(config.get("slide", {}).get("preload_n", 3.0))
    lo_op, hi_op = next(((lo, hi) for lo, hi in zip(e[:-1], e[1:], strict=True) if lo <= preload < hi), (e[0], e[-1]))
    op = (fz >= lo_op) & (fz < hi_op)
    k_all = _slope(shear[small & op], d_par[small & op], cfg.min_frames)
    out["shift_per_n_by_fz"] = by_bin
    out["shift_per_n_mm"] = k_all
    out["shift_per_n_fz_n"] = [lo_op, hi_op]
    out["shift_per_n_pooled_mm"] = _slope(shear[small], d_par[small], cfg.min_frames)
    out["cop_shift_at_2n"] = cop_shift_at_shear([np.linalg.norm(cal[i].force_n[:, :2], axis=1) for i, _ in slides],
                                                [f["dc"][sl] for _, sl in slides], cfg.characterization)
    # -- shear range
    press_dc = np.concatenate([f["dc"][sl][cal[i].force_n[:, 2] >= 1.0] for i, sl in presses]) if presses else np.zeros((0, 2))
    sigma = float(np.sqrt(np.mean(np.sum((press_dc - press_dc.mean(0)) ** 2, axis=1) / 2))) if len(press_dc) else None
    low = cfg.noise_sigmas * sigma / abs(k_all) if (sigma is not None and k_all) else None
    sat = _saturation(shear[op], d_par[op], k_all, cfg) if slides else None
    reached, reasons = [], Counter()
    for i, _ in slides:
        reached.append(float(np.linalg.norm(cal[i].force_n[:, :2], axis=1).max()))
        reasons[extras[cal[i].name].stop or "unknown"] += 1
    applied = float(np.median(reached)) if reached else None
    why = {"shear_reached": "protocol stop", "skin_edge": "slip (friction)", "force_limit": "normal-force limit",
           "depth_limit": "preload not reached (platform travel)"}
    limit = why.get(reasons.most_common(1)[0][0], "unknown") if reasons else None
    high, limited_by = applied, limit
    if sat is not None and (applied is None or sat < applied):
        high, limited_by = sat, "saturation"
    n_sl = max(1, sum(reasons.values()))
    out["slides"] = {"stop_fractions": {k: v / n_sl for k, v in reasons.items()}, "median_max_shear_n": applied,
                     "fz_at_shear_n": float(np.median(fz[shear >= 1.5])) if (shear >= 1.5).sum() else None,
                     "mu_p95": float(np.percentile(shear[fz > 0.5] / fz[fz > 0.5], 95)) if (fz > 0.5).any() else None}
    out.update({"zero_shear_shift_rms_mm": sigma, "saturation_n": sat, "shear_low_n": low, "shear_high_n": high,
                "shear_limited_by": limited_by,
                "dynamic_range": (high / low) if (high is not None and low) else None})
    # -- normal range before densification
    # The tip's travel is the spacer's compression plus the cover's (at most its thickness): past
    # e_d h + t_cover the cells under the tip have closed whatever the cover took (the load is an
    # upper bound on the onset; for a solid spacer, e_d ~ 0.05, the cover dominates it).
    cover_mm = float(config.get("sim", {}).get("cover", {}).get("thickness_mm", 0.2))
    onset_mm = spacer.densification_strain * spacer.thickness_mm + cover_mm
    dens, unreached = [], []
    for i, _ in presses:
        ex = extras[cal[i].name]
        if ex.travel_mm is None:
            continue
        if ex.travel_mm.max() >= onset_mm:
            j = int(np.argmax(ex.travel_mm >= onset_mm))
            dens.append(float(ex.fz_n[j]))
        else:
            unreached.append(float(ex.fz_n.max()))
    out["densification_onset_mm"] = onset_mm
    out["densification_n"] = float(np.median(dens)) if len(dens) > len(unreached) else None
    out["densification_above_n"] = float(np.median(unreached)) if len(unreached) >= len(dens) and unreached else None
    # -- estimators, on folds grouped by position
    y = np.concatenate([t.force_n for t in cal])
    groups = np.concatenate([np.full(len(t.t_s), t.labels.get("position_index", i)) for i, t in enumerate(cal)])
    trial = np.concatenate([np.full(len(t.t_s), i) for i, t in enumerate(cal)])
    splits = position_folds(groups, cfg.folds)
    out["folds"] = len(splits)
    totals = np.column_stack([f["p_s"], f["p_d"]])
    scale = 1.0 / np.maximum(np.percentile(totals, cfg.preprocess.scale_percentile, axis=0), 1e-9)
    phi = linear_features(f["dc"], f["p_s"] * scale[0], f["p_d"] * scale[1])
    out["linear_r2"] = _r2_axes(y, _grouped(phi, y, splits, LinearForceModel))
    out["linear_r2_shear"] = _shear(out["linear_r2"])
    if cfg.ts5:
        out.update(ts5_outcomes(X, y, trial, splits, cfg.cnn, out["linear_r2"]))
    patch = _patches(X[:, 0], f["cop_s"], pitch_mm)
    pred_s = _grouped(patch, y[:, :2], splits, _ridge)
    r2s = r2_score(y[:, :2], pred_s) if pred_s is not None else [None, None]
    vals = [float(v) for v in r2s if v is not None and np.isfinite(v)]
    out["superficial_r2_shear"] = float(np.mean(vals)) if vals else None
    # -- uniformity
    response = f["p_s"] + f["p_d"]  # counts above baseline, both layers
    ptrials = [PressTrial(int(cal[i].labels.get("position_index", i)), cal[i].force_n[:, 2], response[sl])
               for i, sl in presses]
    out["uniformity"] = uniformity(ptrials, cfg.characterization) if ptrials else {"cv": None}
    out["position_cv"] = out["uniformity"].get("cv")
    return out


# ---------------------------------------------------------------------------- the map
def _names(outcome: dict) -> tuple[str, str]:
    """(design, bracket) from the sweep's overrides, else from the spacer values."""
    design = bracket = None
    for o in outcome.get("overrides", []):
        key, _, value = o.partition("=")
        key = key.lstrip("+~")
        if key == "design":
            design = value
        elif key == "bracket":
            bracket = value
    sp = outcome.get("config", {}).get("sim", {}).get("spacer", {})
    if design is None:
        design = f"E{sp.get('modulus_kpa')}_h{sp.get('thickness_mm')}_c{sp.get('cell_mm')}_w{sp.get('wall_mm')}"
    return design, bracket or "nominal"


def _band(values: list) -> list | None:
    v = [x for x in values if x is not None]
    return [min(v), max(v)] if v else None


def build_map(outcomes: list[dict]) -> dict:
    """Group per-campaign outcomes by design and bracket; bands across brackets; robust rankings."""
    designs: dict[str, dict] = {}
    brackets: list[str] = []
    for o in outcomes:
        d, b = _names(o)
        if b not in brackets:
            brackets.append(b)
        sp = o.get("config", {}).get("sim", {}).get("spacer", {})
        entry = designs.setdefault(d, {"spacer": sp, "brackets": {}})
        entry["brackets"][b] = {k: v for k, v in o.items() if k != "config"}
    for entry in designs.values():
        per = entry["brackets"]
        entry["bands"] = {key: _band([per[b].get(key) for b in per]) for key, _, _ in RANKED}
        entry["bands"]["position_cv"] = _band([per[b].get("position_cv") for b in per])
        entry["bands"]["superficial_r2_shear"] = _band([per[b].get("superficial_r2_shear") for b in per])
    rankings = {}
    for key, label, larger in RANKED:
        per_bracket = {}
        for b in brackets:
            vals = {d: e["brackets"].get(b, {}).get(key) for d, e in designs.items()}
            vals = {d: (abs(v) if key in MAGNITUDE else v) for d, v in vals.items() if v is not None}
            per_bracket[b] = sorted(vals, key=lambda d, vals=vals: vals[d], reverse=larger)
        names = sorted(designs)
        holds = []  # (a, b): a beats b in every bracket that measured both
        for a in names:
            for c in names:
                if a == c:
                    continue
                seen = [b for b in brackets if a in per_bracket[b] and c in per_bracket[b]]
                if len(seen) == len(brackets) and all(per_bracket[b].index(a) < per_bracket[b].index(c) for b in seen):
                    holds.append([a, c])
        firsts = {b: (per_bracket[b][0] if per_bracket[b] else None) for b in brackets}
        robust_best = next(iter(set(firsts.values()))) if len(set(firsts.values())) == 1 else None
        rankings[key] = {"label": label, "order_by_bracket": per_bracket, "best_by_bracket": firsts,
                         "best_in_every_bracket": robust_best, "pairs_that_hold": holds}
    return {"brackets": brackets, "designs": designs, "rankings": rankings}


def _fmt(v, spec=".2f") -> str:
    return "–" if v is None else format(v, spec)


def _cell(entry: dict, key: str, spec=".2f") -> str:
    per = entry["brackets"]
    nominal = per.get("nominal", next(iter(per.values()))).get(key)
    band = entry["bands"].get(key) or _band([p.get(key) for p in per.values()])
    if band is None:
        return "–"
    return f"{_fmt(nominal, spec)} [{_fmt(band[0], spec)}–{_fmt(band[1], spec)}]"


def _unconverged(outcome: dict) -> bool:
    tr = outcome.get("ts5_training")
    return bool(tr) and not tr.get("converged", False)


def _ts5_cell(entry: dict) -> str:
    """The T-s5 cell: † on the nominal value when its model did not converge, and how many
    brackets' models did not."""
    per = entry["brackets"]
    if not any(p.get("ts5_training") for p in per.values()):
        return "–"
    nom = per.get("nominal", next(iter(per.values())))
    cell = _cell(entry, "ts5_r2_shear")
    if _unconverged(nom):
        cell = cell.replace(" [", "† [", 1)
    n_bad = sum(_unconverged(p) for p in per.values())
    return cell + (f" ({n_bad}/{len(per)} unconverged)" if n_bad else "")


def write_markdown(path: Path, result: dict, brackets: dict, figures: list[str]) -> None:
    m = result["map"]
    lines = ["# Spacer design map", "",
             f"Sweep: `{result['sweep_dir']}`; {len(m['designs'])} designs x brackets {', '.join(m['brackets'])}. "
             "Each cell: the nominal bracket's value [min–max over the brackets]. Definitions: "
             "analysis/design_map.py.", "",
             "| design | E (kPa) | h / cell / wall (mm) | shift/N at the preload (mm/N; + deep CoP leads, − superficial leads) | shear range low–high (N), limited by | "
             "normal range before densification (N) | linear shear R² | T-s5 shear R² | superficial shear R² | position CV |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, e in sorted(m["designs"].items(), key=lambda kv: kv[0] != STUDY_DESIGN):
        sp = e["spacer"]
        nom = e["brackets"].get("nominal", next(iter(e["brackets"].values())))
        dens = nom.get("densification_n")
        dens_s = _cell(e, "densification_n") if dens is not None else f"> {_fmt(nom.get('densification_above_n'), '.1f')}"
        rng = (f"{_fmt(nom.get('shear_low_n'))}–{_fmt(nom.get('shear_high_n'))} ({nom.get('shear_limited_by')}); "
               f"top {_cell(e, 'shear_high_n')}")
        mark = " ★" if name == STUDY_DESIGN else ""
        lines.append(f"| {name}{mark} | {sp.get('modulus_kpa', 0):g} | {sp.get('thickness_mm', 0):g} / {sp.get('cell_mm', 0):g} / "
                     f"{sp.get('wall_mm', 0):g} | {_cell(e, 'shift_per_n_mm')} | {rng} | {dens_s} | "
                     f"{_cell(e, 'linear_r2_shear')} | {_ts5_cell(e)} | {_cell(e, 'superficial_r2_shear')} | "
                     f"{_cell(e, 'position_cv', '.3f')} |")
    cnn = result.get("cnn") or {}
    folds = sorted({o.get("folds") for e in m["designs"].values() for o in e["brackets"].values()} - {None})
    lines += ["", "★ the study's design. Shear R²: mean of Fx and Fy, pooled out-of-position predictions on "
              f"{'/'.join(map(str, folds)) or '–'} folds grouped by position (the same folds for every estimator). "
              "T-s5: the two-layer five-frame CNN-GRU trained per design, bracket and fold with the sweep's preset "
              f"(batch {cnn.get('batch_size')}, lr {cnn.get('lr')} {cnn.get('lr_schedule')}, "
              f"{cnn.get('max_train_windows')} windows an epoch, at most {cnn.get('max_epochs')} epochs, patience "
              f"{cnn.get('patience')}); † its nominal model is unconverged (the report's flag: it stopped at the "
              "epoch cap still improving, or fell far below the linear baseline); the count says in how many "
              "brackets. An unconverged R² is a lower bound of what the design allows, not its value.", ""]
    ts5_rows = [(name, b, o) for name, e in sorted(m["designs"].items()) for b, o in e["brackets"].items()
                if o.get("ts5_training")]
    if ts5_rows:
        lines += ["## T-s5 training per design and bracket", "",
                  "| design | bracket | T-s5 R² Fx / Fy / Fz | linear R² Fx / Fy / Fz | epochs per fold (best) | "
                  "converged | CPU s |", "|---|---|---|---|---|---|---|"]
        for name, b, o in ts5_rows:
            tr = o["ts5_training"]
            r2 = " / ".join(_fmt((o.get("ts5_r2") or {}).get(a)) for a in "xyz")
            lin = " / ".join(_fmt((o.get("linear_r2") or {}).get(a)) for a in "xyz")
            ep = ", ".join(f"{f['epochs']} ({f['best_epoch']})" for f in tr["folds"])
            capped = sum(1 for f in tr["folds"] if not f["early_stopped"] and f["epochs"] >= f["max_epochs"])
            why = ([f"epoch cap in {capped}/{len(tr['folds'])} folds"] if capped else []) + \
                  ["far below linear" for c in tr["caveats"] if "below the linear" in c]
            conv = "yes" if tr["converged"] else "no: " + "; ".join(why or tr["caveats"])
            lines.append(f"| {name} | {b} | {r2} | {lin} | {ep} | {conv} | {_fmt(tr.get('cpu_s'), '.0f')} |")
        lines.append("")
    lines += ["## Shift per newton by normal load (nominal bracket, mm/N)", ""]
    bins = None
    for name, e in sorted(m["designs"].items()):
        nom = e["brackets"].get("nominal", next(iter(e["brackets"].values())))
        by = nom.get("shift_per_n_by_fz", {})
        if bins is None:
            bins = list(by)
            lines += ["| design | " + " | ".join(f"F_z {b} N" for b in bins) + " |", "|---" * (len(bins) + 1) + "|"]
        lines.append(f"| {name} | " + " | ".join(
            f"{_fmt(by.get(b, {}).get('slope_mm_per_n'))} ({by.get(b, {}).get('frames', 0)} fr)" for b in bins) + " |")
    lines += ["", "## Rankings that hold across the brackets", ""]
    for r in m["rankings"].values():
        best = r["best_in_every_bracket"]
        by = ", ".join(f"{b}: {d}" for b, d in r["best_by_bracket"].items())
        if best:
            lines.append(f"- **{r['label']}**: {best} is best in every bracket ({by}).")
        else:
            lines.append(f"- **{r['label']}**: no design is best in every bracket ({by}); the winner depends on "
                         "the unknowns below.")
        if r["pairs_that_hold"]:
            lines.append(f"  Orderings that hold in every bracket: {len(r['pairs_that_hold'])} of "
                         f"{len(m['designs']) * (len(m['designs']) - 1) // 2} pairs, e.g. "
                         + "; ".join(f"{a} > {b}" for a, b in r["pairs_that_hold"][:6]) + ".")
    lines += ["", "## What the map depends on, and the measurement that settles it", ""]
    for key, p in brackets.items():
        src = " ".join(str(p.get("source", "")).split())
        lo_hi = p.get("levels") or [p.get("low"), p.get("high")]
        lines.append(f"- `{key}` = {p.get('nominal')} (bracket {lo_hi}): {src}")
    for fig in figures:
        lines += ["", f"![{fig}]({fig})"]
    path.write_text("\n".join(lines) + "\n")


def plot_map(path: Path, result: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = result["map"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    for ax, (xkey, xlabel) in zip(axes, (("shear_high_n", "shear range top (N)"),
                                         ("densification_n", "normal load before the spacer densifies (N)")),
                                  strict=True):
        for name, e in sorted(m["designs"].items()):
            per = e["brackets"]
            nom = per.get("nominal", next(iter(per.values())))
            x, y = nom.get(xkey), nom.get("shift_per_n_mm")
            if xkey == "densification_n" and x is None:
                x = nom.get("densification_above_n")
            if x is None or y is None:
                continue
            xb = _band([p.get(xkey) if p.get(xkey) is not None else p.get("densification_above_n") for p in per.values()])
            yb = _band([p.get("shift_per_n_mm") for p in per.values()])
            study = name == STUDY_DESIGN
            ax.errorbar([x], [y], xerr=[[x - xb[0]], [xb[1] - x]] if xb else None,
                        yerr=[[y - yb[0]], [yb[1] - y]] if yb else None, fmt="*" if study else "o",
                        ms=14 if study else 6, capsize=3, color="C3" if study else None, label=name)
            ax.annotate(name, (x, y), textcoords="offset points", xytext=(5, 5), fontsize=8)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("inter-layer shift per newton of shear\nat the slides' preload (mm/N)")
        ax.grid(alpha=0.3)
    axes[0].set_title("sensitivity vs shear range (bars: min–max over brackets)")
    axes[1].set_title("sensitivity vs normal range")
    axes[1].legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)




def design_folders(sweep_dir: Path) -> list[Path]:
    """Every folder holding force-calibration sessions under sweep_dir (one per design x bracket)."""
    return sorted({p.parent for p in Path(sweep_dir).rglob("*.mcap") if "force_calibration" in p.parts})


def _measure(folder: Path, cfg: DesignMapConfig) -> dict:
    """One campaign's outcomes, in this process or a worker (torch on the preset's thread count)."""
    import time

    import torch

    from layerskin_exp.estimation.cnn import default_torch_threads

    torch.set_num_threads(cfg.cnn.torch_threads or default_torch_threads(cfg.cnn.device))
    print(f"design_map: {folder}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    o = campaign_outcomes(folder, cfg)
    o["measure_wall_s"] = time.perf_counter() - t0
    return o


def run(cfg: DesignMapConfig) -> dict:
    sweep = Path(cfg.sweep_dir)
    out = Path(cfg.out) if cfg.out else sweep / "design_map"
    out.mkdir(parents=True, exist_ok=True)
    folders = design_folders(sweep)
    if not folders:
        raise FileNotFoundError(f"sweep_dir={sweep}: no force_calibration sessions found under it; run the "
                                "design sweep first (README, 'Spacer design map')")
    if cfg.n_jobs > 1:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        # spawn: fresh interpreters (no forked torch/numba threads); the stdlib pool, since joblib's
        # loky workers failed to start their own children here ("cannot find context for 'loky'")
        with ProcessPoolExecutor(cfg.n_jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            measured = list(pool.map(_measure, folders, [cfg] * len(folders)))
    else:
        measured = [_measure(folder, cfg) for folder in folders]
    outcomes = [o for o in measured if "error" not in o]
    brackets = load_brackets()
    from dataclasses import asdict

    result = {"sweep_dir": str(sweep), "map": build_map(outcomes), "brackets_file": "layerskin_exp/sim/brackets.yaml",
              "folds": cfg.folds, "cnn": asdict(cfg.cnn) if cfg.ts5 else None}
    figures = []
    if cfg.figures:
        plot_map(out / "design_map.png", result)
        figures.append("design_map.png")
    (out / "design_map.json").write_text(json.dumps(json_safe(result), indent=1))
    write_markdown(out / "design_map.md", json_safe(result), brackets, figures)
    return result


@hydra_main("design_map")
def main(cfg: DictConfig) -> None:
    try:
        typed: DesignMapConfig = validate(cfg)
    except ConfigError as e:
        refuse(e)
    code = command(typed)
    if code:
        sys.exit(code)


def command(cfg: DesignMapConfig) -> int:
    """The command on its validated config: the map, or exit code 2 with one line when the sweep
    folder is missing, holds no campaign, or a campaign cannot be read."""
    if not Path(cfg.sweep_dir).is_dir():
        print(f"configuration error: sweep_dir={cfg.sweep_dir}: no such folder", file=sys.stderr)
        return 2
    try:
        res = run(cfg)
    except (FileNotFoundError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    out = Path(cfg.out) if cfg.out else Path(cfg.sweep_dir) / "design_map"
    print(f"design map of {len(res['map']['designs'])} designs written to {out / 'design_map.md'}")
    return 0


def cli() -> None:
    """`python -m analysis.design_map`: --help, a bad key or value refused in one line (exit 2), then the map."""
    run_command("design_map", lambda: main)


if __name__ == "__main__":
    cli()
