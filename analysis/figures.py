"""Report figures (matplotlib, Agg): predicted vs reference force, tracking traces, slip detections."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

AXES = ("Fx", "Fy", "Fz")


def force_scatter(path, reference: np.ndarray, predictions: dict[str, np.ndarray], progress: np.ndarray) -> None:
    """One row per model, one column per axis; colour = progress through the trial (0..1)."""
    fig, axs = plt.subplots(len(predictions), 3, figsize=(10, 3.2 * len(predictions)), squeeze=False)
    for r, (name, pred) in enumerate(predictions.items()):
        for c, ax_name in enumerate(AXES):
            ax = axs[r, c]
            ax.scatter(reference[:, c], pred[:, c], c=progress, s=2, cmap="viridis", rasterized=True)
            lo = float(min(reference[:, c].min(), pred[:, c].min()))
            hi = float(max(reference[:, c].max(), pred[:, c].max()))
            ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
            ax.set_title(f"{name}: {ax_name}")
            ax.set_xlabel("reference (N)")
            ax.set_ylabel("predicted (N)")
    fig.tight_layout()
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
    """Score trace, threshold, truth (dashed), TP (green ^), FP (orange v), FN (blue x)."""
    fig, ax = plt.subplots(figsize=(8, 3.2))
    t0 = t_s[0]
    ax.plot(t_s - t0, score, "C7-", lw=0.8, label="cue score (MAD units)")
    ax.axhline(threshold, color="C1", lw=0.8, ls="-.", label="threshold")
    for ts in truth_s:
        ax.axvline(ts - t0, color="k", ls="--", lw=0.5)
    top = float(np.nanmax(score)) if score.size else 1.0
    tp = detected_s[tp_det]
    fp = np.delete(detected_s, tp_det)
    ax.plot(tp - t0, np.full(tp.size, top * 1.05), "g^", ms=5, label="TP")
    ax.plot(fp - t0, np.full(fp.size, top * 1.05), "v", color="orange", ms=5, label="FP")
    ax.plot(truth_s[fn_truth] - t0, np.full(len(fn_truth), top * 1.1), "bx", ms=5, label="FN")
    ax.set_xlabel("time (s)")
    ax.set_title(title)
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
