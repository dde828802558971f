"""Report figures (matplotlib, Agg): predicted vs reference force, characterisation, tracking traces, slip detections."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

AXES = ("Fx", "Fy", "Fz")


def _study_interval(study_range: dict | None, ax_name: str, reference: np.ndarray) -> tuple[float, float] | None:
    """The study's force range on one axis, (low, high) N; Fz on the sign side of our data."""
    if not study_range:
        return None
    if ax_name in study_range:
        return study_range[ax_name]["min_n"], study_range[ax_name]["max_n"]
    top = study_range.get("abs_Fz_max_n")
    if top is None:
        return None
    return (-top, 0.0) if np.median(reference) < 0 else (0.0, top)


def force_scatter(path, reference: np.ndarray, predictions: dict[str, np.ndarray], progress: np.ndarray,
                  scores: dict | None = None, study_range: dict | None = None, study_scores: dict | None = None,
                  unconverged: dict[str, str] | None = None) -> None:
    """force_figure saved to path."""
    _save(force_figure(reference, predictions, progress, scores, study_range, study_scores, unconverged), path)


def force_figure(reference: np.ndarray, predictions: dict[str, np.ndarray], progress: np.ndarray,
                 scores: dict | None = None, study_range: dict | None = None, study_scores: dict | None = None,
                 unconverged: dict[str, str] | None = None) -> plt.Figure:
    """Predicted vs reference force (N) on the test frames: one row per model, one column per axis.

    reference (N, 3), predictions name -> (N, 3), progress (N,) through each trial (0..1, colour).
    Each panel states its R² and MAE (scores: name -> axis -> {"r2", "mae"}, the report's table;
    computed here when not given) and the study's for the same model and axis (study_scores, same
    shape); shaded: the study's force range (a narrower range of ours is easier data).
    unconverged: model -> why; its row is titled "NOT CONVERGED" in red and its panels hatched, so
    a flat line is not read as the model's ability. Axes are shared per column and set by the
    reference, so one wild model does not squash the others (its points beyond are drawn at the edge)."""
    from analysis.metrics import mae, r2_score

    n = len(predictions)
    fig, axs = plt.subplots(n, 3, figsize=(11, 3.1 * n), squeeze=False, layout="constrained")
    sc = None
    for c, ax_name in enumerate(AXES):
        ref = reference[:, c]
        iv = _study_interval(study_range, ax_name, ref)
        lo, hi = float(ref.min()), float(ref.max())
        if iv is not None:
            lo, hi = min(lo, iv[0]), max(hi, iv[1])
        pad = 0.08 * (hi - lo or 1.0)
        lo, hi = lo - pad, hi + pad
        for r, (name, pred) in enumerate(predictions.items()):
            ax = axs[r, c]
            if iv is not None:
                ax.axvspan(*iv, color="0.92", zorder=0, label="study's range")
            sc = ax.scatter(ref, np.clip(pred[:, c], lo, hi), c=progress, s=2, cmap="viridis", vmin=0, vmax=1,
                            rasterized=True)
            ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
            ax.set_xlim(lo, hi)
            ax.set_ylim(lo, hi)
            m = (scores or {}).get(name, {}).get(ax_name) or {"r2": r2_score(ref, pred[:, c]), "mae": mae(ref, pred[:, c])}
            r2 = "–" if m["r2"] is None or not np.isfinite(m["r2"]) else f"{m['r2']:.3f}"
            text = f"ours:  R² {r2}, MAE {m['mae']:.3f} N"
            st = (study_scores or {}).get(name, {}).get(ax_name)
            if st:
                text += f"\nstudy: R² {st['r2']:.3f}, MAE {st['mae']:.3f} N"
            ax.text(0.03, 0.97, text, transform=ax.transAxes, va="top", fontsize=7.5, family="monospace",
                    bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
            bad = name in (unconverged or {})
            ax.set_title(f"{name}: {ax_name}" + ("  NOT CONVERGED" if bad else ""), fontsize=10,
                         color="C3" if bad else "k")
            if bad:
                ax.set_facecolor("#fff0f0")
                ax.text(0.97, 0.03, "not converged:\nnot comparable\nwith the study", transform=ax.transAxes,
                        ha="right", va="bottom", fontsize=7, color="C3")
            ax.set_xlabel("reference (N)")
            ax.set_ylabel("predicted (N)")
    if study_range:
        axs[0, 0].legend(loc="lower right", fontsize=7)
    if sc is not None:
        fig.colorbar(sc, ax=axs, shrink=min(1.0, 0.9 / n + 0.1), label="progress through trial")
    return fig


def _save(fig: plt.Figure, path) -> None:
    fig.savefig(path, dpi=110)
    plt.close(fig)


def tracking_figure(motion: str, ours: dict, study: dict, unit: str, example: dict | None = None) -> plt.Figure:
    """Contact-motion tracking over all trials, ours beside the study's, per grip depth.

    ours / study: layer ("deep", "superficial") -> grip depth (str, mm) -> {"a", "r2", "mae"} (ours
    also "n_trials"): the LOTO calibration's mean slope, pooled out-of-fold R² and MAE (unit).
    Filled markers and solid lines are ours, open markers and dashed lines the study's.
    example: optional {"t_s", "arm_ref", "deep", "vision_ref", "superficial", "label"}: one trial's
    traces, drawn in a fourth panel to show what the numbers summarise."""
    n = 4 if example else 3
    fig, axs = plt.subplots(1, n, figsize=(4.0 * n, 3.6), layout="constrained")
    colour = {"deep": "C0", "superficial": "C3"}
    for ax, key, label in ((axs[0], "a", "slope a"), (axs[1], "r2", "R² (pooled, out of fold)"),
                           (axs[2], "mae", f"MAE ({unit.split('(')[-1].rstrip(')')})")):
        for layer, col in colour.items():
            g_o = sorted(ours.get(layer, {}), key=float)
            if g_o:
                ax.plot([float(g) for g in g_o], [ours[layer][g][key] for g in g_o], "o-", color=col,
                        label=f"ours, {layer}")
            g_s = sorted(study.get(layer, {}), key=float)
            if g_s:
                ax.plot([float(g) for g in g_s], [study[layer][g][key] for g in g_s], "s--", color=col,
                        mfc="none", label=f"study, {layer}")
        ax.set(xlabel="grip depth (mm)", title=label)
        ax.set_xticks([6, 9, 12, 15])
    n_trials = sorted({v.get("n_trials") for layer in ours.values() for v in layer.values() if v.get("n_trials")})
    fig.suptitle(f"{motion} tracking, all trials (LOTO calibration"
                 + (f", {'/'.join(map(str, n_trials))} trials per grip depth" if n_trials else "") + ")", fontsize=11)
    handles, labels = axs[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=4, fontsize=8, frameon=False)
    if example:
        ax = axs[3]
        t = example["t_s"] - example["t_s"][0]
        ax.plot(t, example["arm_ref"], "k-", lw=1, label="arm reference")
        ax.plot(t, example["deep"], "C0-", lw=1, label="deep (calibrated)")
        ax.plot(t, example["vision_ref"], "k:", lw=1, label="vision reference")
        ax.plot(t, example["superficial"], "C3-", lw=1, label="superficial (calibrated)")
        ax.set(xlabel="time (s)", ylabel=unit, title=f"example: {example['label']}")
        ax.legend(fontsize=6.5, loc="best")
    return fig


def tracking_plot(path, *args, **kwargs) -> None:
    """tracking_figure saved to path."""
    _save(tracking_figure(*args, **kwargs), path)


def slip_detections(path, t_s, score, truth_s, detected_s, tp_det, fn_truth, threshold, title: str) -> None:
    """slip_figure saved to path."""
    _save(slip_figure(t_s, score, truth_s, detected_s, tp_det, fn_truth, threshold, title), path)


def slip_figure(t_s, score, truth_s, detected_s, tp_det, fn_truth, threshold, title: str) -> plt.Figure:
    """t_s, score (K,): the cue score (MAD units) on the session timeline (s); truth_s, detected_s:
    event times (s); tp_det: indices of matched detections; fn_truth: indices of missed truths.

    Events above, score below. The score axis is set by the threshold and the bulk of the score
    (99th percentile), not its largest spike, so the threshold stays legible; spikes beyond are
    clipped at the top. It is linear up to 1 MAD and logarithmic above (symlog), so a threshold
    fitted near zero is not lost under the peaks. Events sit on their own strip: truth as thin
    ticks, TP / FP / FN markers, with their counts and the trial's F1."""
    fig, (ev, ax) = plt.subplots(2, 1, figsize=(9, 3.8), sharex=True, height_ratios=[1, 3.2],
                                 layout="constrained")
    t0 = t_s[0]
    finite = score[np.isfinite(score)]
    bulk = float(np.percentile(finite, 99)) if finite.size else 1.0
    top = max(1.6 * threshold, 1.15 * bulk, 1.0)
    bottom = min(0.0, float(finite.min()) if finite.size else 0.0)
    ax.plot(t_s - t0, np.minimum(score, top), "C7-", lw=0.8, label="cue score")
    ax.axhline(threshold, color="C1", lw=1.2, ls="-.", label=f"threshold {threshold:.2g}")
    ax.set_yscale("symlog", linthresh=1.0, linscale=0.6)
    ax.set_ylim(bottom - 0.05 * (top - bottom), top)
    if finite.size and finite.max() > top:
        ax.text(0.995, 0.98, f"clipped at {top:.3g} (max {finite.max():.3g})", transform=ax.transAxes,
                ha="right", va="top", fontsize=7, color="0.4")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("cue score (MAD units)")
    tp = detected_s[tp_det]
    fp = np.delete(detected_s, tp_det)
    ev.vlines(truth_s - t0, 2.6, 3.4, color="k", lw=0.6, label=f"vision truth ({truth_s.size})")
    ev.plot(truth_s[fn_truth] - t0, np.full(len(fn_truth), 3.0), "bx", ms=5, label=f"FN, missed ({len(fn_truth)})")
    ev.plot(tp - t0, np.full(tp.size, 1.0), "g^", ms=5, label=f"TP ({tp.size})")
    ev.plot(fp - t0, np.full(fp.size, 1.0), "v", color="orange", ms=5, label=f"FP ({fp.size})")
    ev.set_ylim(0.2, 3.8)
    ev.set_yticks([1.0, 3.0], ["detected", "truth"], fontsize=8)
    denom = 2 * tp.size + fp.size + len(fn_truth)
    ev.set_title(title + (f"; this trial's F1 {2 * tp.size / denom:.2f}" if denom else ""), fontsize=10)
    handles = ev.get_legend_handles_labels()[0] + ax.get_legend_handles_labels()[0]
    fig.legend(handles=handles, loc="outside right center", fontsize=7, frameon=False)
    return fig


def characterization_figure(presses, shear_n: list[np.ndarray], dc_mm: list[np.ndarray], heights: dict | None,
                            matched_load_n: float, shear_band_n: tuple[float, float], study: dict,
                            ours: dict | None = None) -> plt.Figure:
    """The calibration campaign's characterisation in three panels, ours beside the study's.

    (a) each press's loading ramp, summed response (both layers) against F_z, one colour per
    position, with the matched load of the uniformity CV marked; (b) the inter-layer CoP shift
    |Δc| against |F_shear| over the slides (a random 20 000 frames), the trial-wise medians in
    the shear band and the study's median and 10-90 % range; (c) the effective heights h_x, h_y
    fitted per normal-load bin (marker size: fit R²), the study's lowest and highest bins.
    ours: the report's characterisation results ("uniformity": cv, ci_low, ci_high, n_positions),
    whose CV is printed beside the study's. Legends sit below the panels, clear of the points."""
    from analysis.characterization import loading_curve

    fig, axs = plt.subplots(1, 3, figsize=(15.0, 5.0), constrained_layout=True)
    ax = axs[0]
    positions = sorted({p.position for p in presses})
    cmap = plt.get_cmap("viridis", max(len(positions), 2))
    colour = {pos: cmap(i) for i, pos in enumerate(positions)}
    for p in presses:
        load, resp = loading_curve(p.fz_n, p.response)
        ax.plot(load, resp, lw=0.5, alpha=0.5, color=colour[p.position])
    ax.axvline(matched_load_n, color="k", ls="--", lw=0.8)
    uni = study.get("uniformity", {})
    mine = (ours or {}).get("uniformity") or {}
    ours_cv = (f"ours: CV {mine['cv']:.3f} ({mine['ci_low']:.3f}-{mine['ci_high']:.3f}), "
               f"{mine.get('n_positions', len(positions))} positions\n" if mine.get("cv") is not None else "")
    study_cv = (f"study: CV {uni['cv']:.3f} ({uni['ci_low']:.3f}-{uni['ci_high']:.3f}), "
                f"{uni.get('n_positions')} positions" if "cv" in uni else "")
    ax.set(xlabel="F_z (N)", ylabel="summed response (counts above baseline)",
           title=f"(a) loading ramps; CV across positions at {matched_load_n:g} N (95 % CI)\n{ours_cv}{study_cv}")

    ax = axs[1]
    if shear_n:
        s = np.concatenate(shear_n)
        d = np.linalg.norm(np.concatenate(dc_mm), axis=1)
        pick = np.random.default_rng(0).permutation(s.size)[:20000]
        ax.scatter(s[pick], d[pick], s=2, alpha=0.15, color="C0", rasterized=True, label="slide frames")
        lo, hi = shear_band_n
        med = [float(np.median(np.linalg.norm(dd[(ss >= lo) & (ss <= hi)], axis=1)))
               for ss, dd in zip(shear_n, dc_mm, strict=True) if ((ss >= lo) & (ss <= hi)).any()]
        if med:
            ax.errorbar([0.5 * (lo + hi) - 0.05], [np.median(med)],
                        yerr=[[np.median(med) - np.percentile(med, 10)], [np.percentile(med, 90) - np.median(med)]],
                        fmt="o", color="C1", capsize=4, label="ours: trial medians in band (10-90 %)")
        cs = study.get("cop_shift", {})
        if cs:
            ax.errorbar([0.5 * (lo + hi) + 0.05], [cs["median_mm"]],
                        yerr=[[cs["median_mm"] - cs["p10_mm"]], [cs["p90_mm"] - cs["median_mm"]]],
                        fmt="s", color="k", capsize=4, label="study")
        ax.axvspan(lo, hi, color="0.9", zorder=0)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=8, ncol=2, frameon=False)
    ax.set(xlabel="|F_shear| (N)", ylabel="|Δc| (mm)", title="(b) inter-layer CoP shift against shear")

    ax = axs[2]
    bins = (heights or {}).get("bins", [])
    for i, (axis, col) in enumerate((("x", "C0"), ("y", "C3"))):
        mid = [0.5 * (b["fz_low_n"] + b["fz_high_n"]) + (i - 0.5) * 0.08 for b in bins if b.get(f"h_{axis}_mm") is not None]
        h = [b[f"h_{axis}_mm"] for b in bins if b.get(f"h_{axis}_mm") is not None]
        r2 = [max(b[f"r2_{axis}"], 0.0) for b in bins if b.get(f"h_{axis}_mm") is not None]
        ax.scatter(mid, h, s=[20 + 180 * v for v in r2], color=col, label=f"ours h_{axis}")
        ax.plot(mid, h, color=col, lw=0.8)
        for key, mk in (("lowest_bin", "s"), ("highest_bin", "s")):
            sb = study.get("heights", {}).get(key)
            if sb:
                ax.scatter([np.mean(sb["fz_n"]) + (i - 0.5) * 0.08], [sb[f"h_{axis}_mm"]], marker=mk,
                           facecolors="none", edgecolors=col, s=80,
                           label=f"study h_{axis}" if key == "lowest_bin" else None)
    ax.axhline(0.0, color="0.6", lw=0.6)
    if bins:
        finite = [b[f"h_{a}_mm"] for b in bins for a in "xy" if b.get(f"h_{a}_mm") is not None]
        if finite:
            top = max(8.0, min(max(finite) * 1.1, 20.0))
            ax.set_ylim(min(-1.0, max(min(finite) * 1.1, -10.0)), top)
    ax.set(xlabel="F_z bin centre (N)", ylabel="h (mm)",
           title="(c) effective height per normal-load bin\n(marker area ~ fit R²; clipped to -10..20 mm)")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=8, ncol=2, frameon=False)
    return fig


def characterization_plot(path, *args, **kwargs) -> None:
    """characterization_figure saved to path."""
    _save(characterization_figure(*args, **kwargs), path)
