"""Slip-event detection on the grip rig: the five offline cues (LOTO), their causal versions, and
the live detector saved with the T-s5 artifact."""

from __future__ import annotations

import numpy as np

from analysis import study
from analysis.markdown import counted
from analysis.report_run import ReportRun
from analysis.sections.tracking import representative
from analysis.tracking import unwrap_angle
from layerskin_exp.estimation.artifact import CAUSAL_CUES, Estimator
from layerskin_exp.estimation.detector import SlipDetector
from layerskin_exp.estimation.slip import CueTrial, candidates, cue_score, evaluate_loto, vision_slip_events

LIVE_SLIP_CUE = "interlayer"  # the cue of the slip detector saved with the T-s5 artifact


def cue_signal(run: ReportRun, cue: str, i: int, f) -> np.ndarray | None:
    """Grip trial i's raw cue signal (K,) from its features f; None when it needs a missing T-s5."""
    t = run.camp.grip[i]
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
    if run.ts5 is None:
        return None
    force = run.grip_force(i)
    return np.linalg.norm(force, axis=1) if cue == "f_xyz" else force[:, 2]


def slip(run: ReportRun) -> None:
    grip = run.camp.grip
    if not grip:
        run.skip("slip", "no complete grip_depth sessions")
        return
    sc = run.a.slip
    feats = run.grip_features()
    out, causal = {}, {}
    run.slip_fig_data = {}
    # One nominal rate for the causal detector (its filters are designed once, as live).
    fs_nominal = float(np.median([1.0 / np.median(np.diff(t.t_s)) for t in grip]))
    live = {"signals": [], "t_s": [], "truths": []}
    for motion in ("translation", "torsion"):
        idx = [i for i, t in enumerate(grip) if t.motion == motion and t.vision_t_s.size > 1]
        if len(idx) < 2:
            run.skip(f"slip.{motion}", f"{counted(len(idx), motion + ' trial')} with marker poses; LOTO needs 2")
            continue
        truths = {i: vision_slip_events(grip[i].vision_t_s, grip[i].vision_sig, sc) for i in idx}
        det = SlipDetector.from_config(sc, fs_nominal)
        for cue in sc.cues:
            trials, traces, causal_trials = [], [], []
            for i in idx:
                t = grip[i]
                sig = cue_signal(run, cue, i, feats[i])
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
                run.skip(f"slip.{motion}.{cue}", "needs the T-s5 force model (add T-s5 to analysis.cnn.configurations)")
                continue
            r = evaluate_loto(trials, sc)
            out.setdefault(motion, {})[cue] = r
            if causal_trials:
                causal.setdefault(motion, {})[cue] = evaluate_loto(causal_trials, sc)
            if cue == "interlayer":
                run.slip_fig_data[motion] = (trials, traces, r["grip_choice"])
    run.results["slip_causal"] = causal
    if live["signals"] and run.ts5 is not None:
        det = SlipDetector.from_config(sc, fs_nominal).fit(live["signals"], live["t_s"], live["truths"])
        Estimator(run.pre, run.ts5, det, LIVE_SLIP_CUE).save(run.out / "models" / "T-s5.pt")
        run.results["slip_live_detector"] = {"cue": LIVE_SLIP_CUE, **det.to_dict()}
    run.results["slip"] = out
    if run.a.figures:
        _slip_figures(run)


def _slip_figures(run: ReportRun) -> None:
    from analysis.figures import slip_detections
    from layerskin_exp.estimation.slip import detect, matched_pairs

    for motion, (trials, traces, choice) in run.slip_fig_data.items():
        rep = representative(run, motion)
        k = next((j for j, (i, _) in enumerate(traces) if i == rep), 0)
        i, score = traces[k]
        tr, (off, thr) = trials[k], choice[k]
        det = detect(tr.cand_t_s, tr.cand_score, thr, off)
        di, ti = matched_pairs(det, tr.truth_t_s, run.a.slip.tolerance_s)
        fn = np.setdiff1d(np.arange(tr.truth_t_s.size), ti)
        t = run.camp.grip[i]
        ours = run.results["slip"][motion]["interlayer"]["grip"]
        theirs = study.SLIP.get(motion, {}).get("interlayer", {}).get("grip")
        slip_detections(run.out / f"slip_{motion}.png", t.t_s + off, score, tr.truth_t_s, det, di, fn, thr,
                        f"{motion}, inter-layer difference cue, Grip threshold, g = {t.grip_depth_mm:g} mm\n"
                        f"trial-macro F1 (LOTO, Grip) ours {ours:.3f}"
                        + (f", study {theirs:.3f}" if theirs is not None else ""))
        run.figures.append(f"slip_{motion}.png")
