"""One device stream in the simulated world: when it samples, and when the host gets each sample.

A stream samples on its own oscillator (a nominal period in device time, optionally with
period jitter), stamps each sample with its device clock, and queues it until the host
receives it (device clock's transport delay). The device twin drains what the host has
received by a given host time.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from layerskin_exp.sim.clocks import BlockDraws, DeviceClock

_EMPTY = np.empty(0)


class Stream:
    """Sample schedule and receive queue of one device stream.

    period_s: nominal sample period on the device's clock; period_jitter_s: std of each
    interval (true time). Samples queue as (host_receive_ns, record).
    """

    def __init__(self, name: str, clock: DeviceClock, period_s: float, rng: np.random.Generator,
                 period_jitter_s: float = 0.0, start_s: float = 0.0) -> None:
        self.name = name
        self.clock = clock
        self.period_true_s = period_s / (1.0 + clock.drift)  # a fast oscillator samples early
        self.period_jitter_s = period_jitter_s
        self.rng = rng  # (the setter keeps block draws from it)
        self.next_t_s = start_s + float(rng.uniform(0.0, self.period_true_s))
        self.enabled = False
        self.seq = 0
        self._queue: deque = deque()

    @property
    def rng(self) -> np.random.Generator:
        return self._draws.rng

    @rng.setter
    def rng(self, rng: np.random.Generator) -> None:
        self._draws = BlockDraws(rng)

    def due_times(self, t_end_s: float) -> np.ndarray:
        """(N,) true times of the samples up to and including t_end_s; advances the schedule."""
        t0, p = self.next_t_s, self.period_true_s
        if t0 > t_end_s:
            return _EMPTY
        if self.period_jitter_s <= 0:
            k = int((t_end_s - t0) / p) + 1  # samples t0 + i p <= t_end_s (settled exactly below)
            while k > 0 and t0 + (k - 1) * p > t_end_s:
                k -= 1
            while t0 + k * p <= t_end_s:
                k += 1
            self.next_t_s = t0 + k * p
            return t0 + np.arange(k) * p
        n = int((t_end_s - t0) / p) + 2
        # Interval jitter, clipped so the scan never runs backwards.
        steps = np.maximum(p + self._draws.normal(n) * self.period_jitter_s, 0.2 * p)
        times = t0 + np.concatenate(([0.0], np.cumsum(steps[:-1])))
        while times[-1] <= t_end_s:  # jitter made the intervals short: extend
            times = np.concatenate((times, times[-1] + np.cumsum(np.full(n, p))))
        k = int(np.searchsorted(times, t_end_s, side="right"))
        self.next_t_s = float(times[k])
        return times[:k]

    def stamp(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sequence numbers, device times and host receive times (int64 ns) for sample times t_s (N,)."""
        n = len(t_s)
        seq = np.arange(self.seq, self.seq + n)
        self.seq += n
        return (seq, *self.clock.stamp(t_s))

    def push(self, host_ns: int, record) -> None:
        self._queue.append((host_ns, record))

    def push_many(self, host_ns: list[int], records: list) -> None:
        """Queue records in order with their host receive times (host_ns nondecreasing)."""
        self._queue.extend(zip(host_ns, records, strict=True))

    def pop_received(self, host_now_ns: int) -> list:
        """Records the host has received by host_now_ns, oldest first."""
        q = self._queue
        out = []
        while q and q[0][0] <= host_now_ns:
            out.append(q.popleft()[1])
        return out

    def clear(self) -> None:
        self._queue.clear()
