"""UR5e arm: driver over ur_rtde (RTDE + dashboard + control script) and a loopback emulator."""

from hardware.ur5e.config import UR5eConfig

__all__ = ["UR5eArm", "UR5eConfig"]


def __getattr__(name: str):
    """The driver and the rest load at first use: Hydra's schemas import this package's config,
    which runs this file first, and `--help` must not wait for what they import."""
    if name == "UR5eArm":
        from hardware.ur5e import driver

        return getattr(driver, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
