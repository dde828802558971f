"""`python -m analysis.report sessions=DIR out=DIR [analysis=demo|default|paper]`

Turns a folder of session files into the study's tables and figures, ours beside the study's:
out/results.json, out/predictions.npz, out/report.md, out/config.yaml (the resolved config), out/*.png,
out/models/*.pt (estimator artifacts:
each carries the preprocessing from raw counts with the model; T-s5.pt also the causal slip detector,
ready for OnlineEstimator.from_artifact and `python -m layerskin_exp.estimation.export`).
The estimators come from layerskin_exp.estimation; this module orchestrates them and writes tables.
A missing input (no calibration campaign, no shear trials, no grip sessions, no markers) skips
the sections that need it with the reason in results.json and report.md.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm.auto import tqdm

from analysis import study
from analysis.characterization import (
    PressTrial,
    cop_shift_at_shear,
    effective_heights,
    repeatability,
    uniformity,
)
from analysis.config import AnalysisConfig, ReportConfig
from analysis.markdown import write_markdown
from analysis.metrics import mae, r2_score
from analysis.run_info import convergence_caveats, force_ranges, training_state
from analysis.sessions import Campaign, load_campaign, sessions_problem
from analysis.tracking import TrackingTrial, loto_calibration, unwrap_angle
from layerskin_exp.cli import CONF_DIR as _CONF_DIR
from layerskin_exp.cli import EXIT_CONFIG, preflight, refuse
from layerskin_exp.config import SkinConfig, validate
from layerskin_exp.estimation.artifact import CAUSAL_CUES, Estimator
from layerskin_exp.estimation.cnn import CnnGruForceModel, default_torch_threads
from layerskin_exp.estimation.detector import SlipDetector
from layerskin_exp.estimation.linear import LinearForceModel, linear_features
from layerskin_exp.estimation.preprocess import Preprocessor
from layerskin_exp.estimation.slip import CueTrial, candidates, cue_score, evaluate_loto, vision_slip_events
from layerskin_exp.estimation.splits import split_trials
from layerskin_exp.features import two_layer_features
from layerskin_exp.provenance import provenance

log = logging.getLogger(__name__)

LIVE_SLIP_CUE = "interlayer"  # the cue of the slip detector saved with the T-s5 artifact

AXES = ("Fx", "Fy", "Fz")
CONF_DIR = str(_CONF_DIR)  # conf/ in a checkout, layerskin_exp/conf when installed


def _clean(x):
    """JSON-safe: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


class Analysis:
    """One report run. Stages fill self.results; figures and arrays go to self.out."""

    def __init__(self, cfg: ReportConfig, preset: str | None = None) -> None:
        """preset: the name of the analysis preset the config came from (Hydra's choice), for the record."""
        self.cfg, self.a, self.skin = cfg, cfg.analysis, cfg.skin
        self.preset = preset
        self.out = Path(cfg.out)
        self.results: dict = {"provenance": {}, "data": {}, "force": {}, "heights": {}, "characterization": {}, "tracking": {}, "slip": {},
                               "slip_causal": {},
                               "study": study.ALL, "skipped": {}, "inputs": {}, "timing_s": {}}
        self.figures: list[str] = []
        self.ts5: CnnGruForceModel | None = None
        self.camp: Campaign | None = None
        self.calib_feats: dict | None = None
        self._grip_force: dict[int, np.ndarray] = {}  # grip trial index -> T-s5 force (K, 3) N

    def skip(self, section: str, reason: str) -> None:
        self.results["skipped"][section] = reason
        log.info("skipped %s: %s", section, reason)

    # -- stages ---------------------------------------------------------------------------
    def load(self) -> None:
        camp = load_campaign(self.cfg.sessions, self.a.preprocess, self.a.progress)
        self.camp = camp
        n_press = sum(t.labels.get("kind") == "press" for t in camp.calibration)
        self.results["inputs"] = {"sessions_dir": str(self.cfg.sessions), "files": camp.n_files,
                                  "calibration_trials": len(camp.calibration), "press_trials": n_press,
                                  "slide_trials": len(camp.calibration) - n_press, "grip_trials": len(camp.grip),
                                  "skipped": dict(camp.skipped),
                                  "skipped_files": [{"file": f.name, "reason": f.reason, "detail": f.detail}
                                                    for f in camp.skipped_files]}
        self.results["data"] = {"sessions_used": len(camp.calibration) + len(camp.grip),
                                "sessions_skipped": len(camp.skipped_files),
                                "calibration_trials": len(camp.calibration), "grip_trials": len(camp.grip),
                                "calibration_frames": int(sum(len(t.t_s) for t in camp.calibration)),
                                "grip_frames": int(sum(len(t.t_s) for t in camp.grip))}
        log.info("sessions: %d used, %d skipped (%s)", self.results["data"]["sessions_used"],
                 len(camp.skipped_files), dict(camp.skipped) or "none")
        # Per-layer scale from the calibration campaign (else the grip sessions), applied to all.
        self.pre = Preprocessor.from_config(self.a.preprocess)
        src = [t.maps for t in camp.calibration] or [t.maps for t in camp.grip]
        if not src:
            self.pre.layer_scale_ = self.scale = np.ones(2, np.float32)
            return
        self.scale = self.pre.fit_unscaled(src).layer_scale_
        for t in [*camp.calibration, *camp.grip]:
            self.pre.scale(t.maps)
        self.results["inputs"]["layer_scale_counts"] = self.scale

    def _calibration_arrays(self):
        c = self.camp.calibration
        X = np.concatenate([t.maps for t in c])
        y = np.concatenate([t.force_n for t in c])
        trial = np.concatenate([np.full(len(t.t_s), i) for i, t in enumerate(c)])
        progress = np.concatenate([np.linspace(0, 1, len(t.t_s)) for t in c])
        return X, y, trial, progress

    def force(self) -> None:
        if not self.camp.calibration:
            self.skip("force", "no complete force_calibration sessions")
            return
        X, y, trial, progress = self._calibration_arrays()
        f = two_layer_features(X, self.skin, self.a.preprocess.eps)
        self.calib_feats = f
        sp = self.a.split
        tr, va, te = split_trials(trial, (sp.train, sp.val, sp.test), sp.seed)
        if len(te) == 0 or len(tr) == 0:
            self.skip("force", f"{len(np.unique(trial))} calibration trial(s): too few for a 70/15/15 split")
            return
        m_tr, m_va, m_te = np.isin(trial, tr), np.isin(trial, va), np.isin(trial, te)
        phi = linear_features(f["dc"], f["p_s"], f["p_d"])
        preds = {"linear": LinearForceModel().fit(phi[m_tr], y[m_tr]).predict(phi[m_te])}
        models_dir = self.out / "models"
        models_dir.mkdir(parents=True, exist_ok=True)
        history = {}
        self.results["data"]["split"] = {
            part: {"trials": len(ids), "frames": int(m.sum())}
            for part, ids, m in (("train", tr, m_tr), ("val", va, m_va), ("test", te, m_te))}
        self.results["data"]["force_range_n"] = force_ranges(y, m_te)
        for name in tqdm(self.a.cnn.configurations, desc="CNN-GRU models", leave=False, disable=not self.a.progress):
            model = CnnGruForceModel(name, self.a.cnn, progress=self.a.progress)
            t0 = time.perf_counter()
            log.info("training %s on %d frames", name, int(m_tr.sum()))
            model.fit(X[m_tr], y[m_tr], trial[m_tr], X[m_va], y[m_va], trial[m_va])
            self.results["timing_s"][f"train_{name}"] = time.perf_counter() - t0
            preds[name] = model.predict(X[m_te], trial[m_te])
            Estimator(self.pre, model).save(models_dir / f"{name}.pt")
            history[name] = model.history
            if name == "T-s5":
                self.ts5 = model
        for name, p in preds.items():
            r2, err = r2_score(y[m_te], p), mae(y[m_te], p)
            self.results["force"][name] = {ax: {"r2": r2[i], "mae": err[i]} for i, ax in enumerate(AXES)}
        self.results["force_split"] = {"train_trials": len(tr), "val_trials": len(va), "test_trials": len(te),
                                       "test_frames": int(m_te.sum()), "seed": sp.seed}
        linear_r2 = {ax: v["r2"] for ax, v in self.results["force"]["linear"].items()}
        training = {}
        for k, h in history.items():
            st = training_state(h, self.a.cnn.max_epochs, self.a.cnn.patience)
            st["caveats"] = convergence_caveats(
                st, {ax: v["r2"] for ax, v in self.results["force"][k].items()}, linear_r2)
            st["converged"] = not st["caveats"]
            training[k] = st
            log.info("%s: %d/%d epochs, early stopping %s%s", k, st["epochs"], st["max_epochs"],
                     "triggered" if st["early_stopped"] else "not triggered",
                     "; NOT CONVERGED: " + "; ".join(st["caveats"]) if st["caveats"] else "")
        self.results["force_training"] = training
        np.savez_compressed(self.out / "predictions.npz", reference=y[m_te], trial=trial[m_te],
                            progress=progress[m_te], axes=np.array(AXES),
                            **{f"pred_{k}": v for k, v in preds.items()})
        if self.a.figures:
            from analysis.figures import force_scatter

            force_scatter(self.out / "force_pred_vs_ref.png", y[m_te], preds, progress[m_te], self.results["force"],
                          study.FORCE_RANGE_N)
            self.figures.append("force_pred_vs_ref.png")

    def characterization(self) -> None:
        c = self.camp.calibration
        if not c:
            self.skip("characterization", "no complete force_calibration sessions")
            self.skip("heights", "no complete force_calibration sessions")
            return
        cc = self.a.characterization
        if self.calib_feats is None:
            self.calib_feats = two_layer_features(np.concatenate([t.maps for t in c]), self.skin, self.a.preprocess.eps)
        f = self.calib_feats
        bounds = np.cumsum([0] + [len(t.t_s) for t in c])
        response = f["p_s"] * self.scale[0] + f["p_d"] * self.scale[1]  # counts above baseline, both layers
        presses, shear = [], []
        for i, t in enumerate(c):
            sl = slice(bounds[i], bounds[i + 1])
            if t.labels.get("kind") == "press":
                presses.append(PressTrial(int(t.labels.get("position_index", i)), t.force_n[:, 2], response[sl]))
            elif t.labels.get("kind") == "slide":
                shear.append((i, sl))
        res = {}
        if presses:
            res["uniformity"] = uniformity(presses, cc)
            res["repeatability"] = repeatability(presses, cc)
        else:
            self.skip("characterization.uniformity", "no press trials")
        s_n = [np.linalg.norm(c[i].force_n[:, :2], axis=1) for i, _ in shear]
        dcs = [f["dc"][sl] for _, sl in shear]
        if shear:
            res["cop_shift"] = cop_shift_at_shear(s_n, dcs, cc)
            fz = np.concatenate([c[i].force_n[:, 2] for i, _ in shear])
            fs = np.concatenate([c[i].force_n[:, :2] for i, _ in shear])
            self.results["heights"] = effective_heights(fz, np.concatenate(dcs), fs, cc)
        if self.a.figures and (presses or shear):
            from analysis.figures import characterization_plot

            characterization_plot(self.out / "characterization.png", presses, s_n, dcs, self.results.get("heights"),
                                  cc.matched_load_n, tuple(cc.shear_band_n),
                                  {**study.CHARACTERIZATION, "heights": study.HEIGHTS})
            self.figures.append("characterization.png")
        if not shear:
            self.skip("characterization.cop_shift", "no slide (shear) trials")
            self.skip("heights", "no slide (shear) trials")
        self.results["characterization"] = res

    def grip_force(self, i: int) -> np.ndarray:
        """T-s5 force (K, 3) N of grip trial i, predicted once and shared by the preload and slip cues."""
        if i not in self._grip_force:
            self._grip_force[i] = self.ts5.predict(self.camp.grip[i].maps)
        return self._grip_force[i]

    def _grip_features(self):
        return [two_layer_features(t.maps, self.skin, self.a.preprocess.eps) for t in self.camp.grip]

    def tracking(self) -> None:
        grip = self.camp.grip
        if not grip:
            self.skip("tracking", "no complete grip_depth sessions")
            return
        feats = self.grip_feats = self._grip_features()
        out, self.track_preds = {}, {}
        for motion in ("translation", "torsion"):
            for layer, ref_key in (("deep", "arm_ref"), ("superficial", "vision_ref")):
                key = "d" if layer == "deep" else "s"
                for g in sorted({t.grip_depth_mm for t in grip if t.motion == motion}):
                    idx = [i for i, t in enumerate(grip) if t.motion == motion and t.grip_depth_mm == g
                           and np.all(np.isfinite(getattr(t, ref_key)))]
                    if len(idx) < 2:
                        self.skip(f"tracking.{motion}.{layer}.{g:g}",
                                  f"{len(idx)} trial(s) with a {ref_key.split('_')[0]} reference; LOTO needs 2")
                        continue
                    trials = []
                    for i in idx:
                        fi = feats[i]
                        if motion == "translation":
                            rd = fi[f"cop_{key}"] - fi[f"cop_{key}"][:1]
                        else:
                            a = unwrap_angle(fi[f"angle_{key}"])
                            rd = np.degrees(a - a[0])[:, None]
                        trials.append(TrackingTrial(rd, getattr(grip[i], ref_key), grip[i].t_s))
                    r = loto_calibration(trials)
                    for i, p in zip(idx, r.pop("predictions"), strict=True):
                        self.track_preds[(i, layer)] = p
                    out.setdefault(motion, {}).setdefault(layer, {})[f"{g:g}"] = r
        self.results["tracking"] = out
        if self.ts5 is not None:
            pre = {}
            for i, t in enumerate(grip):
                fz = self.grip_force(i)[:, 2]
                pre.setdefault(f"{t.grip_depth_mm:g}", []).append(float(np.mean(fz)))
            self.results["preload_n"] = {g: float(np.mean(v)) for g, v in sorted(pre.items(), key=lambda kv: float(kv[0]))}
        if self.a.figures:
            self._tracking_figures()

    def _representative(self, motion: str) -> int | None:
        idx = [i for i, t in enumerate(self.camp.grip) if t.motion == motion]
        if not idx:
            return None
        depths = sorted({self.camp.grip[i].grip_depth_mm for i in idx})
        g = 12.0 if 12.0 in depths else depths[len(depths) // 2]
        return next(i for i in idx if self.camp.grip[i].grip_depth_mm == g)

    def _tracking_figures(self) -> None:
        from analysis.figures import tracking_trace

        for motion, unit in (("translation", "displacement (mm)"), ("torsion", "angle (°)")):
            i = self._representative(motion)
            if i is None or (i, "deep") not in self.track_preds and (i, "superficial") not in self.track_preds:
                continue
            t = self.camp.grip[i]
            nan = np.full(t.t_s.size, np.nan)
            tracking_trace(self.out / f"tracking_{motion}.png", t.t_s, t.arm_ref, self.track_preds.get((i, "deep"), nan),
                           t.vision_ref, self.track_preds.get((i, "superficial"), nan), unit,
                           f"{motion}, g = {t.grip_depth_mm:g} mm ({t.name})")
            self.figures.append(f"tracking_{motion}.png")

    def _cue_signal(self, cue: str, i: int, f) -> np.ndarray | None:
        t = self.camp.grip[i]
        if cue == "superficial":
            return f["p_s"]
        if cue == "interlayer":
            return np.abs(f["p_s"] - f["p_d"])
        if cue == "geometric":
            if t.motion == "torsion":
                return unwrap_angle(f["angle_s"])
            d = f["cop_s"] - f["cop_s"][:1]
            u = np.linalg.svd(d, full_matrices=False)[2][0] if np.any(d) else np.array([1.0, 0.0])
            return d @ u
        if self.ts5 is None:
            return None
        force = self.grip_force(i)
        return np.linalg.norm(force, axis=1) if cue == "f_xyz" else force[:, 2]

    def slip(self) -> None:
        grip = self.camp.grip
        if not grip:
            self.skip("slip", "no complete grip_depth sessions")
            return
        sc = self.a.slip
        feats = getattr(self, "grip_feats", None) or self._grip_features()
        out, causal = {}, {}
        self.slip_fig_data = {}
        # One nominal rate for the causal detector (its filters are designed once, as live).
        fs_nominal = float(np.median([1.0 / np.median(np.diff(t.t_s)) for t in grip]))
        live = {"signals": [], "t_s": [], "truths": []}
        for motion in ("translation", "torsion"):
            idx = [i for i, t in enumerate(grip) if t.motion == motion and t.vision_t_s.size > 1]
            if len(idx) < 2:
                self.skip(f"slip.{motion}", f"{len(idx)} {motion} trial(s) with marker poses; LOTO needs 2")
                continue
            truths = {i: vision_slip_events(grip[i].vision_t_s, grip[i].vision_sig, sc) for i in idx}
            det = SlipDetector.from_config(sc, fs_nominal)
            for cue in sc.cues:
                trials, traces, causal_trials = [], [], []
                for i in idx:
                    t = grip[i]
                    sig = self._cue_signal(cue, i, feats[i])
                    if sig is None:
                        break
                    fs = 1.0 / float(np.median(np.diff(t.t_s)))
                    score = cue_score(sig, fs, sc)
                    ct, cs = candidates(t.t_s, score)
                    trials.append(CueTrial(ct, cs, truths[i], t.grip_depth_mm))
                    traces.append((i, score))
                    if cue in CAUSAL_CUES:
                        # The causal detector's score is its envelope through (x - median)/MAD frozen at
                        # fit: a monotone map, so thresholds on the envelope pick the same detections.
                        ct, cs = candidates(t.t_s, det.envelope(sig))
                        causal_trials.append(CueTrial(ct, cs, truths[i], t.grip_depth_mm))
                        if cue == LIVE_SLIP_CUE:
                            live["signals"].append(sig)
                            live["t_s"].append(t.t_s)
                            live["truths"].append(truths[i])
                if not trials:
                    self.skip(f"slip.{motion}.{cue}", "needs the T-s5 force model (add T-s5 to analysis.cnn.configurations)")
                    continue
                r = evaluate_loto(trials, sc)
                out.setdefault(motion, {})[cue] = r
                if causal_trials:
                    causal.setdefault(motion, {})[cue] = evaluate_loto(causal_trials, sc)
                if cue == "interlayer":
                    self.slip_fig_data[motion] = (trials, traces, r["grip_choice"])
        self.results["slip_causal"] = causal
        if live["signals"] and self.ts5 is not None:
            det = SlipDetector.from_config(sc, fs_nominal).fit(live["signals"], live["t_s"], live["truths"])
            Estimator(self.pre, self.ts5, det, LIVE_SLIP_CUE).save(self.out / "models" / "T-s5.pt")
            self.results["slip_live_detector"] = {"cue": LIVE_SLIP_CUE, **det.to_dict()}
        self.results["slip"] = out
        if self.a.figures:
            self._slip_figures()

    def _slip_figures(self) -> None:
        from analysis.figures import slip_detections
        from layerskin_exp.estimation.slip import detect, matched_pairs

        for motion, (trials, traces, choice) in self.slip_fig_data.items():
            rep = self._representative(motion)
            k = next((j for j, (i, _) in enumerate(traces) if i == rep), 0)
            i, score = traces[k]
            tr, (off, thr) = trials[k], choice[k]
            det = detect(tr.cand_t_s, tr.cand_score, thr, off)
            di, ti = matched_pairs(det, tr.truth_t_s, self.a.slip.tolerance_s)
            fn = np.setdiff1d(np.arange(tr.truth_t_s.size), ti)
            t = self.camp.grip[i]
            slip_detections(self.out / f"slip_{motion}.png", t.t_s + off, score, tr.truth_t_s, det, di, fn, thr,
                            f"{motion}, inter-layer difference cue, Grip threshold, g = {t.grip_depth_mm:g} mm")
            self.figures.append(f"slip_{motion}.png")

    def write(self) -> None:
        self.results["figures"] = self.figures
        (self.out / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.structured(self.cfg)))
        (self.out / "results.json").write_text(json.dumps(_clean(self.results), indent=1))
        write_markdown(self.out / "report.md", _clean(self.results), self.figures)
        skipped = self.results["inputs"].get("skipped_files")
        if skipped:
            with open(self.out / "report.md", "a") as fh:
                fh.write("\n## Skipped files\n\n" + "".join(
                    f"- `{f['file']}`: {f['reason']}{': ' + f['detail'] if f['detail'] else ''}\n" for f in skipped))

    def run(self) -> dict:
        self.out.mkdir(parents=True, exist_ok=True)
        with deterministic_torch(self.a.cnn.torch_threads or default_torch_threads(self.a.cnn.device)):
            return self._run()

    def _run(self) -> dict:
        self.results["provenance"] = {**provenance(), "analysis_preset": self.preset, "config_file": "config.yaml"}
        log.info("report %s -> %s (analysis preset %s, layerskin-exp %s, commit %s%s)", self.cfg.sessions, self.out,
                 self.preset, self.results["provenance"]["version"], self.results["provenance"]["git_commit"],
                 ", dirty" if self.results["provenance"]["git_dirty"] else "")
        stages = [("load sessions", self.load), ("force estimation", self.force),
                  ("characterisation", self.characterization), ("tracking", self.tracking),
                  ("slip detection", self.slip), ("write report", self.write)]
        bar = tqdm(stages, desc="report", disable=not self.a.progress)
        for name, fn in bar:
            bar.set_postfix_str(name)
            t0 = time.perf_counter()
            log.info("stage: %s", name)
            fn()
            self.results["timing_s"][name] = time.perf_counter() - t0
            log.info("stage %s done in %.1f s", name, self.results["timing_s"][name])
        return self.results


@contextmanager
def deterministic_torch(threads: int):
    """Torch settings under which a report re-run on the same sessions gives the same numbers.

    Seeds alone are not enough on a GPU: the training step gathers shared frame encodings by
    index, whose backward pass accumulates with atomic adds in whatever order the threads finish,
    and cuDNN may pick non-deterministic convolution algorithms. The T-s5 model then differs in
    its last bits from run to run, and the cues built on its force (f_xyz, f_z, the preload, the
    live detector) move in the third decimal. Deterministic kernels cost little for this model.
    The intra-op thread count is fixed too: CPU reductions split by thread. Restored on exit."""
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # deterministic cuBLAS (read at first use)
    saved = (torch.get_num_threads(), torch.are_deterministic_algorithms_enabled(),
             torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark)
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(True, warn_only=True)  # warn, not fail, on an op without one
    torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = True, False
    try:
        yield
    finally:
        torch.set_num_threads(saved[0])
        torch.use_deterministic_algorithms(saved[1])
        torch.backends.cudnn.deterministic, torch.backends.cudnn.benchmark = saved[2], saved[3]


def run_report(sessions, out, analysis: AnalysisConfig | None = None, skin: SkinConfig | None = None,
               preset: str | None = None) -> dict:
    """Library entry point: the same as the command line. preset: a name for the record (report.md,
    results.json); the config itself is `analysis`."""
    return Analysis(ReportConfig(sessions=str(sessions), out=str(out), analysis=analysis or AnalysisConfig(),
                                 skin=skin or SkinConfig()), preset).run()


def _hydra_preset() -> str | None:
    """The analysis preset chosen for this Hydra run (analysis=demo|default|paper)."""
    from hydra.core.hydra_config import HydraConfig

    return HydraConfig.get().runtime.choices.get("analysis") if HydraConfig.initialized() else None


def _out_problem(out) -> str:
    """Why out= cannot hold the report ('' if it can); creates the folder."""
    try:
        Path(out).mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        return f"out={out}: exists and is not a folder; point out= at a folder for the report"
    except OSError as exc:
        return f"out={out}: cannot create the report folder ({exc.strerror or exc})"
    if not os.access(out, os.W_OK):
        return f"out={out}: not writable"
    return ""


@hydra.main(version_base=None, config_path=CONF_DIR, config_name="report")
def main(cfg: DictConfig) -> None:
    try:
        rc: ReportConfig = validate(cfg)
    except ValueError as e:
        refuse(e)
    problem = sessions_problem(rc.sessions) or _out_problem(rc.out)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        sys.exit(EXIT_CONFIG)
    res = Analysis(rc, _hydra_preset()).run()
    print(f"report written to {Path(rc.out) / 'report.md'} ({len(res['skipped'])} section(s) skipped)")


def _check_command_line(argv: list[str]) -> None:
    """sessions=/out= given on the command line are checked before Hydra starts (Hydra makes
    its run folder under out= first and would fail there with a traceback)."""
    for arg in argv:
        key, _, value = arg.partition("=")
        problem = {"sessions": sessions_problem, "out": _out_problem}.get(key.lstrip("+"), lambda v: "")(value)
        if problem:
            print(f"error: {problem}", file=sys.stderr)
            sys.exit(EXIT_CONFIG)


if __name__ == "__main__":
    _check_command_line(sys.argv[1:])
    preflight("report", sys.argv[1:])
    main()
