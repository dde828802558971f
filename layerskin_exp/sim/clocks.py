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
from numba import njit

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

    def true_s_of_device(self, device_ns: np.ndarray) -> np.ndarray:
        """Inverse of the oscillator (no jitter): true time (s) at which the device clock reads device_ns."""
        return (np.asarray(device_ns, dtype=float) - self.offset_ns) / (1e9 * (1.0 + self.drift))

    def stamp(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Device timestamps and host receive times (int64 ns, (N,) each) of samples taken at
        true times t_s (N,): device time with its timestamp jitter; host time after the one-sided
        transport delay, first in first out."""
        t_s = np.ascontiguousarray(t_s, dtype=float)
        n = len(t_s)
        z = self._draws.normal(n) if self.jitter_ns > 0 else _NONE
        e = self._draws.exponential(n) if self.delay_extra_ns > 0 else _NONE
        dev, host = np.empty(n, np.int64), np.empty(n, np.int64)
        self._last_host_ns = _stamp(t_s, float(self.offset_ns), 1e9 * (1.0 + self.drift), self.jitter_ns, z,
                                    float(self.host_start_ns), self.delay_min_ns, self.delay_extra_ns, e,
                                    self._last_host_ns, dev, host)
        return dev, host


_NONE = np.zeros(0)


@njit(cache=True, nogil=True)
def _stamp(t_s, offset_ns, ns_per_s, jitter_ns, z, host_start_ns, delay_min_ns, delay_extra_ns, e, last_host,
           dev, host):
    for i in range(t_s.shape[0]):
        d = offset_ns + t_s[i] * ns_per_s
        if z.shape[0]:
            d += z[i] * jitter_ns
        dev[i] = np.int64(d)
        h = host_start_ns + t_s[i] * 1e9 + delay_min_ns
        if e.shape[0]:
            h += e[i] * delay_extra_ns
        last_host = max(np.int64(h), last_host)  # FIFO: never before the previous sample
        host[i] = last_host
    return last_host
