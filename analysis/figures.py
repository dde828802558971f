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
                  scores: dict | None = None, study_range: dict | None = None) -> None:
    """force_figure saved to path."""
    _save(force_figure(reference, predictions, progress, scores, study_range), path)


def force_figure(reference: np.ndarray, predictions: dict[str, np.ndarray], progress: np.ndarray,
                 scores: dict | None = None, study_range: dict | None = None) -> plt.Figure:
    """Predicted vs reference force (N) on the test frames: one row per model, one column per axis.

    reference (N, 3), predictions name -> (N, 3), progress (N,) through each trial (0..1, colour).
    Each panel states its R² and MAE (scores: name -> axis -> {"r2", "mae"}, the report's table;
    computed here when not given); shaded: the study's force range (a narrower range of ours is
    easier data). Axes are shared per column and set by the reference, so one wild model does not
    squash the others (its points beyond are drawn at the edge)."""
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
            ax.text(0.03, 0.97, f"R² {r2}\nMAE {m['mae']:.3f} N", transform=ax.transAxes, va="top", fontsize=8,
                    bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
            ax.set_title(f"{name}: {ax_name}", fontsize=10)
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


def tracking_trace(path, t_s, arm_ref, deep_pred, vision_ref, sup_pred, unit: str, title: str) -> None:
    fig, ax = plt.subplots(figsize=(8, 3.2))
    t = t_s - t_s[0]
    ax.plot(t, arm_ref, "k-", lw=1, label="arm reference")
    ax.plot(t, deep_pred, "C0-", lw=1, label="deep layer (calibrated)")
    ax.plot(t, vision_ref, "k:", lw=1, label="vision reference")
    ax.plot(t, sup_pred, "C3-", lw=1, label="superficial layer (calibrated)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel(unit)
    ax.set_title(title)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def slip_detections(path, t_s, score, truth_s, detected_s, tp_det, fn_truth, threshold, title: str) -> None:
    """slip_figure saved to path."""
    _save(slip_figure(t_s, score, truth_s, detected_s, tp_det, fn_truth, threshold, title), path)


def slip_figure(t_s, score, truth_s, detected_s, tp_det, fn_truth, threshold, title: str) -> plt.Figure:
    """t_s, score (K,): the cue score (MAD units) on the session timeline (s); truth_s, detected_s:
    event times (s); tp_det: indices of matched detections; fn_truth: indices of missed truths.

    Events above, score below. The score axis is set by the threshold and the bulk of the score
    (99th percentile), not its largest spike, so the threshold stays legible; spikes beyond are
    clipped at the top. Events sit on their own strip: truth as thin ticks, TP / FP / FN markers."""
    fig, (ev, ax) = plt.subplots(2, 1, figsize=(9, 3.8), sharex=True, height_ratios=[1, 3.2],
                                 layout="constrained")
    t0 = t_s[0]
    finite = score[np.isfinite(score)]
    bulk = float(np.percentile(finite, 99)) if finite.size else 1.0
    top = max(1.6 * threshold, 1.15 * bulk, 1.0)
    bottom = min(0.0, float(finite.min()) if finite.size else 0.0)
    ax.plot(t_s - t0, np.minimum(score, top), "C7-", lw=0.8, label="cue score")
    ax.axhline(threshold, color="C1", lw=1.0, ls="-.", label="threshold")
    ax.set_ylim(bottom - 0.05 * (top - bottom), top)
    if finite.size and finite.max() > top:
        ax.text(0.995, 0.98, f"clipped at {top:.3g} (max {finite.max():.3g})", transform=ax.transAxes,
                ha="right", va="top", fontsize=7, color="0.4")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("cue score (MAD units)")
    tp = detected_s[tp_det]
    fp = np.delete(detected_s, tp_det)
    ev.vlines(truth_s - t0, 2.6, 3.4, color="k", lw=0.6, label="vision truth")
    ev.plot(truth_s[fn_truth] - t0, np.full(len(fn_truth), 3.0), "bx", ms=5, label="FN (missed)")
    ev.plot(tp - t0, np.full(tp.size, 1.0), "g^", ms=5, label="TP")
    ev.plot(fp - t0, np.full(fp.size, 1.0), "v", color="orange", ms=5, label="FP")
    ev.set_ylim(0.2, 3.8)
    ev.set_yticks([1.0, 3.0], ["detected", "truth"], fontsize=8)
    ev.set_title(title, fontsize=10)
    handles = ev.get_legend_handles_labels()[0] + ax.get_legend_handles_labels()[0]
    fig.legend(handles=handles, loc="outside right center", fontsize=7, frameon=False)
    return fig


def characterization_figure(presses, shear_n: list[np.ndarray], dc_mm: list[np.ndarray], heights: dict | None,
                            matched_load_n: float, shear_band_n: tuple[float, float], study: dict) -> plt.Figure:
    """The calibration campaign's characterisation in three panels, ours beside the study's.

    (a) each press's loading ramp, summed response (both layers) against F_z, one colour per
    position, with the matched load of the uniformity CV marked; (b) the inter-layer CoP shift
    |Δc| against |F_shear| over the slides (a random 20 000 frames), the trial-wise medians in
    the shear band and the study's median and 10-90 % range; (c) the effective heights h_x, h_y
    fitted per normal-load bin (marker size: fit R²), the study's lowest and highest bins."""
    from analysis.characterization import loading_curve

    fig, axs = plt.subplots(1, 3, figsize=(15.0, 4.4), constrained_layout=True)
    ax = axs[0]
    positions = sorted({p.position for p in presses})
    cmap = plt.get_cmap("viridis", max(len(positions), 2))
    colour = {pos: cmap(i) for i, pos in enumerate(positions)}
    for p in presses:
        load, resp = loading_curve(p.fz_n, p.response)
        ax.plot(load, resp, lw=0.5, alpha=0.5, color=colour[p.position])
    ax.axvline(matched_load_n, color="k", ls="--", lw=0.8)
    uni = study.get("uniformity", {})
    ax.set(xlabel="F_z (N)", ylabel="summed response (counts above baseline)",
           title=f"(a) loading ramps, {len(positions)} positions\nstudy: CV {uni.get('cv', float('nan')):.3f} "
                 f"at {uni.get('matched_load_n', matched_load_n):g} N")

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
        ax.legend(loc="upper left", fontsize=8)
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
    ax.legend(loc="upper left", fontsize=8)
    return fig


def characterization_plot(path, *args, **kwargs) -> None:
    """characterization_figure saved to path."""
    _save(characterization_figure(*args, **kwargs), path)
