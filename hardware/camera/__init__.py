"""The lab marker camera: OpenCV capture (V4L2 or RealSense) + the shared ArUco tracker, and its emulator."""

from hardware.camera.config import CameraConfig

__all__ = ["EMULATOR_SETUP", "CameraConfig", "CameraEmulator", "FakeCapture", "OpenCVMarkerCamera"]


def __getattr__(name: str):
    """The driver and the rest load at first use: Hydra's schemas import this package's config,
    which runs this file first, and `--help` must not wait for what they import."""
    if name == "OpenCVMarkerCamera":
        from hardware.camera import driver

        return getattr(driver, name)
    if name in ("EMULATOR_SETUP", "CameraEmulator", "FakeCapture"):
        from hardware.camera import emulator

        return getattr(emulator, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
