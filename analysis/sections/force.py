"""Force estimation: the linear baseline and the CNN-GRU configurations on a trial split."""

from __future__ import annotations

import logging
import time

import numpy as np
from scipy.stats import bootstrap
from tqdm.auto import tqdm

from analysis import study
from analysis.markdown import counted
from analysis.metrics import mae, r2_score
from analysis.report_run import ReportRun
from analysis.run_info import convergence_caveats, force_ranges, training_state
from layerskin_exp.estimation.artifact import Estimator
from layerskin_exp.estimation.cnn import CnnGruForceModel, parse_configuration
from layerskin_exp.estimation.linear import LinearForceModel, layer_features, linear_features
from layerskin_exp.estimation.splits import split_trials
from layerskin_exp.features import two_layer_features

log = logging.getLogger("analysis.report")

AXES = ("Fx", "Fy", "Fz")
GAIN_RESAMPLES = 999
GAIN_CONFIDENCE = 0.95
# Fewer test trials than this and the gain's interval is undefined, not printed: n trials give
# only C(2n-1, n) distinct resamples (35 for 4, 92378 for 10), and the R² of a resample of two or
# three trials, whose reference barely varies, can take any value.
GAIN_MIN_TEST_TRIALS = 10


def r2_gain_ci(y: np.ndarray, pred: np.ndarray, base: np.ndarray, trial: np.ndarray,
               seed: int = 0) -> dict[str, list[float]]:
    """How far a model's test R² is above a baseline's, with a bootstrap CI over test trials.

    y, pred, base (N, 3) N on the test frames; trial (N,) ids. Trials, not frames, are resampled
    (frames of a trial are not independent), and both models see the same resample. Returns axis ->
    [gain, ci_low, ci_high], the interval NaN (undefined) below GAIN_MIN_TEST_TRIALS test trials. On
    a few dozen test trials the interval is wide: a gain whose interval holds 0 is not resolved by
    this test set.
    """
    ids, inv = np.unique(np.asarray(trial), return_inverse=True)
    frames = [np.flatnonzero(inv == i) for i in range(len(ids))]

    def gain(picked, axis=-1):
        rows = np.concatenate([frames[int(i)] for i in picked])
        return r2_score(y[rows], pred[rows]) - r2_score(y[rows], base[rows])

    if len(ids) < GAIN_MIN_TEST_TRIALS:
        g = gain(np.arange(len(ids)))
        return {ax: [float(g[i]), float("nan"), float("nan")] for i, ax in enumerate(AXES)}
    ci = bootstrap((np.arange(len(ids)),), gain, vectorized=False, n_resamples=GAIN_RESAMPLES,
                   confidence_level=GAIN_CONFIDENCE, method="percentile",
                   random_state=np.random.default_rng(seed)).confidence_interval
    g = gain(np.arange(len(ids)))
    return {ax: [float(g[i]), float(ci.low[i]), float(ci.high[i])] for i, ax in enumerate(AXES)}


def calibration_arrays(run: ReportRun):
    """The calibration trials as one array: X (N, 2, 16, 16), y (N, 3) N, trial (N,), progress (N,)."""
    c = run.camp.calibration
    X = np.concatenate([t.maps for t in c])
    y = np.concatenate([t.force_n for t in c])
    trial = np.concatenate([np.full(len(t.t_s), i) for i, t in enumerate(c)])
    progress = np.concatenate([np.linspace(0, 1, len(t.t_s)) for t in c])
    return X, y, trial, progress


def _same_inputs_baseline(name: str, f: dict, y: np.ndarray, m_tr: np.ndarray, m_te: np.ndarray,
                          linear_r2: dict) -> tuple[str, dict]:
    """The linear model a CNN's convergence is judged against (run_info.convergence_caveats): the
    study's two-layer baseline for a two-layer CNN, the linear model of its own layer's moments
    (estimation.linear.layer_features) for a single-layer one; (its name, axis -> test R²)."""
    layers, _ = parse_configuration(name)
    if layers == "T":
        return "the linear baseline", linear_r2
    key = {"S": "s", "D": "d"}[layers]
    phi = layer_features(f[f"cop_{key}"], f[f"p_{key}"])
    r2 = r2_score(y[m_te], LinearForceModel().fit(phi[m_tr], y[m_tr]).predict(phi[m_te]))
    layer = {"S": "superficial", "D": "deep"}[layers]
    return f"the linear model of the {layer} layer's moments", {ax: r2[i] for i, ax in enumerate(AXES)}


def force(run: ReportRun) -> None:
    if not run.camp.calibration:
        run.skip("force", "no complete force_calibration sessions")
        return
    a, results = run.a, run.results
    X, y, trial, progress = calibration_arrays(run)
    f = two_layer_features(X, run.skin, a.preprocess.eps)
    run.calib_feats = f
    sp = a.split
    tr, va, te = split_trials(trial, (sp.train, sp.val, sp.test), sp.seed)
    if len(te) == 0 or len(tr) == 0:
        run.skip("force", f"{counted(len(np.unique(trial)), 'calibration trial')}: too few for a 70/15/15 split")
        return
    m_tr, m_va, m_te = np.isin(trial, tr), np.isin(trial, va), np.isin(trial, te)
    phi = linear_features(f["dc"], f["p_s"], f["p_d"])
    preds = {"linear": LinearForceModel().fit(phi[m_tr], y[m_tr]).predict(phi[m_te])}
    models_dir = run.out / "models"
    models_dir.mkdir(parents=True, exist_ok=True)
    history = {}
    results["data"]["split"] = {
        part: {"trials": len(ids), "frames": int(m.sum())}
        for part, ids, m in (("train", tr, m_tr), ("val", va, m_va), ("test", te, m_te))}
    results["data"]["force_range_n"] = force_ranges(y, m_te)
    for name in tqdm(a.cnn.configurations, desc="CNN-GRU models", leave=False, disable=not a.progress):
        model = CnnGruForceModel(name, a.cnn, progress=a.progress)
        t0 = time.perf_counter()
        log.info("training %s on %d frames", name, int(m_tr.sum()))
        model.fit(X[m_tr], y[m_tr], trial[m_tr], X[m_va], y[m_va], trial[m_va])
        results["timing_s"][f"train_{name}"] = time.perf_counter() - t0
        preds[name] = model.predict(X[m_te], trial[m_te])
        Estimator(run.pre, model).save(models_dir / f"{name}.pt")
        history[name] = model.history
        if name == "T-s5":
            run.ts5 = model
    for name, p in preds.items():
        r2, err = r2_score(y[m_te], p), mae(y[m_te], p)
        results["force"][name] = {ax: {"r2": r2[i], "mae": err[i]} for i, ax in enumerate(AXES)}
    results["force_gain_over_linear"] = {
        "confidence": GAIN_CONFIDENCE, "resampled": "test trials", "min_test_trials": GAIN_MIN_TEST_TRIALS,
        **{k: r2_gain_ci(y[m_te], p, preds["linear"], trial[m_te], sp.seed) for k, p in preds.items() if k != "linear"}}
    results["force_split"] = {"train_trials": len(tr), "val_trials": len(va), "test_trials": len(te),
                              "test_frames": int(m_te.sum()), "seed": sp.seed}
    linear_r2 = {ax: v["r2"] for ax, v in results["force"]["linear"].items()}
    training = {}
    for k, h in history.items():
        st = training_state(h, a.cnn.max_epochs, a.cnn.patience)
        r2_k = {ax: v["r2"] for ax, v in results["force"][k].items()}
        baseline, own_r2 = _same_inputs_baseline(k, f, y, m_tr, m_te, linear_r2)
        st["baseline"], st["baseline_r2"] = baseline, own_r2
        st["caveats"] = convergence_caveats(st, r2_k, own_r2, baseline)
        st["converged"] = not st["caveats"]
        training[k] = st
        log.info("%s: %d/%d epochs, early stopping %s%s", k, st["epochs"], st["max_epochs"],
                 "triggered" if st["early_stopped"] else "not triggered",
                 "; NOT CONVERGED: " + "; ".join(st["caveats"]) if st["caveats"] else "")
    results["force_training"] = training
    np.savez_compressed(run.out / "predictions.npz", reference=y[m_te], trial=trial[m_te],
                        progress=progress[m_te], axes=np.array(AXES),
                        **{f"pred_{k}": v for k, v in preds.items()})
    if a.figures:
        from analysis.figures import force_scatter

        force_scatter(run.out / "force_pred_vs_ref.png", y[m_te], preds, progress[m_te], results["force"],
                      study.FORCE_RANGE_N, study.FORCE,
                      {k: "; ".join(st["caveats"]) for k, st in training.items() if not st["converged"]})
        run.figures.append("force_pred_vs_ref.png")
