"""Device interfaces the protocols use; every backend (sim, lab, loopback) implements these.

One small abstract base per kind of device, explicit connect/disconnect, a named error when a
device is used unconnected, and health counters on every stream. Protocols never touch a
concrete class or the wall clock: they get a `Rig` (devices + clock) from the backend.

Streaming devices buffer what arrives; `read_available()` hands over everything received since
the previous call, oldest first, each sample carrying device time and host receive time.
Motion commands are non-blocking: they start a move and return; the protocol then advances the
clock and watches the streams (that is what lets it stop a slide the moment a limit trips).
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from layerskin_exp.types import (
    GripperState,
    MarkerDetection,
    Pose,
    StagePosition,
    StreamHealth,
    TwoLayerFrame,
    Wrench,
)


class DeviceError(RuntimeError):
    """A device failed or stopped answering. The message names the device and what to do."""


class DeviceNotConnectedError(DeviceError):
    """A device was used before connect() or after disconnect()."""


class Clock(ABC):
    """The only source of time and waiting for protocols.

    On `sim` it is virtual: sleep() advances the simulated world. On `lab`/`loopback` it is
    the host monotonic clock.
    """

    @abstractmethod
    def now_ns(self) -> int:
        """Host time, monotonic, in ns."""

    @abstractmethod
    def sleep(self, dt_s: float) -> None:
        """Let dt_s seconds pass (devices keep acquiring meanwhile)."""

    @property
    def is_virtual(self) -> bool:
        return False


class Device(ABC):
    """Base of every device: connect/disconnect, context manager, health counters."""

    name: str = "device"

    def __init__(self) -> None:
        self.health = StreamHealth()
        self._connected = False

    def connect(self) -> None:
        self._connect()
        self._connected = True

    def disconnect(self) -> None:
        if self._connected:
            try:
                self._disconnect()
            finally:
                self._connected = False

    @property
    def is_connected(self) -> bool:
        return self._connected

    def fault(self, now_ns: int) -> str | None:
        """Why this device cannot be trusted right now, or None when it is fine.

        now_ns: host monotonic time (the rig clock). Real drivers report a failed link, a fault
        the device itself signals, or a stall: a streaming device that delivered nothing for
        longer than its stall timeout (50 ms at most). The protocol loop asks every tick, from
        its own thread; drivers answer from state their receive threads keep, without I/O.
        """
        return None

    def _require_connected(self) -> None:
        if not self._connected:
            raise DeviceNotConnectedError(f"{self.name}: not connected; call connect() first")

    def __enter__(self):
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.disconnect()

    @abstractmethod
    def _connect(self) -> None: ...

    @abstractmethod
    def _disconnect(self) -> None: ...


class SkinReader(Device):
    """The two-layer readout board."""

    name = "skin"

    @abstractmethod
    def read_available(self) -> list[TwoLayerFrame]: ...

    @abstractmethod
    def calibration(self) -> dict:
        """Sensor description stored in every session's metadata (geometry, readout, board id)."""


class ForceTorqueSensor(Device):
    """Six-axis F/T reference (ATI Mini40 on the calibration platform)."""

    name = "ft"

    @abstractmethod
    def read_available(self) -> list[Wrench]: ...

    @abstractmethod
    def tare(self) -> None:
        """Zero the bias with the current (unloaded) reading."""


class Platform(Device):
    """Three-axis linear platform carrying the indenter. Positions in the skin frame, mm."""

    name = "platform"

    @abstractmethod
    def move_to(self, target_mm: np.ndarray, speed_mm_s: float) -> None:
        """Start a straight move to target (3,) at speed; returns at once."""

    @abstractmethod
    def stop(self) -> None:
        """Stop motion now (decelerate at the platform's limit)."""

    @abstractmethod
    def is_moving(self) -> bool: ...

    @abstractmethod
    def read_available(self) -> list[StagePosition]: ...


class Arm(Device):
    """Robot arm (UR5e). Poses are UR style: (6,) [x, y, z, rx, ry, rz] in m and rad (rotation vector)."""

    name = "arm"

    @abstractmethod
    def move_linear(self, pose6: np.ndarray, speed_m_s: float, accel_m_s2: float,
                    angular_speed_rad_s: float | None = None) -> None:
        """Start a linear tool move to pose6; returns at once. For a pure rotation the
        angular speed governs."""

    @abstractmethod
    def stop(self) -> None: ...

    @abstractmethod
    def is_moving(self) -> bool: ...

    @abstractmethod
    def tcp_pose6(self) -> np.ndarray:
        """Latest TCP pose (6,)."""

    @abstractmethod
    def read_available(self) -> list[Pose]: ...


class Gripper(Device):
    """Parallel gripper (Robotiq Hand-E). Jaw opening in mm (0 = closed, 50 = open)."""

    name = "gripper"

    @abstractmethod
    def move(self, opening_mm: float, speed_mm_s: float, force_pct: float) -> None:
        """Start moving the jaws to an opening; returns at once."""

    @abstractmethod
    def stop(self) -> None: ...

    @abstractmethod
    def is_moving(self) -> bool: ...

    @abstractmethod
    def read_available(self) -> list[GripperState]: ...


class MarkerCamera(Device):
    """Fixed camera tracking the ArUco markers on the superficial layer."""

    name = "camera"

    @abstractmethod
    def read_available(self) -> list[MarkerDetection]:
        """Detections whose images have come out of the pipeline since the last call."""

    def latest_image(self) -> np.ndarray | None:
        """Most recent grey image (H, W) uint8, when the backend keeps images."""
        return None


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
    # Why motion was stopped by a guard (the first reason since the last clear_trip), or None.
    tripped: str | None = None
    _guards: dict[str, list[Guard]] = field(default_factory=dict, init=False, repr=False)
    _faults: list[tuple[str, int]] = field(default_factory=list, init=False, repr=False)
    _lock: threading.RLock = field(default_factory=threading.RLock, init=False, repr=False)
    _watchdog: threading.Thread | None = field(default=None, init=False, repr=False)
    _watchdog_stop: threading.Event = field(default_factory=threading.Event, init=False, repr=False)
    # How often the watchdog asks every device for a fault on a real-time rig.
    watchdog_period_s: float = field(default=0.005, init=False, repr=False)

    # ---- trials --------------------------------------------------------------------------------
    def begin_trial(self, labels: dict) -> None:
        """A trial with these labels is about to start (protocols call this before each trial).
        Real devices need nothing; the simulated rig draws the trial's noise here."""

    # ---- guards --------------------------------------------------------------------------------
    def add_guard(self, guard: Guard, stream: str = "ft") -> None:
        """Watch every sample of `stream` ("ft", "skin", ...) as it is acquired: guard(sample)
        returns None or a reason, and must not act itself (the rig stops motion on a reason)."""
        with self._lock:
            self._guards.setdefault(stream, []).append(guard)

    def remove_guard(self, guard: Guard, stream: str = "ft") -> None:
        with self._lock:
            guards = self._guards.get(stream, [])
            if guard in guards:
                guards.remove(guard)

    def guards(self, stream: str = "ft") -> tuple[Guard, ...]:
        with self._lock:
            return tuple(self._guards.get(stream, ()))

    def watches(self, stream: str) -> bool:
        """Whether any guard watches `stream` (backends skip the per-sample call otherwise)."""
        return bool(self._guards.get(stream))

    def guard_reason(self, sample, stream: str = "ft") -> str | None:
        """What check_guards would trip on for this sample (None if nothing, or if already
        tripped), without acting. Guards are pure functions of the sample."""
        if self.tripped is not None:
            return None
        for g in self.guards(stream):
            reason = g(sample)
            if reason:
                return reason
        return None

    def check_guards(self, sample, stream: str = "ft") -> str | None:
        """Run the guards of `stream` on one sample; stop motion on the first trip. Backends
        call this for every sample as it is acquired, from whatever thread acquires it."""
        if self.tripped is not None:
            return self.tripped
        reason = self.guard_reason(sample, stream)
        if reason:
            with self._lock:
                if self.tripped is not None:  # another thread tripped first
                    return self.tripped
                self.tripped = reason
            self.stop_motion()
        return reason

    def clear_trip(self) -> str | None:
        """Acknowledge a trip (after it was logged) so motion may resume; returns the reason."""
        with self._lock:
            reason, self.tripped = self.tripped, None
        return reason

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
        while not self._watchdog_stop.wait(self.watchdog_period_s):
            with self._lock:
                if self._faults:
                    continue
            now_ns = self.clock.now_ns()
            for d in self.devices():
                reason = d.fault(now_ns) if d.is_connected else None
                if reason:
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

    def __enter__(self) -> Rig:
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.stop_motion()
        self.disconnect()
