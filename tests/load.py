"""A CPU load beside a test: busy processes, twice the core count, stopped on exit (or after
max_s at the latest, so a test that hangs never leaves them spinning)."""

from __future__ import annotations

import multiprocessing as mp
import os
import time


def _spin(stop, max_s: float) -> None:
    deadline = time.monotonic() + max_s
    x = 0
    while not stop.is_set() and time.monotonic() < deadline:
        for _ in range(20_000):
            x = (x * 1103515245 + 12345) & 0x7FFFFFFF


class CpuLoad:
    """with CpuLoad(): ...  runs `per_core` x os.cpu_count() busy processes inside the block."""

    def __init__(self, per_core: int = 2, max_s: float = 120.0) -> None:
        self.n = per_core * (os.cpu_count() or 1)
        self.max_s = max_s
        self._ctx = mp.get_context("spawn")  # no copy of the test's threads or open ports
        self._stop = self._ctx.Event()
        self._procs: list = []

    def __enter__(self) -> CpuLoad:
        self._procs = [self._ctx.Process(target=_spin, args=(self._stop, self.max_s), daemon=True)
                       for _ in range(self.n)]
        for p in self._procs:
            p.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        for p in self._procs:
            p.join(timeout=5.0)
            if p.is_alive():
                p.kill()
                p.join()
        self._procs = []

    @property
    def running(self) -> int:
        return sum(p.is_alive() for p in self._procs)
