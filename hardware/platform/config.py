"""Configuration of the GRBL 1.1 three-axis platform driver (serial link, rates, frame mapping)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from layerskin_exp.config import require


@dataclass
class GrblPlatformConfig:
    """GRBL 1.1 controller of the force-calibration platform, over a serial port.

    Coordinates: GRBL reports MPos, machine coordinates (units per `units`, i.e. GRBL's $13);
    the skin frame is skin_mm = MPos_mm + offset_mm per axis. A real GRBL homed at its switches
    reports MPos in [-$13x, 0]; set offset_mm to the skin-frame position of machine zero. The
    loopback emulator reports MPos in the skin frame already (offset 0).
    """

    port: str = "/dev/ttyUSB0"
    baudrate: int = 115200
    connect_timeout_s: float = 3.0  # port open + welcome banner + first status report
    stall_timeout_s: float = 0.05  # no status report for longer than this -> fault()
    status_rate_hz: float = 100.0  # `?` polls; each report is one StagePosition
    rx_buffer_bytes: int = 128  # GRBL's serial receive buffer, for character counting
    command_timeout_s: float = 1.0  # a command line waits at most this for buffer space / its response
    stop_timeout_s: float = 2.0  # feed hold must complete (Hold:0) within this, else fault()
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)  # skin = MPos (in mm) + offset
    units: str = "mm"  # units of GRBL's reports: "mm" ($13=0) or "inch" ($13=1)
    unlock_alarm: bool = False  # send `$X` when GRBL starts in alarm (only if homing is not needed)

    def __post_init__(self) -> None:
        k = "hardware.platform"
        require(bool(self.port), f"{k}.port", self.port, "must name the serial port (e.g. /dev/ttyUSB0)")
        require(self.baudrate > 0, f"{k}.baudrate", self.baudrate, "must be > 0 (GRBL 1.1 default 115200)")
        require(0 < self.connect_timeout_s <= 60, f"{k}.connect_timeout_s", self.connect_timeout_s, "must be 0..60 s")
        require(0 < self.stall_timeout_s <= 0.05, f"{k}.stall_timeout_s", self.stall_timeout_s,
                "must be > 0 and <= 0.05 s")
        require(1 <= self.status_rate_hz <= 1000 and 1.0 / self.status_rate_hz < self.stall_timeout_s,
                f"{k}.status_rate_hz", self.status_rate_hz,
                "must be 1..1000 Hz with a poll period shorter than stall_timeout_s")
        require(16 <= self.rx_buffer_bytes <= 4096, f"{k}.rx_buffer_bytes", self.rx_buffer_bytes,
                "must be 16..4096 (GRBL on an Uno: 128)")
        require(0 < self.command_timeout_s <= 60, f"{k}.command_timeout_s", self.command_timeout_s, "must be 0..60 s")
        require(0 < self.stop_timeout_s <= 60, f"{k}.stop_timeout_s", self.stop_timeout_s, "must be 0..60 s")
        require(len(self.offset_mm) == 3 and all(math.isfinite(v) for v in self.offset_mm),
                f"{k}.offset_mm", self.offset_mm, "must be three finite values (x, y, z mm)")
        require(self.units in ("mm", "inch"), f"{k}.units", self.units, "must be 'mm' or 'inch'")

    @property
    def mm_per_unit(self) -> float:
        return 25.4 if self.units == "inch" else 1.0
