"""Safety limits enforced by the framework, on every backend.

- Normal force: a ceiling guard on the rig, so the backend checks every F/T sample as it is
  acquired, whatever stop condition is latched (a press target, the slow zone), stops motion on
  the first one over the limit (the protocol loop is far coarser) and keeps every sample over it
  as a safety event.
- Workspace bounds and speed caps: checked before each motion command; a command outside them
  is refused (`SafetyError`) and never reaches the device.
- Grip depth: capped, and a closure may not command the jaws below their minimum opening.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from hardware.rig import Rig
from layerskin_exp.types import Wrench
from protocols.config import SafetyConfig
from protocols.stops import FORCE_LIMIT, SKIN_LOAD_LIMIT, SLOW_ZONE


class SafetyError(RuntimeError):
    """A motion command was refused because it breaks a configured limit."""


class Safety:
    """The configured limits of one protocol run, bound to its rig."""

    def __init__(self, cfg: SafetyConfig, rig: Rig) -> None:
        self.cfg = cfg
        self.rig = rig
        self.lo_mm = np.asarray(cfg.platform_min_mm, float)
        self.hi_mm = np.asarray(cfg.platform_max_mm, float)
        # While lifting off (after a trip the load is still above the limit) moving away from the
        # skin is what makes it safe, so the guards let that one kind of move run.
        self.unloading = False
        self.platform_speed_mm_s = 0.0  # speed of the platform move in progress (0: the stage stands)
        # The limits are ceilings: checked on every sample whatever stop condition is latched.
        if rig.ft is not None:
            rig.add_guard(self._normal_force_guard, ceiling=True)
            rig.add_guard(self._slow_zone_guard)
        else:  # no F/T sensor (the grip rig): the skin itself guards the load, on every frame
            self._skin_full_scale = 2 * 256 * 4095
            rig.add_guard(self._skin_load_guard, "skin", ceiling=True)

    # ---- per-sample guard -----------------------------------------------------------------
    def _normal_force_guard(self, sample: Wrench) -> str | None:
        fz_n = float(sample.force_n[2])
        if fz_n > self.cfg.max_normal_force_n and not self.unloading:
            return f"{FORCE_LIMIT}: Fz={fz_n:.3f} N exceeds {self.cfg.max_normal_force_n} N"
        return None

    def _slow_zone_guard(self, sample: Wrench) -> str | None:
        """Near the limit a fast move is stopped so it can go on slowly: the force rises while the
        stage brakes, and at the slow speed that overshoot past the limit is ~(v_slow/v)^2 smaller."""
        fz_n = float(sample.force_n[2])
        zone_n = self.cfg.slow_zone_fraction * self.cfg.max_normal_force_n
        if fz_n > zone_n and not self.unloading and self.platform_speed_mm_s > self.cfg.slow_zone_speed_mm_s:
            return f"{SLOW_ZONE}: Fz={fz_n:.3f} N above {zone_n:.2f} N"
        return None

    def _skin_load_guard(self, frame) -> str | None:
        load = (int(frame.superficial.sum(dtype="int64")) + int(frame.deep.sum(dtype="int64"))) / self._skin_full_scale
        if load > self.cfg.max_skin_load_fraction:
            return (f"{SKIN_LOAD_LIMIT}: both layers at {100 * load:.1f} % of full scale exceed "
                    f"safety.max_skin_load_fraction={self.cfg.max_skin_load_fraction}")
        return None

    # ---- command checks -------------------------------------------------------------------
    def check_platform_move(self, target_mm: np.ndarray, speed_mm_s: float) -> None:
        target_mm = np.asarray(target_mm, float)
        if not np.all(np.isfinite(target_mm)) or np.any(target_mm < self.lo_mm) or np.any(target_mm > self.hi_mm):
            raise SafetyError(f"platform target {np.round(target_mm, 3).tolist()} mm is outside the workspace "
                              f"{self.lo_mm.tolist()}..{self.hi_mm.tolist()} (safety.platform_min_mm/max_mm)")
        if not 0 < speed_mm_s <= self.cfg.max_platform_speed_mm_s:
            raise SafetyError(f"platform speed {speed_mm_s} mm/s is outside (0, "
                              f"safety.max_platform_speed_mm_s={self.cfg.max_platform_speed_mm_s}]")
        if self.rig.tripped is not None and not self.unloading:
            raise SafetyError(f"guard tripped ({self.rig.tripped}); acknowledge it before moving again")
        self.platform_speed_mm_s = float(speed_mm_s)

    def check_arm_move(self, pose6: np.ndarray, start_pose6: np.ndarray, speed_mm_s: float,
                       angular_speed_deg_s: float | None) -> None:
        offset_mm = 1000.0 * float(np.linalg.norm(np.asarray(pose6[:3]) - np.asarray(start_pose6[:3])))
        if offset_mm > self.cfg.arm_max_offset_mm + 1e-6:
            raise SafetyError(f"arm target {offset_mm:.2f} mm from the start pose exceeds "
                              f"safety.arm_max_offset_mm={self.cfg.arm_max_offset_mm}")
        rel = Rotation.from_rotvec(pose6[3:]) * Rotation.from_rotvec(start_pose6[3:]).inv()
        angle_deg = float(np.degrees(rel.magnitude()))
        if angle_deg > self.cfg.arm_max_rotation_deg + 1e-6:
            raise SafetyError(f"arm target rotated {angle_deg:.2f}° from the start pose exceeds "
                              f"safety.arm_max_rotation_deg={self.cfg.arm_max_rotation_deg}")
        if not 0 < speed_mm_s <= self.cfg.max_arm_speed_mm_s:
            raise SafetyError(f"arm speed {speed_mm_s} mm/s is outside (0, "
                              f"safety.max_arm_speed_mm_s={self.cfg.max_arm_speed_mm_s}]")
        if angular_speed_deg_s is not None and not 0 < angular_speed_deg_s <= self.cfg.max_arm_angular_speed_deg_s:
            raise SafetyError(f"arm angular speed {angular_speed_deg_s} °/s is outside (0, "
                              f"safety.max_arm_angular_speed_deg_s={self.cfg.max_arm_angular_speed_deg_s}]")

    def check_gripper_move(self, opening_mm: float, speed_mm_s: float, min_opening_mm: float) -> None:
        if not np.isfinite(opening_mm) or opening_mm < min_opening_mm:
            raise SafetyError(f"gripper opening {opening_mm:.2f} mm is below the minimum {min_opening_mm} mm "
                              "(approach.min_opening_mm); lower grip_depth")
        if not 0 < speed_mm_s <= self.cfg.max_gripper_speed_mm_s:
            raise SafetyError(f"gripper speed {speed_mm_s} mm/s is outside (0, "
                              f"safety.max_gripper_speed_mm_s={self.cfg.max_gripper_speed_mm_s}]")

    def check_grip_depth(self, grip_depth_mm: float) -> None:
        if not 0 < grip_depth_mm <= self.cfg.max_grip_depth_mm:
            raise SafetyError(f"grip depth {grip_depth_mm} mm is outside (0, "
                              f"safety.max_grip_depth_mm={self.cfg.max_grip_depth_mm}]")
