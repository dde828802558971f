"""The three-axis force-calibration platform behind a GRBL 1.1 controller (serial).

GrblPlatform: the driver (hardware.interfaces.Platform); GrblPlatformConfig: its settings;
hardware.platform.emulator.GrblEmulator: GRBL on a pseudo-terminal backed by the simulated stage.
"""

from hardware.platform.config import GrblPlatformConfig
from hardware.platform.driver import GrblPlatform

__all__ = ["GrblPlatform", "GrblPlatformConfig"]
