"""Speed and memory of the simulated rig, driven the way a protocol drives it.

- calibration press/slide on the platform (10 ms control ticks, every stream drained each tick);
- grip trial with camera rendering: approach, close 12 mm, 0 -> +5 -> 0 -> -5 -> 0 mm at 2 mm/s;
- peak Python heap (tracemalloc) of a 60 s grip trial that keeps every record it reads.
Shares of wall time: skin frames (SkinModel.frames_of_steps) in both trials, camera render + detect in the grip.
Each speed is simulated seconds per wall second. Baseline, same run: the same trial with the
plain numpy frame pipeline (layerskin_exp.sim.reference, via benchmarks/skin_naive.py) in place
of the frame kernel. It is very slow, so its cost per frame pair is timed on a short stretch and
the baseline extrapolated: wall - time in frames + frames x naive cost per frame.
"""

from __future__ import annotations

import time
import tracemalloc

import numpy as np

from benchmarks.skin_naive import naive_frames
from hardware.sim import build_sim_rig
from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.config import SimConfig

TICK_S = 0.01


class _TimedFrames:
    """Wraps a skin model's frame pipeline (frames_of_steps, what the skin reader calls) to count
    frames and the wall time spent in it."""

    def __init__(self, model) -> None:
        self.inner, self.n, self.wall_s = model.frames_of_steps, 0, 0.0
        model.frames_of_steps = self

    def __call__(self, recs, t_s):
        t0 = time.perf_counter()
        out = self.inner(recs, t_s)
        self.wall_s += time.perf_counter() - t0
        self.n += len(t_s)
        return out


class _TimedCamera:
    """Wraps a camera imager's render and detect to sum the wall time spent in them."""

    def __init__(self, imager) -> None:
        self.wall_s = 0.0
        for name in ("render", "detect"):
            setattr(imager, name, self._timed(getattr(imager, name)))

    def _timed(self, fn):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.wall_s += time.perf_counter() - t0
        return call


def _drain(rig, keep=None):
    for dev in rig.devices():
        recs = dev.read_available()
        if keep is not None:
            keep.extend(recs)


def _until_still(rig, mover, keep=None, max_s=60.0, tick_s=None):
    tick_s = tick_s or TICK_S
    t = 0.0
    while mover.is_moving() and t < max_s:
        rig.clock.sleep(tick_s)
        _drain(rig, keep)
        t += tick_s
    return t


def calibration_trial(seed: int = 0, tick_s: float = TICK_S):
    rig = build_sim_rig(SimConfig(seed=seed), SkinConfig(), "platform")
    rig.connect()
    timed = _TimedFrames(rig.extras["world"].skin_model)
    t0 = time.perf_counter()
    sim_s = 0.0
    for target, speed in (((2.0, 1.0, 0.5), 8.0), ((2.0, 1.0, -1.8), 2.0), ((5.0, 1.0, -1.8), 2.0),
                          ((5.0, 1.0, 1.0), 8.0)):
        rig.platform.move_to(np.array(target), speed)
        sim_s += _until_still(rig, rig.platform, tick_s=tick_s)
    return sim_s, time.perf_counter() - t0, timed


def grip_trial(seed: int = 0, keep=None, repeats: int = 1):
    rig = build_sim_rig(SimConfig(seed=seed), SkinConfig(), "gripper")
    rig.connect()
    world = rig.extras["world"]
    timed = _TimedFrames(world.skin_model)
    timed.camera = _TimedCamera(rig.camera.imager)
    t0 = time.perf_counter()
    sim_s = 0.0
    rig.gripper.move(40.0, 20.0, 0.0)
    sim_s += _until_still(rig, rig.gripper, keep)
    rig.gripper.move(0.0, 20.0, 0.0)
    while world.state.force_n[2] < 0.05:
        rig.clock.sleep(0.0025)
        sim_s += 0.0025
    rig.gripper.stop()
    rig.gripper.move(world.scene.opening_mm - 12.0, 20.0, 50.0)
    sim_s += _until_still(rig, rig.gripper, keep)
    p0 = rig.arm.tcp_pose6()
    for _ in range(repeats):
        for dx_mm in (5.0, 0.0, -5.0, 0.0):
            p = p0.copy()
            p[0] += dx_mm * 1e-3
            rig.arm.move_linear(p, 0.002, 0.5)
            sim_s += _until_still(rig, rig.arm, keep)
    n_det = rig.camera.health.received
    return sim_s, time.perf_counter() - t0, timed, n_det


def naive_cost_per_frame_s(n: int = 4) -> float:
    from layerskin_exp.sim.skin import SkinModel

    model = SkinModel(SimConfig(), SkinConfig(), "hemisphere", np.random.default_rng(0))
    states = [model.step(k * 1e-3, np.array([0.1 * k, 0.0, -1.5])) for k in range(n)]
    t0 = time.perf_counter()
    naive_frames(model, states, np.arange(n) * 2.36e-3)
    return (time.perf_counter() - t0) / n


def run() -> dict:
    naive_s = naive_cost_per_frame_s()
    # The compiled kernels load from numba's on-disk cache on their first call in a process (a
    # campaign pays that once, not per trial): warm them on a short trial of each rig first.
    t0 = time.perf_counter()
    calibration_trial(seed=9)
    grip_trial(seed=9)
    warmup_s = time.perf_counter() - t0
    cal_sim, cal_wall, cal_frames = calibration_trial()
    coarse_sim, coarse_wall, _ = calibration_trial(tick_s=0.1)  # bigger frame batches per advance
    grip_sim, grip_wall, grip_frames, n_det = grip_trial()

    def baseline(sim_s, wall_s, frames):
        return sim_s / (wall_s - frames.wall_s + frames.n * naive_s)

    tracemalloc.start()
    kept: list = []
    mem_sim, _, _, _ = grip_trial(seed=1, keep=kept, repeats=6)  # ~60 s of motion
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "calibration_sim_s": cal_sim,
        "calibration_x_realtime": cal_sim / cal_wall,
        "calibration_frames_share_of_wall": cal_frames.wall_s / cal_wall,
        "calibration_baseline_naive_x_realtime": baseline(cal_sim, cal_wall, cal_frames),
        "calibration_100ms_tick_x_realtime": coarse_sim / coarse_wall,
        "grip_sim_s": grip_sim,
        "grip_x_realtime": grip_sim / grip_wall,
        "grip_frames_share_of_wall": grip_frames.wall_s / grip_wall,
        "grip_camera_share_of_wall": grip_frames.camera.wall_s / grip_wall,  # render + detect
        "grip_camera_detections": n_det,
        "grip_baseline_naive_x_realtime": baseline(grip_sim, grip_wall, grip_frames),
        "naive_frame_pair_ms": naive_s * 1e3,
        "memory_trial_sim_s": mem_sim,
        "memory_records_kept": len(kept),
        "memory_peak_mb": peak / 2**20,
        "warmup_wall_s": warmup_s,  # first trial of each rig in the process, kernels loading
    }


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k}: {v:.4g}" if isinstance(v, float) else f"{k}: {v}")
