"""Simulated Mini40 under the skin: one sample per F/T period, each checked by the rig's guards."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np

from hardware.interfaces import ForceTorqueSensor
from hardware.sim.stream_device import SimStreamMixin
from layerskin_exp.sim.ft_sensor import FTSynth
from layerskin_exp.sim.rig_config import ForceTorqueConfig
from layerskin_exp.sim.world import World
from layerskin_exp.types import Wrench


class SimForceTorque(SimStreamMixin, ForceTorqueSensor):
    """Samples are generated step by step (not batched) so a guard acts at the sample's time.

    on_sample: called with every acquired Wrench at its acquisition time (the rig's check_guards).
    """

    def __init__(self, world: World, cfg: ForceTorqueConfig, rng: np.random.Generator,
                 on_sample: Callable[[Wrench], object] | None = None) -> None:
        super().__init__()
        self.world = world
        self.cfg = cfg
        self.synth = FTSynth(cfg, rng)
        self.on_sample = on_sample
        self.tare_offset = np.zeros(6)
        self._recent_raw: deque = deque(maxlen=32)
        self.stream = world.new_stream("ft", cfg.clock, 1.0 / cfg.rate_hz)
        world.add_per_tick(self._per_tick)
        world.on_trial(lambda w: self.synth.reseed(w.rng("ft.noise")))

    def _per_tick(self, world: World, t_from_s: float, t_to_s: float) -> None:
        t_s = self.stream.due_times(t_to_s)
        if len(t_s) == 0 or not self.stream.enabled:
            return
        st = world.state
        seq, dev_ns, host_ns = self.stream.stamp(t_s)
        for i in range(len(t_s)):
            raw = self.synth.reading(st.force_n, st.torque_z_nmm, st.contact_xy_mm)
            self._recent_raw.append(raw)
            w = raw - self.tare_offset
            sample = Wrench(w[:3], w[3:], int(seq[i]), int(dev_ns[i]), int(host_ns[i]))
            self.stream.push(int(host_ns[i]), sample)
            if self.on_sample is not None:
                self.on_sample(sample)

    def read_available(self) -> list[Wrench]:
        return self._drain()

    def tare(self) -> None:
        """Zero the reading with the mean of the last 32 raw samples (the sensor should be unloaded)."""
        self._require_connected()
        if not self._recent_raw:
            self.world.advance(32.0 / self.cfg.rate_hz)  # the Net F/T averages samples it has yet to take
        self.tare_offset = np.mean(np.asarray(self._recent_raw), axis=0)
