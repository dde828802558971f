"""Grip-depth protocol on the arm + gripper rig: one trial per run.

Open the jaws, measure the skin baseline, close slowly until the sum of both layers (baseline
subtracted) exceeds `approach.threshold_counts` for `approach.consecutive_frames` frames in a
row, stop, close a further `grip_depth` mm, run the trajectory (arm translation along X0 or
torsion about the skin normal), release. Logs skin frames, TCP pose, gripper state, marker poses
(and optionally images) and events. With `estimator` set, each skin frame also goes through
the online estimator and the live force and slip estimates are logged (/estimate/force,
/estimate/slip): the session carries its own preload estimate.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from hardware.rig import Rig
from layerskin_exp.config import ConfigError
from layerskin_exp.types import SkinEstimate
from protocols.config import GripDepthConfig, TrajectoryConfig
from protocols.identity import design_id, exact_number, trial_identity, write_manifest
from protocols.loop import ControlLoop, DeviceTimeout
from protocols.runner import ProtocolError, TrialLog, TrialResult, run_trial, trial_slot_s
from protocols.safety import Safety
from protocols.stops import NO_CONTACT, TARGET_REACHED

PROTOCOL = "grip_depth"


def trial_labels(cfg: GripDepthConfig) -> dict:
    return {"protocol": PROTOCOL, "grip_depth_mm": float(cfg.grip_depth), "motion": cfg.trajectory.motion,
            "trial": int(cfg.trial)}


def trial_name(labels: dict) -> str:
    """g<depth>_<motion>_t<trial>; the depth is written in full (g9, g9.5, g9.0000001), so two
    trials of one design never share a name."""
    return f"g{exact_number(labels['grip_depth_mm'])}_{labels['motion']}_t{labels['trial']}"


def trial_path(cfg: GripDepthConfig, config: dict) -> Path:
    """Where the trial of `cfg` goes; config: the resolved config (its design names the folder)."""
    return Path(cfg.data_root) / PROTOCOL / design_id(config) / f"{trial_name(trial_labels(cfg))}.mcap"


def trajectory_poses(start_pose6: np.ndarray, traj: TrajectoryConfig) -> list[np.ndarray]:
    """(6,) UR poses for each waypoint after the first, from the start pose.

    translation: the position moves waypoint mm along the (base-frame) axis.
    torsion: the orientation turns waypoint degrees about the (tool-frame) axis, about the TCP.
    """
    axis = np.asarray(traj.axis, float)  # of the motion that runs
    axis /= np.linalg.norm(axis)
    start_rot = Rotation.from_rotvec(start_pose6[3:])
    poses = []
    for w in traj.waypoints[1:]:
        pose = np.array(start_pose6, float)
        if traj.motion == "translation":
            pose[:3] = start_pose6[:3] + 1e-3 * w * axis
        else:
            pose[3:] = (start_rot * Rotation.from_rotvec(np.radians(w) * axis)).as_rotvec()
        poses.append(pose)
    return poses


class GripControl:
    """Gripper and arm moves of one trial: safety-checked, waited on through the control loop."""

    def __init__(self, log: TrialLog, safety: Safety, cfg: GripDepthConfig) -> None:
        self.log, self.safety, self.cfg = log, safety, cfg
        self.rig = log.rig
        self.loop = ControlLoop(log, cfg.control_period_s, trips_abort=True, trial_timeout_s=cfg.trial_timeout_s)

    def gripper_opening_mm(self, first_state_timeout_s: float = 0.5) -> float:
        """The last reported jaw opening; waits (ticking) for the gripper's first state report."""
        if self.log.last_gripper is None:
            self.log.drain()
        if self.log.last_gripper is None:
            self.loop.until(lambda *_: self.log.last_gripper is not None, first_state_timeout_s,
                            "gripper's first state report (is the gripper streaming?)")
        return float(self.log.last_gripper.position_mm)

    def move_gripper(self, opening_mm: float, speed_mm_s: float, force_pct: float, min_opening_mm: float) -> None:
        self.safety.check_gripper_move(opening_mm, speed_mm_s, min_opening_mm)
        self.rig.gripper.move(opening_mm, speed_mm_s, force_pct)
        self.loop.tick()  # let the move start before asking whether it is moving
        travel_mm = abs(self.gripper_opening_mm() - opening_mm)
        self.loop.wait(self.rig.gripper.is_moving, 1.5 * travel_mm / speed_mm_s + 3.0, "gripper move")

    def approach(self) -> float:
        """Close until contact; returns the jaw opening (mm) where contact was declared."""
        a = self.cfg.approach
        self.log.event("phase", "approach")
        self.safety.check_gripper_move(a.min_opening_mm, a.speed_mm_s, a.min_opening_mm)
        baseline_frames = self.loop.hold(a.baseline_s)
        baseline = (float(np.mean([_total(f) for f in baseline_frames])) if baseline_frames else 0.0)
        self.rig.gripper.move(a.min_opening_mm, a.speed_mm_s, a.force_pct)
        state = {"run": 0, "started": False}

        def contact_or_end(frames, _wrenches):
            for f in frames:
                state["run"] = state["run"] + 1 if _total(f) - baseline > a.threshold_counts else 0
                if state["run"] >= a.consecutive_frames:
                    return "contact", f
            moving = self.rig.gripper.is_moving()
            state["started"] |= moving
            return ("end", None) if state["started"] and not moving else None

        try:
            kind, frame = self.loop.until(contact_or_end, a.start_opening_mm / a.speed_mm_s * 1.5 + 3.0,
                                          "gripper approach")
        except DeviceTimeout:
            kind, frame = "end", None
        if kind == "end":
            self.log.stop(NO_CONTACT, opening_mm=self.gripper_opening_mm())
            raise ProtocolError(f"no contact before the jaws reached {self.gripper_opening_mm():.1f} mm "
                                "(approach.min_opening_mm); check the rod position or approach.threshold_counts")
        self.rig.gripper.stop()
        self.loop.wait(self.rig.gripper.is_moving, 3.0, "gripper stop")
        opening = self.gripper_opening_mm()
        self.log.event("contact", "contact", opening_mm=opening, baseline_counts=baseline,
                       frame_seq=int(frame.seq), total_counts=int(_total(frame)))
        return opening

    def move_arm(self, pose6: np.ndarray, start_pose6: np.ndarray, traj: TrajectoryConfig) -> None:
        here = self.rig.arm.tcp_pose6()
        if traj.motion == "translation":
            t = traj.translation
            speed_mm_s, angular_deg_s, accel = t.speed_mm_s, None, t.accel_mm_s2 / 1000.0  # m/s^2
            duration_s = 1000.0 * float(np.linalg.norm(pose6[:3] - here[:3])) / t.speed_mm_s
        else:
            t = traj.torsion
            # Arm.move_linear takes one acceleration; for a turn the drivers read it as rad/s^2.
            speed_mm_s, angular_deg_s, accel = min(1.0, self.cfg.safety.max_arm_speed_mm_s), t.speed_deg_s, \
                t.accel_rad_s2
            rel = Rotation.from_rotvec(pose6[3:]) * Rotation.from_rotvec(here[3:]).inv()
            duration_s = float(np.degrees(rel.magnitude())) / t.speed_deg_s
        self.safety.check_arm_move(pose6, start_pose6, speed_mm_s, angular_deg_s)
        self.rig.arm.move_linear(pose6, speed_mm_s / 1000.0, accel,
                                 None if angular_deg_s is None else float(np.radians(angular_deg_s)))
        self.loop.tick()
        self.loop.wait(self.rig.arm.is_moving, 1.5 * duration_s + 5.0, "arm move")


def _total(frame) -> int:
    """Sum of both layers' counts of one frame pair."""
    return int(frame.superficial.sum(dtype=np.int64) + frame.deep.sum(dtype=np.int64))


def log_estimates(log: TrialLog, online) -> None:
    """From now on, every skin frame the log drains goes through `online` (an OnlineEstimator)
    and each new estimate is written to the session beside the frames."""

    def estimates(frames) -> list[SkinEstimate]:
        out = []
        for f in frames:
            e = online.update(f.superficial, f.deep, f.device_t_ns)
            if e is not None and e.new:
                score = None if e.slip_score != e.slip_score else e.slip_score  # NaN: no slip detector
                out.append(SkinEstimate(e.force_n, score, e.slip, e.frame, e.t_ns, f.host_t_ns))
        return out

    log.derive.append(estimates)


@functools.lru_cache(maxsize=4)
def online_estimator(path: str):
    """The OnlineEstimator of an artifact, loaded once per process (its ONNX export imports torch.onnx
    and onnx and takes a while): the jobs of a sweep in one process share it, each trial resets it."""
    from layerskin_exp.estimation import OnlineEstimator

    return OnlineEstimator.from_artifact(path)


def prepare_grip(cfg: GripDepthConfig) -> None:
    """Before the devices connect (run_app's `prepare`): load the estimator, so that a bad artifact
    refuses the run before anything moves and its imports and export do not run while the devices
    stream (the loopback emulators in this process keep 50 ms deadlines)."""
    if cfg.estimator:
        online_estimator(cfg.estimator)


def run_grip_trial(cfg: GripDepthConfig, rig: Rig, metadata: dict, live=None) -> TrialResult:
    if rig.arm is None or rig.gripper is None:
        raise ConfigError(f"hardware: backend {rig.backend!r} gave no arm/gripper; the grip-depth protocol "
                          "needs the gripper setup")
    safety = Safety(cfg.safety, rig)
    safety.check_grip_depth(cfg.grip_depth)
    labels = trial_labels(cfg)
    online = None
    if cfg.estimator:
        online = online_estimator(cfg.estimator)
        online.reset()  # this trial's own baseline and windows

    def body(log: TrialLog) -> None:
        if online is not None:
            log_estimates(log, online)
        ctl = GripControl(log, safety, cfg)
        a = cfg.approach
        log.event("phase", "open")
        ctl.move_gripper(a.start_opening_mm, cfg.release.speed_mm_s, a.force_pct, a.min_opening_mm)
        contact_mm = ctl.approach()
        target_mm = contact_mm - cfg.grip_depth
        log.event("phase", "close", grip_depth_mm=cfg.grip_depth, contact_opening_mm=contact_mm,
                  target_opening_mm=target_mm)
        ctl.move_gripper(target_mm, cfg.close.speed_mm_s, cfg.close.force_pct, a.min_opening_mm)
        log.event("phase", "hold", opening_mm=ctl.gripper_opening_mm())
        ctl.loop.hold(max(cfg.close.settle_s, cfg.hold_s))
        start = np.asarray(rig.arm.tcp_pose6(), float)
        traj = cfg.trajectory
        units = {"waypoints_mm": traj.waypoints, "speed_mm_s": traj.translation.speed_mm_s} \
            if traj.motion == "translation" else {"waypoints_deg": traj.waypoints, "speed_deg_s": traj.torsion.speed_deg_s}
        log.event("phase", "motion", motion=traj.motion, **units, start_pose6=start.tolist())
        for i, pose in enumerate(trajectory_poses(start, cfg.trajectory), start=1):
            log.event("waypoint", f"{cfg.trajectory.waypoints[i]:g}", index=i)
            ctl.move_arm(pose, start, cfg.trajectory)
        log.stop(TARGET_REACHED)
        log.event("phase", "hold")
        ctl.loop.hold(cfg.hold_s)
        log.event("phase", "release")
        ctl.move_gripper(cfg.release.opening_mm, cfg.release.speed_mm_s, a.force_pct, a.min_opening_mm)

    meta = {**metadata, "protocol": PROTOCOL, "plan": labels}
    path = trial_path(cfg, metadata["config"])
    write_manifest(path.parent, metadata["config"])
    result = run_trial(rig, path, labels, meta, body,
                       identity=trial_identity(metadata["config"], labels), save_images=cfg.save_images, live=live,
                       slot_s=trial_slot_s(cfg.trial, cfg.trial_timeout_s),
                       max_lost_skin_frames=cfg.max_lost_skin_frames)
    print(result.summary(), flush=True)
    return result
