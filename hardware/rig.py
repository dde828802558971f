"""The runtime a backend hands a protocol: a clock, the devices it has, and the guards and faults
that stop motion from whatever thread notices them first.

The device interfaces themselves are in `hardware/interfaces.py`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

from hardware.interfaces import (
    Arm,
    Clock,
    Device,
    ForceTorqueSensor,
    Gripper,
    MarkerCamera,
    Platform,
    SkinReader,
)

Guard = Callable[[object], "str | None"]


@dataclass
class Rig:
    """What a backend hands a protocol: a clock and the devices it has (None where absent).

    Thread safety: real drivers acquire in their own threads and call back into the rig from
    there (`check_guards` on every sample, `report_fault` on a broken link), while the protocol
    runs in the main thread. The guard registry, the trip and the fault list are kept under one
    lock; `stop_motion()` may be called from any thread (a guard trip in a receive thread, a
    signal handler, the protocol loop) and never raises.
    """

    backend: str
    clock: Clock
    skin: SkinReader
    ft: ForceTorqueSensor | None = None
    platform: Platform | None = None
    arm: Arm | None = None
    gripper: Gripper | None = None
    camera: MarkerCamera | None = None
    # Why motion was stopped by a guard (the first reason since the last clear_trip, or the first
    # ceiling trip that came after a latched stop condition), or None.
    tripped: str | None = None
    _guards: dict[str, list[Guard]] = field(default_factory=dict, init=False, repr=False)
    _ceilings: dict[str, list[Guard]] = field(default_factory=dict, init=False, repr=False)
    # (reason, host receive ns) of every sample a ceiling guard flagged, not yet taken
    _ceiling_events: list[tuple[str, int]] = field(default_factory=list, init=False, repr=False)
    _ceiling_tripped: bool = field(default=False, init=False, repr=False)  # `tripped` is a ceiling's
    _faults: list[tuple[str, int]] = field(default_factory=list, init=False, repr=False)
    # how late (ns) the watchdog's check that latched the first fault ran behind its period (the
    # host's scheduling, not the device: a stall is caught within a period of its rule firing plus this)
    fault_check_late_ns: int | None = field(default=None, init=False, repr=False)
    _lock: threading.RLock = field(default_factory=threading.RLock, init=False, repr=False)
    _watchdog: threading.Thread | None = field(default=None, init=False, repr=False)
    _watchdog_stop: threading.Event = field(default_factory=threading.Event, init=False, repr=False)
    # How often the watchdog asks every device for a fault on a real-time rig.
    watchdog_period_s: float = field(default=0.005, init=False, repr=False)
    # Undoes what build_rig set up for the trial (the raised priority, the held heap:
    # hardware.priority); called when the rig disconnects.
    release: Callable[[], None] | None = field(default=None, repr=False)

    # ---- trials --------------------------------------------------------------------------------
    def begin_trial(self, labels: dict, slot_s: float = 0.0) -> None:
        """A trial with these labels is about to start (protocols call this before each trial).
        slot_s: where the trial starts in its campaign, s after the run's start (see
        protocols.runner.trial_slot_s). Real devices need nothing; the simulated rig draws the
        trial's noise here and dates the trial at its slot."""

    def log_time(self) -> tuple[int, str] | None:
        """(offset of the current trial's host times on the Unix epoch, how it was chosen) where
        the rig's clock is not the host's (the simulator); None where the session writer dates
        by the wall clock (layerskin_exp.log.session.epoch)."""
        return None

    # ---- guards --------------------------------------------------------------------------------
    def add_guard(self, guard: Guard, stream: str = "ft", ceiling: bool = False) -> None:
        """Watch every sample of `stream` ("ft", "skin", ...) as it is acquired: guard(sample)
        returns None or a reason, and must not act itself (the rig stops motion on a reason).

        ceiling: a safety limit. It is checked on every sample whatever trip is latched (a stop
        condition latched first does not hide it), every sample it flags is kept as a safety event
        (take_ceiling_events), and its trip replaces a latched stop condition, so whoever
        acknowledges that stop condition does not clear the ceiling's trip with it."""
        with self._lock:
            (self._ceilings if ceiling else self._guards).setdefault(stream, []).append(guard)

    def remove_guard(self, guard: Guard, stream: str = "ft") -> None:
        with self._lock:
            for registry in (self._ceilings, self._guards):
                guards = registry.get(stream, [])
                if guard in guards:
                    guards.remove(guard)

    def guards(self, stream: str = "ft") -> tuple[Guard, ...]:
        """Every guard of `stream`, the ceilings first."""
        with self._lock:
            return tuple(self._ceilings.get(stream, ())) + tuple(self._guards.get(stream, ()))

    def watches(self, stream: str) -> bool:
        """Whether any guard watches `stream` (backends skip the per-sample call otherwise)."""
        return bool(self._ceilings.get(stream) or self._guards.get(stream))

    def check_frames(self, frames, stream: str = "skin") -> bool:
        """Run the guards of `stream` on a batch as it is acquired (a skin reader's on_frames);
        True when one tripped. Every frame is checked (a ceiling sees each one); nothing is called
        when no guard watches the stream."""
        if not self.watches(stream):
            return False
        return any([self.check_guards(f, stream) for f in frames])

    def _first_reason(self, registry: dict[str, list[Guard]], sample, stream: str) -> str | None:
        with self._lock:
            guards = tuple(registry.get(stream, ()))
        for g in guards:
            reason = g(sample)
            if reason:
                return reason
        return None

    def guard_reason(self, sample, stream: str = "ft") -> str | None:
        """What check_guards would trip on for this sample, without acting: a ceiling's reason
        unless a ceiling trip is latched already, any guard's when nothing is latched, else None.
        Guards are pure functions of the sample."""
        if self._ceiling_tripped:
            return None
        reason = self._first_reason(self._ceilings, sample, stream)
        if reason or self.tripped is not None:
            return reason
        return self._first_reason(self._guards, sample, stream)

    def check_guards(self, sample, stream: str = "ft") -> str | None:
        """Run the guards of `stream` on one sample; stop motion on the first trip. Backends
        call this for every sample as it is acquired, from whatever thread acquires it.

        The ceilings run on every sample: each sample one flags is kept (take_ceiling_events), and
        the first such trip stops motion from this thread at once, whatever else is latched."""
        reason = self._first_reason(self._ceilings, sample, stream)
        if reason:
            with self._lock:
                self._ceiling_events.append((reason, int(getattr(sample, "host_t_ns", 0))))
                first = not self._ceiling_tripped
                if first:
                    self.tripped, self._ceiling_tripped = reason, True
            if first:  # later samples over the limit find the motion stopped and every move refused
                self.stop_motion()
            return self.tripped
        if self.tripped is not None:
            return self.tripped
        reason = self._first_reason(self._guards, sample, stream)
        if reason:
            with self._lock:
                if self.tripped is not None:  # another thread tripped first
                    return self.tripped
                self.tripped = reason
            self.stop_motion()
        return reason

    def take_ceiling_events(self) -> list[tuple[str, int]]:
        """(reason, host receive ns) of every sample a ceiling guard flagged since the last call."""
        with self._lock:
            events, self._ceiling_events = self._ceiling_events, []
        return events

    def clear_trip(self, reason: str | None = None) -> str | None:
        """Acknowledge a trip (after it was logged) so motion may resume; returns what was cleared.
        reason: the trip being acknowledged; a different one latched since (a ceiling's, which
        replaces a stop condition) is kept, and None is returned."""
        with self._lock:
            if reason is not None and self.tripped != reason:
                return None
            cleared, self.tripped, self._ceiling_tripped = self.tripped, None, False
        return cleared

    # ---- faults --------------------------------------------------------------------------------
    def report_fault(self, reason: str) -> None:
        """A device or driver thread reports a failure (any thread). Motion stops at once; the
        protocol loop raises it on its next tick."""
        with self._lock:
            self._faults.append((reason, self.clock.now_ns()))
        self.stop_motion()

    def fault(self) -> str | None:
        """The first reported fault, else the first connected device whose `fault()` is not None
        (a stalled stream, a lost link, a fault the device signals). The protocol loop asks every
        tick."""
        first = self.first_fault()
        return None if first is None else first[0]

    def first_fault(self) -> tuple[str, int] | None:
        """(reason, host ns when it was detected) of the first fault, as fault()."""
        with self._lock:
            if self._faults:
                return self._faults[0]
        now_ns = self.clock.now_ns()
        for d in self.devices():
            if d.is_connected:
                reason = d.fault(now_ns)
                if reason:
                    return reason, now_ns
        return None

    def _watch(self) -> None:
        """Real-time rigs: ask every device for a fault every few ms, whatever the protocol thread
        is doing (it may be blocked in a command to a hung device), and stop all motion on the
        first one. Faults are latched: the protocol loop raises the first on its next tick."""
        period_ns = int(self.watchdog_period_s * 1e9)
        prev_ns = self.clock.now_ns()
        while not self._watchdog_stop.wait(self.watchdog_period_s):
            now_ns = self.clock.now_ns()
            late_ns, prev_ns = max(0, now_ns - prev_ns - period_ns), now_ns
            with self._lock:
                if self._faults:
                    continue
            for d in self.devices():
                reason = d.fault(now_ns) if d.is_connected else None
                if reason:
                    with self._lock:
                        first = not self._faults
                    if first:
                        self.fault_check_late_ns = late_ns
                    self.report_fault(reason)
                    break

    # ---- devices -------------------------------------------------------------------------------
    def devices(self) -> list[Device]:
        return [d for d in (self.skin, self.ft, self.platform, self.arm, self.gripper, self.camera)
                if d is not None]

    def connect(self) -> None:
        """Connect every device; if one fails, disconnect those already connected and raise.
        On a real-time clock a watchdog thread then checks every device for faults (see _watch)."""
        done: list[Device] = []
        try:
            for d in self.devices():
                d.connect()
                done.append(d)
        except BaseException:
            for d in reversed(done):
                try:
                    d.disconnect()
                except Exception:  # noqa: BLE001 - keep the original error
                    pass
            raise
        if not self.clock.is_virtual and self._watchdog is None:
            self._watchdog_stop.clear()
            self._watchdog = threading.Thread(target=self._watch, name="rig-watchdog", daemon=True)
            self._watchdog.start()

    def stop_motion(self) -> None:
        """Stop everything that moves; never raises. Safe from any thread."""
        for d in (self.platform, self.arm, self.gripper):
            if d is not None and d.is_connected:
                try:
                    d.stop()
                except Exception:  # noqa: BLE001 - stopping must try every device
                    pass

    def disconnect(self) -> None:
        if self._watchdog is not None:
            self._watchdog_stop.set()
            self._watchdog.join(timeout=1.0)
            self._watchdog = None
        for d in reversed(self.devices()):
            try:
                d.disconnect()
            except Exception:  # noqa: BLE001 - disconnect the rest
                pass
        release, self.release = self.release, None
        if release is not None:
            release()

    def __enter__(self) -> Rig:
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.stop_motion()
        self.disconnect()
