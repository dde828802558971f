"""The simulated world at wall-clock pace: what the loopback emulators are backed by.

On `hardware=sim` the protocol's clock *is* the world's clock (sleeping advances it). The
emulators of `hardware=loopback` instead serve real drivers that read the host's monotonic
clock, so here a pacer thread advances the same world to keep up with wall time, and every
emulator reaches the simulated devices (the twins of `hardware/sim/`) under one lock.

World host time and the host's monotonic clock share an origin here: world host time
`host_start_ns + t_s * 1e9` is kept within one pacer period of `time.monotonic_ns()` (minus
the offset taken at start), so records drained from a twin can be handed out when their
receive time comes.

Each emulator claims the twins whose streams it drains (`claim`); after every advance the pacer
discards what the host has received from every other twin, so the streams of devices no
emulator serves (a standalone emulator serves one) do not queue without bound.

    rt = RealtimeWorld.from_config(cfg.sim, cfg.skin, "platform")
    with rt:                                   # connects the twins, starts the pacer
        with rt.lock:
            frames = rt.rig.skin.read_available()
"""

from __future__ import annotations

import threading
import time

from hardware.rig import Rig

WARM_UP_S = 0.01
# The most world time one advance takes under the lock: a world that fell behind (a busy host, a
# slow camera frame) catches up in steps of this, so the emulators reach the twins between them
# instead of waiting out one long catch-up (0.8 s, measured while a run shut down).
MAX_ADVANCE_S = 0.02
STREAM_TWINS = ("skin", "ft", "platform", "arm", "gripper", "camera")  # rig attributes with a stream


class RealtimeWorld:
    """A simulated rig (world + twins) advanced in real time by a background thread.

    rig: the simulated Rig (`build_sim_rig`); its clock is virtual and must only be advanced by
    the pacer. period_s: how often the pacer advances the world (a stream's samples reach the
    emulators in bursts of at most this length). Use `lock` around every access to the twins.
    """

    def __init__(self, rig: Rig, period_s: float = 0.002) -> None:
        if rig.backend != "sim":
            raise ValueError(f"RealtimeWorld needs a simulated rig, got backend {rig.backend!r}")
        if not period_s > 0:
            raise ValueError(f"period_s={period_s!r}: must be > 0 s")
        self.rig = rig
        rig.fresh_trials = False  # one world runs on at wall-clock pace: it cannot go back to a first state
        self.world = rig.extras["world"]
        self.period_s = float(period_s)
        self.lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._origin_ns = 0  # monotonic time at world time 0
        self.lag_s = 0.0  # worst lag of the world behind wall time seen by the pacer
        self.error: BaseException | None = None  # what ended the pacer, if it failed
        self._claims: dict[int, tuple[str, ...]] = {}  # id(emulator) -> twins it drains
        self._unclaimed: tuple = self._twins_without({})

    @classmethod
    def from_config(cls, sim_cfg, skin_cfg, setup: str, period_s: float = 0.002) -> RealtimeWorld:
        """The simulated rig of `setup` ("platform" | "gripper") from typed SimConfig/SkinConfig."""
        from hardware.sim.build import build_sim_rig

        return cls(build_sim_rig(sim_cfg, skin_cfg, setup), period_s)

    # ---- life cycle ------------------------------------------------------------------------
    def start(self) -> None:
        """Connect the twins and start advancing the world with wall time."""
        if self._thread is not None:
            return
        with self.lock:
            self.rig.connect()
            # The first advance loads (or compiles) the compiled kernels, which takes seconds:
            # take it before wall time starts counting, not while emulators wait on the lock.
            self.world.advance(WARM_UP_S)
            self.rig.clock.now_ns()
            for d in self.rig.devices():  # nothing acquired during the warm-up is served
                d.read_available()
            self._origin_ns = time.monotonic_ns() - int(round(self.world.t_s * 1e9))
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="realtime-world", daemon=True)
        self._thread.start()

    def halt(self) -> None:
        """Stop advancing the world (after the step in progress); `stop` then disconnects it."""
        self._stop.set()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        with self.lock:
            self.rig.disconnect()

    def __enter__(self) -> RealtimeWorld:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # ---- who drains which stream --------------------------------------------------------------
    def _twins_without(self, claims: dict) -> tuple:
        claimed = {name for names in claims.values() for name in names}
        return tuple(getattr(self.rig, n) for n in STREAM_TWINS
                     if n not in claimed and getattr(self.rig, n, None) is not None)

    def claim(self, emulator, twins) -> None:
        """`emulator` drains the streams of `twins` (rig attribute names) from now on."""
        with self.lock:
            self._claims[id(emulator)] = tuple(twins)
            self._unclaimed = self._twins_without(self._claims)

    def release(self, emulator) -> None:
        with self.lock:
            self._claims.pop(id(emulator), None)
            self._unclaimed = self._twins_without(self._claims)

    def _discard_unclaimed(self) -> None:
        for twin in self._unclaimed:
            if twin.is_connected:
                twin.read_available()

    # ---- time --------------------------------------------------------------------------------
    def world_time_s(self) -> float:
        """Where the world should be now (wall time since start)."""
        return (time.monotonic_ns() - self._origin_ns) * 1e-9

    def to_monotonic_ns(self, world_host_ns: int) -> int:
        """A world host time (as stamped on twin records) on this host's monotonic clock."""
        return int(world_host_ns - self.world.host_start_ns + self._origin_ns)

    def begin_trial(self, labels: dict) -> None:
        """The next trial's labels: the world draws that trial's noise and bench variation."""
        with self.lock:
            self.rig.begin_trial(labels)

    def _run(self) -> None:
        try:
            while not self._stop.wait(self.period_s):
                target_s = self.world_time_s()
                while not self._stop.is_set():
                    with self.lock:
                        dt = min(target_s - self.world.t_s, MAX_ADVANCE_S)
                        if dt > 0:
                            self.world.advance(dt)
                            self._discard_unclaimed()
                    if dt < MAX_ADVANCE_S:
                        break
                self.lag_s = max(self.lag_s, self.world_time_s() - target_s)
        except BaseException as exc:  # noqa: BLE001 - reported to the emulators through `error`
            self.error = exc
