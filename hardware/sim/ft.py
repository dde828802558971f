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
    """Samples are taken at their own times between mechanical steps, each holding the last step
    before it, so a guard acts at the sample's time. Their schedule and timestamps (device time,
    host receive time) are drawn once per world advance; each stretch of steps the world runs
    then takes the samples that fall under it, readings computed together.

    on_sample: called with every acquired Wrench at its acquisition time (the rig's check_guards).
    probe: the same check without acting (the rig's guard_reason): the world runs stretches of
    steps ahead, and a sample the probe flags makes it rewind to that sample's step first.
    """

    def __init__(self, world: World, cfg: ForceTorqueConfig, rng: np.random.Generator,
                 on_sample: Callable[[Wrench], object] | None = None,
                 probe: Callable[[Wrench], str | None] | None = None) -> None:
        super().__init__()
        if (on_sample is None) != (probe is None):
            raise ValueError("SimForceTorque: give both on_sample and probe (the check and its side-effect-free "
                             "twin), or neither")
        self.world = world
        self.cfg = cfg
        self.synth = FTSynth(cfg, rng)
        self.on_sample, self.probe = on_sample, probe
        self.tare_offset = np.zeros(6)
        self._recent_raw: deque = deque(maxlen=32)  # raw readings (k, 6) of the last takes
        self.stream = world.new_stream("ft", cfg.clock, 1.0 / cfg.rate_hz)
        # This advance's samples: true times (N,), seq, device and host ns (lists), next index.
        self._sched: tuple[np.ndarray, list, list, list] = (np.empty(0), [], [], [])
        self._next = 0
        world.add_sampler(self._sample, prepare=self._prepare)
        world.on_trial(lambda w: self.synth.reseed(w.rng("ft.noise")))

    def _prepare(self, world: World, t_end_s: float) -> None:
        t_s = self.stream.due_times(t_end_s)
        self._next = 0
        if len(t_s) == 0 or not self.stream.enabled:
            self._sched = (np.empty(0), [], [], [])
            return
        seq, dev_ns, host_ns = self.stream.stamp(t_s)
        self._sched = (t_s, seq.tolist(), dev_ns.tolist(), host_ns.tolist())

    def _sample(self, world: World, t_k: np.ndarray, recs: np.ndarray, t_to_s: float, act: bool) -> int | None:
        times, seq, dev_ns, host_ns = self._sched
        k0 = self._next
        if k0 >= len(times) or times[k0] > t_to_s:
            return None
        k1 = int(np.searchsorted(times, t_to_s, side="right"))
        held = np.searchsorted(t_k, times[k0:k1], side="left") - 1  # the last step before each sample
        np.maximum(held, 0, out=held)
        raw = self.synth.readings(recs, held)
        wrench = raw - self.tare_offset
        n = k1 - k0
        samples = [Wrench(w[:3], w[3:], q, d, h) for w, q, d, h in zip(wrench, seq[k0:k1], dev_ns[k0:k1],
                                                                       host_ns[k0:k1], strict=True)]
        if not act and self.probe is not None:
            probe = self.probe
            for i, sample in enumerate(samples):
                if probe(sample):  # taken again (with the guard acting) once the world has rewound
                    n, trip = i, int(held[i])
                    break
            else:
                trip = None
        else:
            trip = None
        self.synth.consume(n)
        self._next = k0 + n
        if n:
            self._recent_raw.append(raw[:n])
            self.stream.push_many(host_ns[k0:k0 + n], samples[:n])
            if act and self.on_sample is not None:
                for sample in samples:
                    self.on_sample(sample)
        return trip

    def read_available(self) -> list[Wrench]:
        return self._drain()

    def tare(self) -> None:
        """Zero the reading with the mean of the last 32 raw samples (the sensor should be unloaded)."""
        self._require_connected()
        if not self._recent_raw:
            self.world.advance(32.0 / self.cfg.rate_hz)  # the Net F/T averages samples it has yet to take
        self.tare_offset = np.mean(np.concatenate(self._recent_raw)[-32:], axis=0)
