"""The three-axis force-calibration platform behind a GRBL 1.1 controller (serial).

GrblPlatform: the driver (hardware.interfaces.Platform); GrblPlatformConfig: its settings;
hardware.platform.emulator.GrblEmulator: GRBL on a pseudo-terminal backed by the simulated stage.
"""

from hardware.platform.config import GrblPlatformConfig

__all__ = ["GrblPlatform", "GrblPlatformConfig"]


def __getattr__(name: str):
    """The driver and the rest load at first use: Hydra's schemas import this package's config,
    which runs this file first, and `--help` must not wait for what they import."""
    if name == "GrblPlatform":
        from hardware.platform import driver

        return getattr(driver, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
