"""How the drivers' watchdogs tell a silent device from a host that was busy (issue 30).

A receive thread that the scheduler did not run for 50 ms leaves the device's data in the OS
buffer; judged by when that thread last received, a busy host looks like a silent device. The
drivers therefore first take what the OS holds (drain the port, peek at the socket, ask the
client's cache) and then judge by what the device itself says:

- `DeviceClock`, for devices that stamp their data (skin board time, Net F/T sample counter, UR
  controller timestamp): when the device made its newest sample, on the host clock.
- `ReplyWatch`, for polled devices that carry no clock (GRBL status reports, the Hand-E's
  replies): silence counts only while a request has waited for its answer, so a poller that the
  host did not run is not a silent device.

Either way a genuinely silent device is reported no later than the host-receive rule would:
host receipt never precedes making, and the first unanswered request follows the last reply
within one poll period.
"""

from __future__ import annotations

import threading

# How fast the host-minus-device offset may grow (device clock slower than the host's): 1000 ppm,
# far above a crystal's drift, far below what would hide a stall.
DRIFT_ALLOWANCE = 1e-3


class DeviceClock:
    """When the device made its newest sample, on the host clock: its device time plus the
    smallest host-minus-device offset seen (allowed to grow DRIFT_ALLOWANCE to follow drift).
    Any thread may call it."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._state: tuple[int, int] | None = None  # (newest device ns, offset ns)

    def reset(self) -> None:
        """Forget the device's clock (it may have restarted it: a reconnect)."""
        self._state = None

    @property
    def newest_device_ns(self) -> int | None:
        state = self._state
        return None if state is None else state[0]

    @property
    def newest_host_ns(self) -> int | None:
        """When the device made its newest sample, on the host clock (None before one)."""
        state = self._state
        return None if state is None else state[0] + state[1]

    def observe(self, device_ns: int, host_ns: int) -> None:
        """The newest sample: made at device_ns (device clock), received at host_ns."""
        with self._lock:
            offset = host_ns - device_ns
            state = self._state
            if state is not None:
                newest, old = state
                if device_ns < newest:  # an older sample (two observers raced): nothing new
                    return
                offset = min(offset, old + int((device_ns - newest) * DRIFT_ALLOWANCE))
            self._state = (device_ns, offset)

    def silent_ns(self, now_ns: int) -> int | None:
        """How long before now_ns (host ns) the device made its newest sample; None before one."""
        made = self.newest_host_ns
        return None if made is None else now_ns - made


class ReplyWatch:
    """A polled device's silence: the time since its last answer, counted only while a request
    has waited for an answer for longer than `allowance_ns` (the bound less one poll period, so
    a silent device is still reported one bound after its last answer)."""

    def __init__(self, allowance_ns: float) -> None:
        self.allowance_ns = allowance_ns
        self._lock = threading.Lock()
        self._answer_ns: int | None = None
        self._asked_ns: int | None = None  # the oldest request sent since the last answer

    def reset(self) -> None:
        with self._lock:
            self._answer_ns = self._asked_ns = None

    def asked(self, host_ns: int, sending_from_ns: int | None = None) -> None:
        """A request went out; host_ns: once it was sent (a thread descheduled before sending
        asked nothing yet). sending_from_ns: when sending began, where the answer is read by
        another thread: an answer read since then means the device answers (a sender descheduled
        between sending and this call would otherwise leave an answered request waiting, and
        the next request, if its sender is late too, could not clear it)."""
        with self._lock:
            if sending_from_ns is not None and self._answer_ns is not None and self._answer_ns >= sending_from_ns:
                return
            if self._asked_ns is None:
                self._asked_ns = host_ns

    def answered(self, host_ns: int) -> None:
        with self._lock:
            self._answer_ns, self._asked_ns = host_ns, None

    def asked_after_answer_ns(self) -> int:
        """How long after the last answer the waiting request went out (0 if none waits): beyond
        one poll period, the poller ran late (the host's scheduling), and the silence rule can
        fire only that much later."""
        answer, asked = self._answer_ns, self._asked_ns
        return 0 if answer is None or asked is None else max(0, asked - answer)

    def silent_ns(self, now_ns: int) -> int | None:
        """Time since the last answer while a request waits beyond the allowance; else None."""
        answer, asked = self._answer_ns, self._asked_ns
        if answer is None or asked is None or now_ns - asked <= self.allowance_ns:
            return None
        return now_ns - answer
