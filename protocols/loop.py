"""The one protocol loop: tick the rig clock, drain the streams into the trial log, check faults
and the deadline. Both protocols wait on the rig only through this, so the stall and fault
checks live in one place.

Every tick asks the rig for a fault (a stalled stream, a lost link, a fault a device signals,
one a driver thread reported): the first one stops all motion and raises `DeviceFault`, which
closes the trial file "aborted: <reason>". A wait that outlasts its deadline, or a trial that
outlasts `trial_timeout_s`, raises `DeviceTimeout` after stopping all motion. Both are
`DeviceError`s.
"""

from __future__ import annotations

from collections.abc import Callable

from hardware.interfaces import DeviceError
from protocols.runner import Terminated, TrialLog, check_termination


class DeviceFault(DeviceError):
    """A device failed, stalled or lost its link during a trial (motion has been stopped).
    detected_ns: host time at which the fault was detected."""

    def __init__(self, reason: str, detected_ns: int | None = None) -> None:
        super().__init__(reason)
        self.detected_ns = detected_ns


class GuardTripped(RuntimeError):
    """A safety guard stopped the motion and the protocol cannot go on with this trial."""


class DeviceTimeout(DeviceError):
    """A device did not finish what it was told within the allowed time (motion has been stopped)."""


class ControlLoop:
    """Ticks of one trial: `period_s` of rig clock each, every sample drained into `log`."""

    def __init__(self, log: TrialLog, period_s: float, trips_abort: bool = False,
                 trial_timeout_s: float | None = None) -> None:
        """trips_abort: a guard trip ends the trial (raises GuardTripped) instead of being left to
        the protocol to handle (the calibration protocol retracts and goes on).
        trial_timeout_s: rig-clock seconds from now after which the trial is stopped."""
        self.trips_abort = trips_abort
        self.log = log
        self.rig = log.rig
        self.clock = log.rig.clock
        self.period_s = float(period_s)
        self.trial_timeout_s = trial_timeout_s
        self._trial_end_ns = None if trial_timeout_s is None else self.clock.now_ns() + int(trial_timeout_s * 1e9)

    def check(self) -> None:
        """Raise DeviceFault (after stopping all motion) if any device reports a fault, and
        GuardTripped if a guard tripped and trips end the trial."""
        first = self.rig.first_fault()
        if first:
            self.rig.stop_motion()
            raise DeviceFault(*first)
        try:
            check_termination()
        except Terminated:
            self.rig.stop_motion()
            raise
        if self.trips_abort and self.rig.tripped is not None:
            raise GuardTripped(self.rig.tripped)
        if self._trial_end_ns is not None and self.clock.now_ns() > self._trial_end_ns:
            self.rig.stop_motion()
            raise DeviceTimeout(f"the trial outlasted trial_timeout_s={self.trial_timeout_s:g} s and was stopped "
                                "(raise trial_timeout_s if the protocol needs longer)")

    def tick(self) -> tuple[list, list]:
        """One control period: sleep, drain, check faults. Returns the new (skin frames, wrenches)."""
        self.clock.sleep(self.period_s)
        out = self.log.drain()
        self.check()
        return out

    def until(self, done: Callable[[list, list], object], timeout_s: float, what: str):
        """Tick until done(frames, wrenches) returns something truthy (returned), with the frames
        and wrenches of that tick; raise DeviceTimeout after timeout_s."""
        deadline_ns = self.clock.now_ns() + int(timeout_s * 1e9)
        while True:
            result = done(*self.tick())
            if result:
                return result
            if self.clock.now_ns() > deadline_ns:
                self.rig.stop_motion()
                raise DeviceTimeout(f"{what} did not finish within {timeout_s:.1f} s")

    def wait(self, busy: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Tick while busy() (checked before each tick), at most timeout_s; then drain once more."""
        if busy():
            self.until(lambda *_: not busy(), timeout_s, what)
        self.log.drain()

    def hold(self, duration_s: float) -> list:
        """Let duration_s pass; returns the skin frames acquired meanwhile."""
        frames: list = []
        end_ns = self.clock.now_ns() + int(duration_s * 1e9)
        while self.clock.now_ns() < end_ns:
            frames += self.tick()[0]
        return frames
