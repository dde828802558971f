"""Simulated two-layer readout board: frame pairs every ~2.36 ms with scan-period jitter."""

from __future__ import annotations

import numpy as np

from hardware.interfaces import SkinReader
from hardware.sim.stream_device import SimStreamMixin
from layerskin_exp.sim.rig_config import SkinReaderConfig
from layerskin_exp.sim.world import World
from layerskin_exp.types import TwoLayerFrame


class SimSkinReader(SimStreamMixin, SkinReader):
    """Frames come from the skin model, batched per world advance."""

    def __init__(self, world: World, cfg: SkinReaderConfig) -> None:
        super().__init__()
        self.world = world
        self.cfg = cfg
        period_s = world.skin_cfg.frame_period_ms * 1e-3
        self.stream = world.new_stream("skin", cfg.clock, period_s, cfg.period_jitter_ms * 1e-3)
        # on_frames(frames) is called with each batch as it is acquired (the rig's skin guards)
        self.on_frames = None
        world.add_producer(self.stream, self._produce)

    def _produce(self, world: World, t_s: np.ndarray, idx: np.ndarray) -> None:
        sup, deep = world.skin_model.frames_of_steps(world.records(idx), t_s)
        seq, dev_ns, host_ns = (a.tolist() for a in self.stream.stamp(t_s))
        frames = [TwoLayerFrame(*rec) for rec in zip(sup, deep, seq, dev_ns, host_ns, strict=True)]
        self.stream.push_many(host_ns, frames)
        if self.on_frames is not None:
            self.on_frames(frames)

    def read_available(self) -> list[TwoLayerFrame]:
        return self._drain()

    def calibration(self) -> dict:
        s = self.world.skin_cfg
        cal = {"board_id": self.cfg.board_id, "backend": "sim", "n_taxels": s.n_taxels, "pitch_mm": s.pitch_mm,
               "electrode_mm": s.electrode_mm, "adc_bits": s.adc_bits, "frame_period_ms": s.frame_period_ms,
               "layers": list(s.layers)}
        model_cal = getattr(self.world.skin_model, "calibration", None)
        if model_cal is not None:
            cal["model"] = model_cal()
        return cal
