"""Simulated Mini40 under the skin: one sample per F/T period, each checked by the rig's guards."""

from __future__ import annotations

from bisect import bisect_right
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
    Their schedule and timestamps (device time, host receive time) are drawn once per world
    advance; each mechanical step then reads the samples that fall under it.

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
        # This advance's samples: true times, seq, device and host ns (lists), next index.
        self._sched: tuple[list, list, list, list] = ([], [], [], [])
        self._next = 0
        world.add_per_tick(self._per_tick, prepare=self._prepare)
        world.on_trial(lambda w: self.synth.reseed(w.rng("ft.noise")))

    def _prepare(self, world: World, t_end_s: float) -> None:
        t_s = self.stream.due_times(t_end_s)
        self._next = 0
        if len(t_s) == 0 or not self.stream.enabled:
            self._sched = ([], [], [], [])
            return
        seq, dev_ns, host_ns = self.stream.stamp(t_s)
        self._sched = (t_s.tolist(), seq.tolist(), dev_ns.tolist(), host_ns.tolist())

    def _per_tick(self, world: World, t_from_s: float, t_to_s: float) -> None:
        times, seq, dev_ns, host_ns = self._sched
        k0 = self._next
        if k0 >= len(times) or times[k0] > t_to_s:
            return
        k1 = bisect_right(times, t_to_s, lo=k0)
        self._next = k1
        st = world.state
        synth = self.synth
        load = synth.load(st.force_n, st.torque_z_nmm, st.contact_xy_mm)  # the state holds for these
        push, on_sample, recent, tare = self.stream.push, self.on_sample, self._recent_raw, self.tare_offset
        for i in range(k0, k1):
            raw = synth.reading_of_load(load)
            recent.append(raw)
            w = raw - tare
            h = host_ns[i]
            sample = Wrench(w[:3], w[3:], seq[i], dev_ns[i], h)
            push(h, sample)
            if on_sample is not None:
                on_sample(sample)

    def read_available(self) -> list[Wrench]:
        return self._drain()

    def tare(self) -> None:
        """Zero the reading with the mean of the last 32 raw samples (the sensor should be unloaded)."""
        self._require_connected()
        if not self._recent_raw:
            self.world.advance(32.0 / self.cfg.rate_hz)  # the Net F/T averages samples it has yet to take
        self.tare_offset = np.mean(np.asarray(self._recent_raw), axis=0)
