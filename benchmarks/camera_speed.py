"""Marker camera render + detect per frame (the default 1280x720, 2-marker, 4x-supersampled camera).

Sequences: `moving` (every frame a new pose: the layer drifts up to 0.3 mm/frame, turns and
tilts) and `still` (one pose held, as during a hold or a stuck contact); sensor noise on.
Paths, run interleaved frame by frame on the same poses so load on the host hits them alike:
- tracked: the camera as simulated now (window search from the last detections, still-pose
  render reuse);
- baseline_full_frame: every frame rendered afresh and searched over the whole frame (the
  pipeline without tracking);
- baseline_render_region: the previous per-frame work: fresh render, multi-scale search over
  the region the renderer chose, same corner refinement and layer PnP.
Accuracy of the tracked path: |depth| and rotation-angle errors against the rendered poses.
Each path renders and detects one frame before the timing (one-off costs: compiled kernels,
the sensor-noise bank).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.spatial.transform import Rotation

from layerskin_exp.sim.camera import MarkerImager
from layerskin_exp.sim.rig_config import CameraConfig
from layerskin_exp.vision import refine_marker_corners

FACING = Rotation.from_rotvec([np.pi, 0.0, 0.0])


def moving_layer(cfg: CameraConfig, n: int, seed: int, step_mm: float = 0.3) -> list[dict]:
    """n frames of marker poses (id -> (R, t mm)) of a drifting, slowly turning and tilting layer."""
    rng = np.random.default_rng(seed)
    centre = np.array([np.mean(cfg.marker_x_mm), np.mean(cfg.marker_y_mm), 0.0])
    c, v = np.array([0.0, 0.0, cfg.distance_mm]), rng.uniform(-step_mm, step_mm, 3)
    out = []
    for k in range(n):
        c = np.clip(c + v, [-4.0, -4.0, cfg.distance_mm - 4.0], [4.0, 4.0, cfg.distance_mm + 4.0])
        v = np.clip(v + rng.normal(0.0, step_mm / 6, 3), -step_mm, step_mm)
        tilt = np.radians(3.0) * np.sin([k / 7.0, k / 11.0])
        R = (Rotation.from_rotvec([*tilt, 0.3 * np.sin(k / 15.0)]) * FACING).as_matrix()
        out.append({mid: (R, c + R @ (np.array([x, y, 0.0]) - centre))
                    for mid, x, y in zip(cfg.marker_ids, cfg.marker_x_mm, cfg.marker_y_mm, strict=True)})
    return out


def _render_region_detect(imager: MarkerImager, frame) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """The previous detection: multi-scale search of the rendered region, refinement, layer PnP."""
    tr = imager.tracker
    corners, ids, _ = tr.acquirer.detectMarkers(frame.patch)
    if ids is None:
        return []
    c = np.stack([x.reshape(4, 2) for x in corners]).astype(np.float64)
    refined = refine_marker_corners(frame.patch, c) + frame.origin_px
    found = dict(zip(ids.ravel().tolist(), refined, strict=True))
    layer = tr.layer_pose(found) if len(found) >= 2 else None
    return [] if layer is None else [(mid, layer[0], layer[1]) for mid in found]


def _time_paths(poses_seq: list[dict], cfg: CameraConfig) -> dict:
    paths = {"tracked": MarkerImager(cfg), "baseline_full_frame": MarkerImager(cfg, track=False, reuse_still=False),
             "baseline_render_region": MarkerImager(cfg, reuse_still=False)}
    rngs = {k: np.random.default_rng(0) for k in paths}
    for imager in paths.values():  # one-off costs (compiled kernels, the sensor-noise bank) outside the timing
        imager.detect(imager.render(poses_seq[-1], np.random.default_rng(1)))
        imager.reset_tracking()
        imager.tracker.full_searches = 0
    render_s = dict.fromkeys(paths, 0.0)
    detect_s = dict.fromkeys(paths, 0.0)
    err = []
    for poses in poses_seq:
        for name, imager in paths.items():
            t0 = time.perf_counter()
            frame = imager.render(poses, rngs[name])
            t1 = time.perf_counter()
            if name == "baseline_render_region":
                _render_region_detect(imager, frame)
            else:
                dets = imager.detect(frame)
            render_s[name] += t1 - t0
            detect_s[name] += time.perf_counter() - t1
            if name == "tracked":
                for d in dets:
                    R, t = poses[d.marker_id]
                    ang = (Rotation.from_rotvec(d.rvec).inv() * Rotation.from_matrix(R)).magnitude()
                    err.append([abs(d.tvec_mm[2] - t[2]), np.degrees(ang)])
    n = len(poses_seq)
    out = {}
    for name in paths:
        out[f"{name}_render_ms"] = render_s[name] / n * 1e3
        out[f"{name}_detect_ms"] = detect_s[name] / n * 1e3
        out[f"{name}_total_ms"] = (render_s[name] + detect_s[name]) / n * 1e3
    err = np.array(err)
    out["tracked_detections"] = len(err)
    out["tracked_full_searches"] = paths["tracked"].tracker.full_searches
    out["tracked_depth_err_max_mm"] = float(err[:, 0].max())
    out["tracked_depth_err_p95_mm"] = float(np.percentile(err[:, 0], 95))
    out["tracked_angle_err_max_deg"] = float(err[:, 1].max())
    out["tracked_angle_err_p95_deg"] = float(np.percentile(err[:, 1], 95))
    return out


def run() -> dict:
    cfg = CameraConfig()
    moving = moving_layer(cfg, 300, 0)
    still = [moving[0]] * 100
    out = {"frames_moving": len(moving), "frames_still": len(still)}
    for label, seq in (("moving", moving), ("still", still)):
        out.update({f"{label}_{k}": v for k, v in _time_paths(seq, cfg).items()})
    for label in ("moving", "still"):
        for base in ("baseline_full_frame", "baseline_render_region"):
            out[f"{label}_speedup_vs_{base}"] = out[f"{label}_{base}_total_ms"] / out[f"{label}_tracked_total_ms"]
    return out
