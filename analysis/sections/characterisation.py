"""Characterisation of the calibration campaign: uniformity, repeatability, CoP shift, heights,
the slides' loads, and (given `sensitivity=FILE`) the simulator's bands over its brackets beside
the study and this campaign."""

from __future__ import annotations

import numpy as np

from analysis import study
from analysis.characterization import (
    PressTrial,
    cop_shift_at_shear,
    effective_heights,
    repeatability,
    slide_loads,
    uniformity,
)
from analysis.report_run import ReportRun
from layerskin_exp.features import two_layer_features


def characterization(run: ReportRun) -> None:
    c = run.camp.calibration
    if not c:
        run.skip("characterization", "no complete force_calibration sessions")
        run.skip("heights", "no complete force_calibration sessions")
        run.results["characterization"] = sensitivity_bands(run, {})
        return
    cc = run.a.characterization
    if run.calib_feats is None:
        run.calib_feats = two_layer_features(np.concatenate([t.maps for t in c]), run.skin, run.a.preprocess.eps)
    f = run.calib_feats
    bounds = np.cumsum([0] + [len(t.t_s) for t in c])
    response = f["p_s"] * run.scale[0] + f["p_d"] * run.scale[1]  # counts above baseline, both layers
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
        run.skip("characterization.uniformity", "no press trials")
    s_n = [np.linalg.norm(c[i].force_n[:, :2], axis=1) for i, _ in shear]
    dcs = [f["dc"][sl] for _, sl in shear]
    if shear:
        res["cop_shift"] = cop_shift_at_shear(s_n, dcs, cc)
        fz = np.concatenate([c[i].force_n[:, 2] for i, _ in shear])
        fs = np.concatenate([c[i].force_n[:, :2] for i, _ in shear])
        run.results["heights"] = effective_heights(fz, np.concatenate(dcs), fs, cc)
        res["slide_loads"] = slide_loads(s_n, [c[i].force_n[:, 2] for i, _ in shear])
    if run.a.figures and (presses or shear):
        from analysis.figures import characterization_plot

        characterization_plot(run.out / "characterization.png", presses, s_n, dcs, run.results.get("heights"),
                              cc.matched_load_n, tuple(cc.shear_band_n),
                              {**study.CHARACTERIZATION, "heights": study.HEIGHTS}, res)
        run.figures.append("characterization.png")
    if not shear:
        run.skip("characterization.cop_shift", "no slide (shear) trials")
        run.skip("heights", "no slide (shear) trials")
    run.results["characterization"] = {**res, **sensitivity_bands(run, res)}


def sensitivity_bands(run: ReportRun, res: dict) -> dict:
    """{"sensitivity_bands": ...}: the screen's band per outcome beside the study's value and this
    campaign's (what this section measured, and the force section's linear model); {} when no
    screening result was given."""
    if run.cfg.sensitivity is None:
        return {}
    from analysis.sensitivity_result import bands, load_result

    def val(v, source):
        return {"value": v, "source": source} if v is not None else None

    lin = [(run.results.get("force") or {}).get("linear", {}).get(ax, {}).get("r2") for ax in ("Fx", "Fy")]
    ours = {"cop_shift_at_2n_mm": val((res.get("cop_shift") or {}).get("median_mm"), "this section"),
            "position_cv": val((res.get("uniformity") or {}).get("cv"), "this section"),
            "slide_fz_at_shear_n": val((res.get("slide_loads") or {}).get("fz_at_shear_n"), "this section"),
            "slide_max_shear_n": val((res.get("slide_loads") or {}).get("median_max_shear_n"), "this section"),
            "linear_r2_shear": val(float(np.mean(lin)) if None not in lin else None,
                                   "force section, trial split")}
    out = bands(load_result(run.cfg.sensitivity), study.SENSITIVITY_OUTCOMES, {k: v for k, v in ours.items() if v})
    return {"sensitivity_bands": {"file": str(run.cfg.sensitivity), **out}}
