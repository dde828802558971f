"""Simulated three-axis platform: straight moves under speed/acceleration limits, position stream."""

from __future__ import annotations

import numpy as np

from hardware.interfaces import DeviceError, Platform
from hardware.sim.stream_device import SimStreamMixin
from layerskin_exp.sim.platform_scene import PlatformScene
from layerskin_exp.sim.rig_config import PlatformConfig
from layerskin_exp.sim.world import World
from layerskin_exp.types import StagePosition


class SimPlatform(SimStreamMixin, Platform):
    def __init__(self, world: World, scene: PlatformScene, cfg: PlatformConfig) -> None:
        super().__init__()
        self.world, self.scene, self.cfg = world, scene, cfg
        self.stream = world.new_stream("platform", cfg.clock, 1.0 / cfg.rate_hz)
        world.add_producer(self.stream, self._produce)

    def _produce(self, world: World, t_s: np.ndarray, idx: np.ndarray) -> None:
        pos = world.snapshots(idx)[:, :3]
        res = self.cfg.encoder_resolution_mm
        if res > 0:
            pos = np.round(pos / res) * res
        seq, dev_ns, host_ns = (a.tolist() for a in self.stream.stamp(t_s))
        pos = pos.copy()  # records own their data (snapshots are views of the world's buffer)
        self.stream.push_many(host_ns, [StagePosition(*rec) for rec in zip(pos, seq, dev_ns, host_ns, strict=True)])

    def move_to(self, target_mm: np.ndarray, speed_mm_s: float) -> None:
        """Refuse what the stage's controller would (outside its travel, beyond its speed)."""
        self._require_connected()
        target = np.asarray(target_mm, dtype=float).reshape(-1)
        lo, hi = np.asarray(self.cfg.workspace_min_mm, float), np.asarray(self.cfg.workspace_max_mm, float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise DeviceError(f"platform: target {target_mm!r} must be three finite values (x, y, z mm)")
        if np.any(target < lo) or np.any(target > hi):
            raise DeviceError(f"platform: target {np.round(target, 4).tolist()} mm is outside the stage's travel "
                              f"{lo.tolist()}..{hi.tolist()} mm; command a reachable point")
        if not (np.isfinite(speed_mm_s) and 0 < speed_mm_s <= self.cfg.max_speed_mm_s):
            raise DeviceError(f"platform: speed {speed_mm_s!r} mm/s is outside (0, {self.cfg.max_speed_mm_s}] "
                              "mm/s (sim.rig.platform.max_speed_mm_s)")
        self.scene.command_move(target, float(speed_mm_s))

    def stop(self) -> None:
        self._require_connected()
        self.scene.stage.stop()

    def is_moving(self) -> bool:
        self._require_connected()
        return self.scene.stage.moving

    def read_available(self) -> list[StagePosition]:
        return self._drain()

    def position_mm(self) -> np.ndarray:
        """(3,) the stage's current position (sim only; protocols read the stream)."""
        return np.asarray(self.scene.stage.position, float)
