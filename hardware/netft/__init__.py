"""ATI Mini40 behind a Net F/T box: RDT over UDP (driver), its loopback emulator, the wire format."""

from hardware.netft.config import NetFTConfig

__all__ = ["EMULATOR_SETUP", "Calibration", "NetFTConfig", "NetFTEmulator", "NetFTSensor"]


def __getattr__(name: str):
    """The driver and the rest load at first use: Hydra's schemas import this package's config,
    which runs this file first, and `--help` must not wait for what they import."""
    if name == "NetFTSensor":
        from hardware.netft import driver

        return getattr(driver, name)
    if name in ("EMULATOR_SETUP", "NetFTEmulator"):
        from hardware.netft import emulator

        return getattr(emulator, name)
    if name == "Calibration":
        from hardware.netft import wire

        return getattr(wire, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
