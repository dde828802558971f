"""Time in the simulated world: one true timeline, the host's monotonic clock, and each device's clock.

The world runs on true time t (s, from world start). The host clock reads t plus a fixed start
value. Every device keeps its own oscillator: device time = offset + (1 + drift) * t, read with a
small timestamp jitter; what it sends reaches the host after a one-sided transport delay, first
in first out (a serial line or a TCP stream never reorders).
"""

from __future__ import annotations

import math
import zlib

import numpy as np

from layerskin_exp.sim.rig_config import DeviceClockConfig


def device_rng(seed: int, name: str) -> np.random.Generator:
    """A generator for one named part of the world, reproducible from the world seed alone."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, zlib.crc32(name.encode())])


def lognormal_unit_mean(rng: np.random.Generator, cv: float, size=None):
    """Mean-one lognormal draw(s) with coefficient of variation cv (exactly 1 where cv is 0)."""
    if cv <= 0:
        return 1.0 if size is None else np.ones(size)
    sigma = math.sqrt(math.log1p(cv * cv))
    return np.exp(rng.normal(-0.5 * sigma * sigma, sigma, size=size))


class BlockDraws:
    """Standard normal and exponential draws for many small requests, taken from blocks
    (one generator call per block instead of one per request; reproducible from the generator)."""

    BLOCK = 4096

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self._normal, self._exp = np.empty(0), np.empty(0)
        self._i = self._j = 0

    def normal(self, n: int) -> np.ndarray:
        if self._i + n > len(self._normal):
            self._normal = np.concatenate((self._normal[self._i:], self.rng.standard_normal(max(self.BLOCK, n))))
            self._i = 0
        self._i += n
        return self._normal[self._i - n:self._i]

    def exponential(self, n: int) -> np.ndarray:
        if self._j + n > len(self._exp):
            self._exp = np.concatenate((self._exp[self._j:], self.rng.standard_exponential(max(self.BLOCK, n))))
            self._j = 0
        self._j += n
        return self._exp[self._j - n:self._j]


class DeviceClock:
    """One device's oscillator and link: device timestamps and host receive times for sample times."""

    def __init__(self, cfg: DeviceClockConfig, rng: np.random.Generator, host_start_ns: int) -> None:
        self.offset_ns = int(rng.uniform(0.0, cfg.offset_max_s) * 1e9)
        self.drift = float(rng.normal(0.0, cfg.drift_ppm_std)) * 1e-6
        self.jitter_ns = cfg.timestamp_jitter_us * 1e3
        self.delay_min_ns = cfg.delay_min_ms * 1e6
        self.delay_extra_ns = cfg.delay_mean_extra_ms * 1e6
        self.host_start_ns = host_start_ns
        self._draws = BlockDraws(rng)
        self._last_host_ns = -1

    def reseed(self, rng: np.random.Generator) -> None:
        """New jitter and delay draws from rng; the oscillator (offset, drift) stays."""
        self._draws = BlockDraws(rng)

    def device_ns(self, t_s: np.ndarray) -> np.ndarray:
        """(N,) device timestamps (int64 ns) of events at true times t_s (N,)."""
        t_s = np.asarray(t_s, dtype=float)
        jitter = self._draws.normal(t_s.size).reshape(t_s.shape) * self.jitter_ns if self.jitter_ns > 0 else 0.0
        return (self.offset_ns + t_s * 1e9 * (1.0 + self.drift) + jitter).astype(np.int64)

    def true_s_of_device(self, device_ns: np.ndarray) -> np.ndarray:
        """Inverse of the oscillator (no jitter): true time (s) at which the device clock reads device_ns."""
        return (np.asarray(device_ns, dtype=float) - self.offset_ns) / (1e9 * (1.0 + self.drift))

    def host_receive_ns(self, t_s: np.ndarray) -> np.ndarray:
        """(N,) host receive times (int64 ns) of samples sent at true times t_s (N,), kept FIFO."""
        t_s = np.asarray(t_s, dtype=float)
        delay = self.delay_min_ns
        if self.delay_extra_ns > 0:
            delay = delay + self._draws.exponential(t_s.size).reshape(t_s.shape) * self.delay_extra_ns
        host = (self.host_start_ns + t_s * 1e9 + delay).astype(np.int64)
        if host.size:
            host = np.maximum.accumulate(np.maximum(host, self._last_host_ns))
            self._last_host_ns = int(host[-1])
        return host
