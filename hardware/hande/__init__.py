"""Robotiq Hand-E gripper through the Robotiq URCap's socket service (TCP 63352).

HandEGripper: the driver (hardware.interfaces.Gripper); HandEConfig: its settings;
hardware.hande.emulator.HandEEmulator: the URCap socket on loopback backed by the simulated gripper.
"""

from hardware.hande.config import HandEConfig

__all__ = ["HandEConfig", "HandEGripper"]


def __getattr__(name: str):
    """The driver and the rest load at first use: Hydra's schemas import this package's config,
    which runs this file first, and `--help` must not wait for what they import."""
    if name == "HandEGripper":
        from hardware.hande import driver

        return getattr(driver, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
