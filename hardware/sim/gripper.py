"""Simulated Robotiq Hand-E: jaw moves within the stroke and speed range, state polled at rate_hz."""

from __future__ import annotations

import numpy as np

from hardware.interfaces import DeviceError, Gripper
from hardware.sim.stream_device import SimStreamMixin
from layerskin_exp.sim.grip_scene import GripScene
from layerskin_exp.sim.rig_config import GripperConfig
from layerskin_exp.sim.world import World
from layerskin_exp.types import GripperState


class SimGripper(SimStreamMixin, Gripper):
    def __init__(self, world: World, scene: GripScene, cfg: GripperConfig) -> None:
        super().__init__()
        self.world, self.scene, self.cfg = world, scene, cfg
        self.stream = world.new_stream("gripper", cfg.clock, 1.0 / cfg.rate_hz)
        world.add_producer(self.stream, self._produce)

    def _produce(self, world: World, t_s: np.ndarray, idx: np.ndarray) -> None:
        snap = world.snapshots(idx)
        res = self.cfg.position_resolution_mm
        opening = np.round(snap[:, 12] / res) * res if res > 0 else snap[:, 12]
        sc = self.scene
        speed = int(round(255 * (sc.grip_speed_mm_s - self.cfg.min_speed_mm_s)
                          / (self.cfg.max_speed_mm_s - self.cfg.min_speed_mm_s)))
        force = int(round(255 * sc.force_pct / 100.0))
        seq, dev_ns, host_ns = (a.tolist() for a in self.stream.stamp(t_s))
        self.stream.push_many(host_ns, [GripperState(o, sc.requested_mm, speed, force, st > 0.5, 0, d, h, k)
                                        for o, st, d, h, k in zip(opening.tolist(), snap[:, 13].tolist(), dev_ns,
                                                                  host_ns, seq, strict=True)])

    def move(self, opening_mm: float, speed_mm_s: float, force_pct: float) -> None:
        """Refuse what the Hand-E would (outside its stroke, speed range or force range)."""
        self._require_connected()
        cfg = self.cfg
        if not (np.isfinite(opening_mm) and 0 <= opening_mm <= cfg.stroke_mm):
            raise DeviceError(f"gripper: opening {opening_mm!r} mm is outside the stroke 0..{cfg.stroke_mm} mm")
        if not (np.isfinite(speed_mm_s) and cfg.min_speed_mm_s <= speed_mm_s <= cfg.max_speed_mm_s):
            raise DeviceError(f"gripper: speed {speed_mm_s!r} mm/s is outside the Hand-E's "
                              f"{cfg.min_speed_mm_s}..{cfg.max_speed_mm_s} mm/s")
        if not (np.isfinite(force_pct) and 0 <= force_pct <= 100):
            raise DeviceError(f"gripper: force {force_pct!r} % is outside 0..100 %")
        self.scene.command_gripper(opening_mm, speed_mm_s, force_pct)

    def stop(self) -> None:
        self._require_connected()
        self.scene.stop_gripper()

    def is_moving(self) -> bool:
        self._require_connected()
        return self.scene.jaw.moving

    def read_available(self) -> list[GripperState]:
        return self._drain()
