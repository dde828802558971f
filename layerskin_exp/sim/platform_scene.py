"""The force-calibration platform: a three-axis stage pressing a hemispherical indenter into the skin.

The stage carries the indenter; its position is the indenter tip in the skin frame (mm), z the
height of the tip above the undeformed cover. The skin lies on the F/T sensor on a rigid table.
"""

from __future__ import annotations

import numpy as np

from layerskin_exp.sim.kinematics import LimitedMotion
from layerskin_exp.sim.rig_config import PlatformConfig


class PlatformScene:
    indenter = "hemisphere"
    support_stiffness_n_per_mm = None  # rigid table under the F/T sensor
    snapshot_names = ("x_mm", "y_mm", "z_mm")

    def __init__(self, cfg: PlatformConfig) -> None:
        self.cfg = cfg
        self.stage = LimitedMotion(list(cfg.home_mm), cfg.max_accel_mm_s2)

    def command_move(self, target_mm: np.ndarray, speed_mm_s: float) -> None:
        """Start a straight move (the device twin has checked it against the stage's range)."""
        self.stage.command(np.asarray(target_mm, float).reshape(3).tolist(), float(speed_mm_s))

    # ---- world stepping (see World.advance for the protocol) -------------------------------
    def plan(self, m: int, dt_s: float):
        """The next m steps without changing the scene: indenter tip (m, 3) mm, yaw (m,) rad,
        snapshots (m, 3) and a token for commit()."""
        states = self.stage.plan(m, dt_s)
        xyz = self.stage.positions(states)
        return xyz, np.zeros(m), xyz, states

    def commit(self, token, k: int) -> None:
        self.stage.commit(token, k)

    def first_reaction(self, token, recs: np.ndarray) -> int | None:
        """Nothing reacts to the load here: the stage is stiff and position controlled."""
        return None

    def after_step(self, fz_n: float) -> bool:
        """Nothing reacts to the load here (returns whether the scene changed)."""
        return False

    def indenter_pose(self) -> tuple[list[float], float]:
        """Indenter tip (x, y, z) mm in the skin frame and its yaw (rad)."""
        return self.stage.position, 0.0

    def snapshot(self) -> np.ndarray:
        return np.asarray(self.stage.position, float)

    def stop_all(self) -> None:
        self.stage.stop()
