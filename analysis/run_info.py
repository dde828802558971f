"""What produced a report, and how far to trust it: data size, force ranges, training state.

The study's numbers are printed beside ours; these summaries say when that comparison is unfair
(easier data: a narrower force range) or premature (a model that had not finished learning).
"""

from __future__ import annotations

import numpy as np

AXES = ("Fx", "Fy", "Fz")
# Mean R² over the three axes this far below a linear model of the same inputs flags a CNN as not
# converged: a CNN that reads the maps a linear model reads the moments of should do at least as
# well, so falling far short means it had not learned, not that its inputs lack the information.
# A two-layer CNN is held to the study's two-layer baseline, a single-layer one to the linear model
# of its own layer's moments (estimation.linear.layer_features).
BELOW_LINEAR_R2 = 0.2


def force_ranges(force_n: np.ndarray, test_mask: np.ndarray) -> dict:
    """Per-axis min/max of force_n (N, 3) in N, and the 5–95 % range of the test frames' shear
    magnitude |(Fx, Fy)| and normal load |Fz|."""
    force_n = np.asarray(force_n, np.float64)
    out = {ax: {"min_n": float(force_n[:, i].min()), "max_n": float(force_n[:, i].max())}
           for i, ax in enumerate(AXES)}
    test = force_n[np.asarray(test_mask, bool)]
    if len(test):
        shear = np.linalg.norm(test[:, :2], axis=1)
        out["test_shear_p5_p95_n"] = [float(v) for v in np.percentile(shear, [5, 95])]
        out["test_abs_fz_p5_p95_n"] = [float(v) for v in np.percentile(np.abs(test[:, 2]), [5, 95])]
    return out


def training_state(history: list[dict], max_epochs: int, patience: int) -> dict:
    """Epochs reached, best epoch, and whether early stopping ended the run.

    Replays CnnGruForceModel.fit's rule (an improvement is a drop of more than 1e-6; stop after
    `patience` epochs without one), so it reads the same decision from the saved history."""
    best, best_epoch, stale, early = np.inf, -1, 0, False
    for i, h in enumerate(history):
        if h["val_loss"] < best - 1e-6:
            best, best_epoch, stale = h["val_loss"], i, 0
        else:
            stale += 1
            early = stale >= patience
    return {"epochs": len(history), "max_epochs": max_epochs, "best_epoch": best_epoch + 1,
            "best_val_loss": float(best) if history else None, "early_stopped": early}


def convergence_caveats(state: dict, r2: dict, linear_r2: dict | None, baseline: str = "the linear baseline") -> list[str]:
    """Why a trained model's numbers should not be read against the study's ([] if none).

    r2 / linear_r2: axis -> R² on the test trials; linear_r2 the linear model of the same inputs
    (`baseline` names it)."""
    why = []
    if not state["early_stopped"] and state["epochs"] >= state["max_epochs"]:
        why.append(f"stopped at the epoch cap ({state['max_epochs']}) with the validation loss still "
                   f"improving (best at epoch {state['best_epoch']})")
    vals = [r2[a] for a in AXES if r2.get(a) is not None]
    lin = [linear_r2[a] for a in AXES if linear_r2 and linear_r2.get(a) is not None]
    if vals and lin and np.mean(vals) < np.mean(lin) - BELOW_LINEAR_R2:
        why.append(f"mean R² {np.mean(vals):.3f} is far below {baseline} ({np.mean(lin):.3f})")
    return why
