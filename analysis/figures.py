"""Report figures (matplotlib, Agg): predicted vs reference force, tracking traces, slip detections."""

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
