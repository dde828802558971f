"""Contact-motion tracking: references from arm and vision poses, LOTO scale-and-offset calibration.

References (relative to the trial start, resampled onto the skin timeline):
- translation: displacement from the first sample, projected onto its principal direction (first
  right singular vector), in mm;
- torsion: rotation relative to the first sample, as a rotation vector projected onto its
  principal axis, in degrees.
The sign of either is fixed so that the first large excursion (largest |q| in the first half of
the trial) is positive — the trajectories go to + first.

Skin readouts: translation uses the layer CoP displacement from the trial start (2-D), reduced
to a scalar along the principal direction of the training trials' displacements; torsion the PCA
angle unwrapped (period π) relative to the trial start. In each fold the readout's sign is taken
so that the training slope is positive; q̂ = a·q + b is fitted on the training trials only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from analysis.metrics import mae, r2_score


def _orient(q: np.ndarray) -> np.ndarray:
    half = q[: max(1, q.size // 2)]
    return q if half.size == 0 or half[np.argmax(np.abs(half))] >= 0 else -q


def _principal(v: np.ndarray) -> np.ndarray:
    """Unit principal direction of displacement rows v (N, D) (not centred: relative to start)."""
    if not np.any(v):
        e = np.zeros(v.shape[1])
        e[0] = 1.0
        return e
    return np.linalg.svd(v, full_matrices=False)[2][0]


def translation_reference_mm(position_m: np.ndarray) -> np.ndarray:
    """(N, 3) positions in m -> (N,) displacement from the first sample along the motion, mm."""
    d = (np.asarray(position_m, np.float64) - position_m[0]) * 1e3
    return _orient(d @ _principal(d))


def torsion_reference_deg(orientation_xyzw: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions -> (N,) rotation from the first sample about the dominant axis, degrees."""
    r = Rotation.from_quat(np.asarray(orientation_xyzw, np.float64))
    rv = (r[0].inv() * r).as_rotvec()
    return _orient(np.degrees(rv @ _principal(rv)))


def unwrap_angle(theta_rad: np.ndarray) -> np.ndarray:
    """PCA angles have period π: unwrap them along time. (N,) -> (N,) rad."""
    return np.unwrap(2.0 * np.asarray(theta_rad, np.float64)) / 2.0


@dataclass
class TrackingTrial:
    """One grip trial for one layer: readout and reference on the skin timeline.

    readout: (N, 2) CoP displacement in mm for translation, (N, 1) angle change in ° for torsion.
    reference: (N,) mm or °.
    """

    readout: np.ndarray
    reference: np.ndarray
    t_s: np.ndarray


def _direction(trials: list[TrackingTrial]) -> np.ndarray:
    return _principal(np.concatenate([t.readout for t in trials]))


def loto_calibration(trials: list[TrackingTrial]) -> dict:
    """Leave-one-trial-out q̂ = a·q + b. Returns mean slope a, pooled out-of-fold R², MAE, and the
    out-of-fold predictions per trial (list of (N,) arrays)."""
    n = len(trials)
    if n < 2:
        raise ValueError(f"{n} trial(s): leave-one-trial-out calibration needs at least two")
    slopes, preds = [], []
    for i in range(n):
        train = [t for j, t in enumerate(trials) if j != i]
        u = _direction(train)
        q = np.concatenate([t.readout @ u for t in train])
        ref = np.concatenate([t.reference for t in train])
        a, b = np.polyfit(q, ref, 1) if np.ptp(q) > 0 else (0.0, float(ref.mean()))
        # The readout's axis sign is arbitrary; report the slope of the sign-corrected readout.
        slopes.append(abs(a))
        preds.append(a * (trials[i].readout @ u) + b)
    y = np.concatenate([t.reference for t in trials])
    p = np.concatenate(preds)
    return {"a": float(np.mean(slopes)), "r2": float(r2_score(y, p)), "mae": float(mae(y, p)),
            "n_trials": n, "predictions": preds}
