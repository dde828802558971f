"""Contact-motion tracking on the grip rig (LOTO scale-and-offset calibration) and the preload."""

from __future__ import annotations

import numpy as np

from analysis import study
from analysis.markdown import counted
from analysis.report_run import ReportRun
from analysis.tracking import TrackingTrial, loto_calibration, unwrap_angle


def tracking(run: ReportRun) -> None:
    grip = run.camp.grip
    if not grip:
        run.skip("tracking", "no complete grip_depth sessions")
        return
    feats = run.grip_features()
    out, run.track_preds = {}, {}
    for motion in ("translation", "torsion"):
        for layer, ref_key in (("deep", "arm_ref"), ("superficial", "vision_ref")):
            key = "d" if layer == "deep" else "s"
            for g in sorted({t.grip_depth_mm for t in grip if t.motion == motion}):
                idx = [i for i, t in enumerate(grip) if t.motion == motion and t.grip_depth_mm == g
                       and np.all(np.isfinite(getattr(t, ref_key)))]
                if len(idx) < 2:
                    run.skip(f"tracking.{motion}.{layer}.{g:g}",
                             f"{counted(len(idx), 'trial')} with the {ref_key.split('_')[0]} reference; LOTO needs 2")
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
                    run.track_preds[(i, layer)] = p
                out.setdefault(motion, {}).setdefault(layer, {})[f"{g:g}"] = r
    run.results["tracking"] = out
    if run.ts5 is not None:
        pre = {}
        for i, t in enumerate(grip):
            fz = run.grip_force(i)[:, 2]
            pre.setdefault(f"{t.grip_depth_mm:g}", []).append(float(np.mean(fz)))
        run.results["preload_n"] = {g: float(np.mean(v)) for g, v in sorted(pre.items(), key=lambda kv: float(kv[0]))}
    if run.a.figures:
        _tracking_figures(run)


def representative(run: ReportRun, motion: str) -> int | None:
    """The grip trial shown for a motion: the first at g = 12 mm (else the middle depth)."""
    idx = [i for i, t in enumerate(run.camp.grip) if t.motion == motion]
    if not idx:
        return None
    depths = sorted({run.camp.grip[i].grip_depth_mm for i in idx})
    g = 12.0 if 12.0 in depths else depths[len(depths) // 2]
    return next(i for i in idx if run.camp.grip[i].grip_depth_mm == g)


def _tracking_figures(run: ReportRun) -> None:
    from analysis.figures import tracking_plot

    for motion, unit in (("translation", "displacement (mm)"), ("torsion", "angle (°)")):
        ours = run.results["tracking"].get(motion)
        if not ours:
            continue
        i = representative(run, motion)
        example = None
        if i is not None and ((i, "deep") in run.track_preds or (i, "superficial") in run.track_preds):
            t = run.camp.grip[i]
            nan = np.full(t.t_s.size, np.nan)
            example = {"t_s": t.t_s, "arm_ref": t.arm_ref, "deep": run.track_preds.get((i, "deep"), nan),
                       "vision_ref": t.vision_ref, "superficial": run.track_preds.get((i, "superficial"), nan),
                       "label": f"g = {t.grip_depth_mm:g} mm, trial {t.labels.get('trial', 0)}"}
        tracking_plot(run.out / f"tracking_{motion}.png", motion, ours, study.TRACKING.get(motion, {}), unit, example)
        run.figures.append(f"tracking_{motion}.png")
