"""Simulated UR5e: linear tool moves under speed limits, TCP pose streamed at 500 Hz (RTDE)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from hardware.interfaces import Arm, DeviceError
from hardware.sim.stream_device import SimStreamMixin
from layerskin_exp.sim.grip_scene import GripScene
from layerskin_exp.sim.rig_config import ArmConfig
from layerskin_exp.sim.world import World
from layerskin_exp.types import Pose


class SimArm(SimStreamMixin, Arm):
    def __init__(self, world: World, scene: GripScene, cfg: ArmConfig) -> None:
        super().__init__()
        self.world, self.scene, self.cfg = world, scene, cfg
        self.stream = world.new_stream("arm", cfg.clock, 1.0 / cfg.rate_hz)
        self._noise_rng = np.random.default_rng(self.stream.rng.integers(2**63))
        self._last_rot: tuple[np.ndarray, np.ndarray] | None = None  # (rotation (9,), its quaternion (4,))
        world.add_producer(self.stream, self._produce)
        world.on_trial(self._reseed)

    def _reseed(self, world: World) -> None:
        self._noise_rng = world.rng("arm.noise")

    def _produce(self, world: World, t_s: np.ndarray, idx: np.ndarray) -> None:
        snap = world.snapshots(idx)
        p = snap[:, :3] + self._noise_rng.normal(0.0, self.cfg.position_noise_m, (len(t_s), 3))
        q = self._quats(snap[:, 3:12])
        seq, dev_ns, host_ns = (a.tolist() for a in self.stream.stamp(t_s))
        self.stream.push_many(host_ns, [Pose(pi, qi, "base", d, h, k)
                                        for pi, qi, d, h, k in zip(p, q, dev_ns, host_ns, seq, strict=True)])

    def _quats(self, rot9: np.ndarray) -> np.ndarray:
        """(N, 4) quaternions x, y, z, w of row-major rotation matrices (N, 9). The tool mostly
        keeps its orientation: when every matrix equals the last one converted, reuse its result."""
        last = self._last_rot
        if last is not None and (rot9 == last[0]).all():
            return np.repeat(last[1][None], len(rot9), axis=0)
        q = Rotation.from_matrix(rot9.reshape(-1, 3, 3)).as_quat()
        self._last_rot = (rot9[-1].copy(), q[-1].copy())
        return q

    def move_linear(self, pose6: np.ndarray, speed_m_s: float, accel_m_s2: float,
                    angular_speed_rad_s: float | None = None) -> None:
        """Refuse what the UR controller would (unreachable pose, beyond its speed limits)."""
        self._require_connected()
        cfg = self.cfg
        pose6 = np.asarray(pose6, dtype=float).reshape(-1)
        if pose6.shape != (6,) or not np.all(np.isfinite(pose6)):
            raise DeviceError(f"arm: pose {pose6.tolist()} must be six finite values [x, y, z, rx, ry, rz]")
        lo, hi = np.asarray(cfg.workspace_min_m), np.asarray(cfg.workspace_max_m)
        if np.any(pose6[:3] < lo) or np.any(pose6[:3] > hi):
            raise DeviceError(f"arm: target position {np.round(pose6[:3], 5).tolist()} m is outside the reachable "
                              f"box {lo.tolist()}..{hi.tolist()} m (sim.rig.arm.workspace_*)")
        if not (np.isfinite(speed_m_s) and 0 < speed_m_s <= cfg.max_speed_m_s):
            raise DeviceError(f"arm: speed {speed_m_s!r} m/s is outside (0, {cfg.max_speed_m_s}] m/s")
        if not (np.isfinite(accel_m_s2) and 0 < accel_m_s2 <= cfg.max_accel_m_s2):
            raise DeviceError(f"arm: acceleration {accel_m_s2!r} m/s^2 is outside (0, {cfg.max_accel_m_s2}]")
        w = cfg.max_angular_speed_rad_s if angular_speed_rad_s is None else float(angular_speed_rad_s)
        if not (np.isfinite(w) and 0 < w <= cfg.max_angular_speed_rad_s):
            raise DeviceError(f"arm: angular speed {angular_speed_rad_s!r} rad/s is outside "
                              f"(0, {cfg.max_angular_speed_rad_s}]")
        self.scene.command_arm(pose6, speed_m_s, accel_m_s2, angular_speed_rad_s)

    def stop(self) -> None:
        self._require_connected()
        self.scene.stop_arm()

    def is_moving(self) -> bool:
        self._require_connected()
        return self.scene.pos.moving or self.scene.rot.moving

    def tcp_pose6(self) -> np.ndarray:
        self._require_connected()
        rv = Rotation.from_matrix(self.scene.tcp_rotation()).as_rotvec()
        return np.concatenate((np.asarray(self.scene.pos.position, float), rv))

    def tcp_speed6(self) -> np.ndarray:
        """TCP twist [vx, vy, vz, wx, wy, wz] (m/s, rad/s, base frame), as RTDE's actual_TCP_speed.
        The turn is a rotation vector r relative to the reference orientation R_ref; its angular
        velocity in base is R_ref J(r) dr/dt with J the rotation vector's (left) Jacobian."""
        self._require_connected()
        r, r_dot = np.asarray(self.scene.rot.position, float), np.asarray(self.scene.rot.velocity, float)
        th = float(np.linalg.norm(r))
        k = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        if th < 1e-8:
            jac = np.eye(3) + 0.5 * k
        else:
            jac = np.eye(3) + (1.0 - np.cos(th)) / th**2 * k + (th - np.sin(th)) / th**3 * (k @ k)
        w = self.scene.R_ref @ (jac @ r_dot)
        return np.concatenate((np.asarray(self.scene.pos.velocity, float), w))

    def read_available(self) -> list[Pose]:
        return self._drain()
