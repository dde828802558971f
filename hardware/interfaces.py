"""Device interfaces the protocols use; every backend (sim, lab, loopback) implements these.

One small abstract base per kind of device, explicit connect/disconnect, a named error when a
device is used unconnected, and health counters on every stream. Protocols never touch a
concrete class or the wall clock: they get a `Rig` (devices + clock, `hardware/rig.py`) from the
backend.

Streaming devices buffer what arrives; `read_available()` hands over everything received since
the previous call, oldest first, each sample carrying device time and host receive time.
Motion commands are non-blocking: they start a move and return; the protocol then advances the
clock and watches the streams (that is what lets it stop a slide the moment a limit trips).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

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
    # Called with each batch of frames as it is acquired, from the acquiring thread (the rig's
    # skin guards: Rig.check_frames). Set by the backend that builds the rig.
    on_frames: Callable[[list[TwoLayerFrame]], object] | None = None

    @abstractmethod
    def read_available(self) -> list[TwoLayerFrame]: ...

    @abstractmethod
    def calibration(self) -> dict:
        """Sensor description stored in every session's metadata (geometry, readout, board id)."""


class ForceTorqueSensor(Device):
    """Six-axis F/T reference (ATI Mini40 on the calibration platform)."""

    name = "ft"
    # Called with every sample as it is acquired, from the acquiring thread (the rig's force
    # guards: Rig.check_guards). Set by the backend that builds the rig.
    on_sample: Callable[[Wrench], object] | None = None

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
