"""The manipulation rig: a UR5e carrying a Hand-E whose skin-covered finger presses a fixed rod.

Frames (all right-handed):
- base: the UR base; the TCP pose comes from the arm's motion.
- TCP: z is the approach direction, the jaws close along y; the skin finger is the -y jaw.
- skin: attached to the skin finger's cover. x = TCP x, y = -TCP z, z = TCP y (the skin normal,
  pointing from the finger toward the rod). Its origin, the sensing area's centre, lies on the
  TCP y axis at -opening/2 (symmetric jaws: closing the opening by d moves each finger d/2).
- rod: fixed in base, axis along TCP z at the home pose (so along the skin's y axis), placed
  so that the skin cover touches it at `contact_opening_mm` with the arm at home.

Arm translation along base X0 (= TCP x at the home pose) moves the rod along skin x; a rotation
of the tool about its y axis (the skin normal) turns the rod about the skin normal (yaw). The
other finger is `contact_opening_mm - rig.ROD_DIAMETER_MM` away from the rod at contact and closes
only half the commanded closure, so within the stroke used it never touches the rod.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from layerskin_exp import rig
from layerskin_exp.rig import R_TCP_SKIN
from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.kinematics import LimitedMotion
from layerskin_exp.sim.rig_config import ArmConfig, GripperConfig


def rotvec_to_matrix(rv: list[float]) -> np.ndarray:
    """Rodrigues' formula for a rotation vector (3,) -> (3, 3); cheaper than scipy per call."""
    x, y, z = rv
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        return np.eye(3)
    kx, ky, kz = x / th, y / th, z / th
    c, s = math.cos(th), math.sin(th)
    v = 1.0 - c
    return np.array([[c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s],
                     [ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s],
                     [kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v]])


class GripScene:
    indenter = "rod"
    # snapshot: TCP position (3, m), TCP rotation matrix row-major (9), jaw opening (mm), stalled (0/1)
    snapshot_names = ("x_m", "y_m", "z_m") + tuple(f"r{i}{j}" for i in range(3) for j in range(3)) + (
        "opening_mm", "stalled")

    def __init__(self, arm: ArmConfig, grip: GripperConfig) -> None:
        self.arm_cfg, self.grip_cfg = arm, grip
        self.support_stiffness_n_per_mm = grip.support_stiffness_n_per_mm
        home = np.asarray(arm.home_pose6, float)
        self.home_p_m = home[:3].copy()
        self.R_ref = Rotation.from_rotvec(home[3:]).as_matrix()
        self.pos = LimitedMotion(home[:3].tolist(), arm.max_accel_m_s2)
        self.rot = LimitedMotion([0.0, 0.0, 0.0], arm.max_angular_accel_rad_s2)
        self.jaw = LimitedMotion([grip.initial_opening_mm], grip.accel_mm_s2)
        self.requested_mm = grip.initial_opening_mm
        self.grip_speed_mm_s = grip.max_speed_mm_s
        self.force_pct = 0.0
        self.force_limit_n = grip.force_min_n
        self.stalled = False
        self.radius_mm = rig.ROD_DIAMETER_MM / 2.0
        # The rod, fixed in base (m): axis point and unit direction.
        self.R_home = self.R_ref.copy()
        self.place_rod(0.0, 0.0)
        self._R_tcp = self.R_ref.copy()
        self._last_yaw = math.pi / 2

    def place_rod(self, offset_mm: float, yaw_deg: float) -> None:
        """Clamp the rod `offset_mm` along skin x from its nominal place, turned by `yaw_deg` about
        the skin normal (both 0: the nominal placement described in the module docstring)."""
        c_tcp = np.array([offset_mm, -self.grip_cfg.contact_opening_mm / 2.0 + self.radius_mm, 0.0]) * 1e-3
        th = math.radians(yaw_deg)
        self.rod_c_m = self.home_p_m + self.R_home @ c_tcp
        # skin normal = TCP y: turn the axis (TCP z at home) about it
        self.rod_a = self.R_home @ np.array([math.sin(th), 0.0, math.cos(th)])

    def begin_trial(self, rng: np.random.Generator, variation) -> None:
        """The rod is re-clamped between trials: draw its placement (variation: TrialVariationConfig)."""
        self.place_rod(float(rng.normal(0.0, variation.rod_offset_sd_mm)),
                       float(rng.normal(0.0, variation.rod_yaw_sd_deg)))

    # ---- commands (the device twins have checked them against the devices' range) -----------
    def command_arm(self, pose6: np.ndarray, speed_m_s: float, accel_m_s2: float,
                    angular_speed_rad_s: float | None) -> None:
        pose6 = np.asarray(pose6, dtype=float).reshape(6)
        w = self.arm_cfg.max_angular_speed_rad_s if angular_speed_rad_s is None else float(angular_speed_rad_s)
        # Re-reference the rotation at the current orientation; the new target is relative to it.
        self.R_ref = self.tcp_rotation()
        rel = Rotation.from_matrix(self.R_ref.T @ Rotation.from_rotvec(pose6[3:]).as_matrix()).as_rotvec()
        self.rot.position = [0.0, 0.0, 0.0]
        self.pos.command(pose6[:3].tolist(), speed_m_s, accel_m_s2)
        self.rot.command(rel.tolist(), w)

    def command_gripper(self, opening_mm: float, speed_mm_s: float, force_pct: float) -> None:
        cfg = self.grip_cfg
        self.requested_mm = float(opening_mm)
        self.grip_speed_mm_s = float(speed_mm_s)
        self.force_pct = float(force_pct)
        self.force_limit_n = cfg.force_min_n + force_pct / 100.0 * (cfg.force_max_n - cfg.force_min_n)
        self.stalled = False
        self.jaw.command([self.requested_mm], self.grip_speed_mm_s)

    def stop_arm(self) -> None:
        self.pos.stop()
        self.rot.stop()

    def stop_gripper(self) -> None:
        self.jaw.stop()

    def stop_all(self) -> None:
        self.stop_arm()
        self.stop_gripper()

    # ---- world stepping (see World.advance for the protocol) -------------------------------
    def plan(self, m: int, dt_s: float):
        """The next m steps without changing the scene: rod (x, y, z) mm in the skin frame
        (m, 3), its yaw (m,) rad, snapshots (m, 14) and a token for commit() (one compiled call,
        mechanics.grip_plan)."""
        plans = tuple(np.empty((m, len(mo.state))) for mo in (self.pos, self.rot, self.jaw))
        xyz, yaw, R = np.empty((m, 3)), np.empty(m), np.empty((m, 3, 3))
        snap = np.empty((m, len(self.snapshot_names)))
        mk.grip_plan(self.pos.state, self.rot.state, self.jaw.state, dt_s, m, self.R_ref, self.rod_c_m, self.rod_a,
                     R_TCP_SKIN, self.radius_mm, self._last_yaw, float(self.stalled), *plans, xyz, yaw, R, snap)
        return xyz, yaw, snap, (plans, yaw, R)

    def commit(self, token, k: int) -> None:
        plans, yaw, R = token
        for motion, plan in zip((self.pos, self.rot, self.jaw), plans, strict=True):
            motion.commit(plan, k)
        self._last_yaw, self._R_tcp = float(yaw[k]), R[k]

    def first_reaction(self, token, recs: np.ndarray) -> int | None:
        """Index of the first planned step after which after_step would stop the jaws (closing,
        grip force at the setting), or None; recs (m, STEP_FIELDS) are the steps' contact records."""
        jaw = token[0][2]  # the jaw's planned states (m, state size)
        v = jaw[:, mk.M_POS + 1]
        moving = (jaw[:, mk.M_HAS_TARGET] != 0) | (jaw[:, mk.M_STOPPING] != 0)
        hit = np.flatnonzero(moving & (v < 0) & (recs[:, mk.S_FZ] >= self.force_limit_n))
        return int(hit[0]) if len(hit) else None

    def after_step(self, fz_n: float) -> bool:
        """The Hand-E stops its jaws once the grip force reaches its force setting (returns
        whether it did)."""
        if self.jaw.moving and self.jaw.velocity[0] < 0 and fz_n >= self.force_limit_n:
            self.jaw.halt()
            self.stalled = True
            return True
        return False

    def tcp_rotation(self) -> np.ndarray:
        """TCP rotation (3, 3) in base."""
        return self.R_ref @ rotvec_to_matrix(self.rot.position)

    @property
    def opening_mm(self) -> float:
        return self.jaw.position[0]

    def skin_pose(self, p_m: np.ndarray, R_tcp: np.ndarray, opening_mm: float) -> tuple[np.ndarray, np.ndarray]:
        """Skin frame in base: origin (3, m) and rotation (3, 3)."""
        origin = p_m + R_tcp @ np.array([0.0, -opening_mm / 2.0 * 1e-3, 0.0])
        return origin, R_tcp @ R_TCP_SKIN

    def indenter_pose(self) -> tuple[list[float], float]:
        """Rod in the skin frame: the axis point nearest the skin origin (x, y mm), the height of the
        rod's surface above the undeformed cover (z mm, negative = pressed), and its yaw (rad: the
        axis direction measured from skin x; +-pi/2 at the home pose, where it lies along skin y)."""
        xyz, yaw, R = np.empty((1, 3)), np.empty(1), np.empty((1, 3, 3))
        self._last_yaw = mk.rod_poses(self.R_ref, np.array([self.rot.position]), np.array([self.pos.position]),
                                      np.array([self.opening_mm]), self.rod_c_m, self.rod_a, R_TCP_SKIN,
                                      self.radius_mm, self._last_yaw, xyz, yaw, R)
        self._R_tcp = R[0]
        return xyz[0].tolist(), float(yaw[0])

    def snapshot(self) -> np.ndarray:
        return np.array([*self.pos.position, *self._R_tcp.ravel().tolist(), self.opening_mm, float(self.stalled)])
