"""The skin readout board: serial frame protocol, driver, and a pty emulator backed by the simulated world."""

from hardware.skin_board.config import SkinBoardConfig

__all__ = ["EMULATOR_SETUP", "FrameParser", "SkinBoardConfig", "SkinBoardEmulator", "SkinBoardReader", "WireFrame",
           "encode_frame"]


def __getattr__(name: str):
    """The driver and the rest load at first use: Hydra's schemas import this package's config,
    which runs this file first, and `--help` must not wait for what they import."""
    if name == "SkinBoardReader":
        from hardware.skin_board import driver

        return getattr(driver, name)
    if name in ("EMULATOR_SETUP", "SkinBoardEmulator"):
        from hardware.skin_board import emulator

        return getattr(emulator, name)
    if name in ("FrameParser", "WireFrame", "encode_frame"):
        from hardware.skin_board import wire

        return getattr(wire, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
