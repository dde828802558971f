"""Simulated three-axis platform: straight moves under speed/acceleration limits, position stream."""

from __future__ import annotations

import numpy as np

from hardware.interfaces import Platform
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
        self._require_connected()
        self.scene.command_move(target_mm, speed_mm_s)

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
