"""The virtual clock: the host's monotonic time in the simulated world; sleeping advances the world."""

from __future__ import annotations

import math

from hardware.interfaces import Clock
from layerskin_exp.sim.world import World


class SimClock(Clock):
    """Host clock of the simulated world. sleep(dt) runs dt seconds of world time at once."""

    def __init__(self, world: World) -> None:
        self.world = world

    def now_ns(self) -> int:
        return self.world.host_now_ns()

    def sleep(self, dt_s: float) -> None:
        if not (math.isfinite(dt_s) and dt_s >= 0):
            raise ValueError(f"sleep({dt_s!r}): the duration must be a finite number of seconds >= 0")
        self.world.advance(dt_s)

    @property
    def is_virtual(self) -> bool:
        return True
