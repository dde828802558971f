"""A tiny synthetic campaign written with SessionWriter, for report tests that need no simulator.

Closed-form stand-ins, not the simulated world: a Gaussian contact whose superficial and deep
centres separate by h·F_shear/F_z (h = 2 mm) for calibration trials; for grip trials an elongated
rod contact that the arm drags (deep layer) while the superficial layer sticks and slips in
steps (vision markers see the superficial layer, with 60 ms camera latency).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from layerskin_exp.config import SkinConfig
from layerskin_exp.log import SessionWriter
from layerskin_exp.types import MarkerDetection, Pose, ProtocolEvent, TwoLayerFrame, Wrench

DT_NS = 2_360_000
X = SkinConfig().taxel_centres_mm()
YY, XX = np.meshgrid(X, X, indexing="ij")


def _blob(cx, cy, sx, sy, theta, amp):
    c, s = np.cos(theta), np.sin(theta)
    dx, dy = XX[None] - cx[:, None, None], YY[None] - cy[:, None, None]
    u = c[:, None, None] * dx + s[:, None, None] * dy
    v = -s[:, None, None] * dx + c[:, None, None] * dy
    return amp[:, None, None] * np.exp(-0.5 * ((u / sx) ** 2 + (v / sy) ** 2))


def _counts(maps, rng):
    return np.clip(100 + maps + rng.normal(0, 3, maps.shape), 0, 4095).astype(np.uint16)


def _write_skin(w, sup, deep, t_ns):
    for i in range(len(t_ns)):
        w.write(TwoLayerFrame(sup[i], deep[i], i, int(t_ns[i]), int(t_ns[i])))


def calibration_trial(path, pos_index, kind, repeat, rng, n=500, h_mm=2.0, gain=1.0, config=None,
                      stream_health=None):
    x0, y0 = rng.uniform(-6, 6, 2)
    s = np.linspace(0, 1, n)
    if kind == "press":
        fz = 4.0 * np.interp(s, [0, 0.1, 0.55, 1], [0, 0, 1, 0])
        fxy = np.zeros((n, 2))
    else:
        fz = 3.0 * np.interp(s, [0, 0.05, 0.25, 1], [0, 0, 1, 1])
        phi = rng.uniform(0, 2 * np.pi)
        mag = 2.0 * np.interp(s, [0, 0.3, 1], [0, 0, 1])
        fxy = np.column_stack([mag * np.cos(phi), mag * np.sin(phi)])
    shift = h_mm * fxy / np.maximum(fz, 0.3)[:, None]
    sup = _blob(x0 + shift[:, 0] / 2, y0 + shift[:, 1] / 2, 1.5, 1.5, np.zeros(n), 250 * gain * fz)
    deep = _blob(x0 - shift[:, 0] / 2, y0 - shift[:, 1] / 2, 2.5, 2.5, np.zeros(n), 120 * gain * fz)
    t_ns = 10**9 + np.arange(n) * DT_NS
    labels = {"protocol": "force_calibration", "position_index": pos_index, "position_mm": [x0, y0], "kind": kind,
              "repeat": repeat, "direction_rad": None, "z_offset_mm": 0.0}
    with SessionWriter(path, metadata={"config": config or {}, "backend": "synthetic"}, labels=labels) as w:
        _write_skin(w, _counts(sup, rng), _counts(deep, rng), t_ns)
        for i in range(0, n, 2):
            f = np.array([fxy[i, 0], fxy[i, 1], fz[i]]) + rng.normal(0, 0.01, 3)
            w.write(Wrench(f, np.zeros(3), i, int(t_ns[i]), int(t_ns[i])))
        w.close("complete", stream_health=stream_health)


def _stick_slip(arm, limit, rng):
    """Superficial position follows arm, slipping in steps when the lag exceeds `limit`."""
    sup = np.zeros_like(arm)
    for i in range(1, arm.size):
        sup[i] = sup[i - 1]
        lag = arm[i] - sup[i]
        if abs(lag) > limit:
            sup[i] = arm[i] - np.sign(lag) * limit * rng.uniform(0.0, 0.3)
    return sup


def grip_trial(path, depth_mm, motion, trial, rng, n=1700):
    s = np.linspace(0, 1, n)
    amp = 5.0 if motion == "translation" else 25.0
    arm = amp * np.interp(s, [0, 0.1, 0.3, 0.5, 0.7, 0.9, 1], [0, 0, 1, 0, -1, 0, 0])
    sup = _stick_slip(arm, 0.12 * amp, rng)
    load = 100.0 * depth_mm * (np.arange(n) >= n // 25)  # jaws open (unloaded) for the baseline first
    t_ns = 10**9 + np.arange(n) * DT_NS
    if motion == "translation":
        s_map = _blob(-sup * 1.0, np.zeros(n), 1.2, 8.0, np.zeros(n), load * 2)
        d_map = _blob(-arm * 0.8, np.zeros(n), 2.0, 8.0, np.zeros(n), load)
    else:
        s_map = _blob(np.zeros(n), np.zeros(n), 1.2, 8.0, np.radians(-sup) + 0.3, load * 2)
        d_map = _blob(np.zeros(n), np.zeros(n), 2.0, 8.0, np.radians(-arm * 0.9) + 0.3, load)
    labels = {"protocol": "grip_depth", "grip_depth_mm": float(depth_mm), "motion": motion, "trial": trial}
    base_rot = Rotation.from_euler("xyz", [180, 0, 90], degrees=True)
    with SessionWriter(path, metadata={"config": {}, "backend": "synthetic"}, labels=labels) as w:
        w.write(ProtocolEvent("phase", "hold", int(t_ns[0])))
        w.write(ProtocolEvent("phase", "motion", int(t_ns[n // 20])))
        _write_skin(w, _counts(s_map, rng), _counts(d_map, rng), t_ns)
        for i in range(0, n, 4):
            if motion == "translation":
                pos, rot = np.array([0.4 + arm[i] * 1e-3, 0.1, 0.3]), base_rot
            else:
                pos, rot = np.array([0.4, 0.1, 0.3]), base_rot * Rotation.from_euler("z", arm[i], degrees=True)
            w.write(Pose(pos, rot.as_quat(), "tcp", int(t_ns[i]), int(t_ns[i]), i))
        cam_period = int(1e9 / 30)
        for k, tc in enumerate(range(int(t_ns[0]), int(t_ns[-1]), cam_period)):
            j = min(n - 1, (tc - int(t_ns[0])) // DT_NS)
            for mid, off in ((0, -0.01), (1, 0.01)):
                if motion == "translation":
                    p = np.array([sup[j] * 1e-3 + off, 0.0, 0.25]) + rng.normal(0, 2e-5, 3)
                    q = Rotation.identity().as_quat()
                else:
                    p = np.array([off, 0.0, 0.25])
                    q = Rotation.from_euler("z", sup[j] + rng.normal(0, 0.1), degrees=True).as_quat()
                pose = Pose(p, q, "camera", tc, tc + 60_000_000, k)
                w.write(MarkerDetection(mid, pose, np.zeros((4, 2)), k, tc, tc + 60_000_000))
        w.write(ProtocolEvent("phase", "hold", int(t_ns[-n // 20])))
        w.close("complete")


def write_campaign(root, n_positions=6, grip_depths=(6, 12), trials=3, seed=0, h_mm=2.0) -> Path:
    root = Path(root)
    rng = np.random.default_rng(seed)
    (root / "force_calibration").mkdir(parents=True, exist_ok=True)
    (root / "grip_depth").mkdir(parents=True, exist_ok=True)
    for p in range(n_positions):
        gain = rng.normal(1.0, 0.1)
        for kind, reps in (("press", 3), ("slide", 2)):
            for r in range(reps):
                calibration_trial(root / "force_calibration" / f"pos{p:03d}_{kind}{r}.mcap", p, kind, r, rng,
                                  h_mm=h_mm, gain=gain)
    for g in grip_depths:
        for motion in ("translation", "torsion"):
            for t in range(trials):
                grip_trial(root / "grip_depth" / f"g{g}_{motion}_t{t}.mcap", g, motion, t, rng)
    return root


def write_sensitivity_result(path) -> Path:
    """A screening result in the shape `python -m protocols.sensitivity` writes, with made-up
    numbers chosen against the study's (no simulator runs): the inter-layer shift at 2 N spans
    1.0-1.5 mm (the study's 2.20 lies above), position CV 0.10-0.20 (the study's 0.145 inside),
    the normal load during shear 4.1-4.3 N (the study's about 6 above), the grip preload 4.0-9.0 N
    (the study's 3.74 below), the linear R² undefined everywhere."""
    import json

    from protocols.sensitivity import OUTCOMES

    names = ["sim.sheet.interface", "sim.cover.friction", "sim.rig.gripper.support_stiffness_n_per_mm"]

    def entry(lo, hi, mu):
        return {"range": [lo, hi], "missing": 0, "mu_star": dict(zip(names, mu, strict=True)),
                "sigma": dict.fromkeys(names, 0.01)}

    morris = {"shift_per_n_mm": entry(0.8, 1.4, (0.5, 0.3, 0.0)),
              "cop_shift_at_2n_mm": entry(1.0, 1.5, (0.4, 0.3, 0.01)),
              "linear_r2_shear": {"missing": 8, "reason": "undefined in every sample"},
              "position_cv": entry(0.10, 0.20, (0.02, 0.05, 0.0)),
              "slide_fz_at_shear_n": entry(4.1, 4.3, (0.1, 0.2, 0.0)),
              "grip_preload_n": {**entry(4.0, 9.0, (0.0, 0.0, 4.5)), "missing": 2}}
    result = {"size": "quick", "campaign": ["positions.count=2"], "trajectories": 2, "num_levels": 4, "seed": 0,
              "problem": {"num_vars": 3, "names": names, "bounds": [[0, 1], [0.6, 1.2], [0.5, 2.0]]},
              "brackets_file": "layerskin_exp/sim/brackets.yaml", "wall_s": 1.0,
              "outcomes": {k: {"label": lab, "unit": u} for k, (lab, u) in OUTCOMES.items()},
              "morris": morris, "samples": [{"overrides": [], "outcomes": {}} for _ in range(8)]}
    Path(path).write_text(json.dumps(result))
    return Path(path)
