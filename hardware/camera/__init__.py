"""The lab marker camera: OpenCV capture (V4L2 or RealSense) + the shared ArUco tracker, and its emulator."""

from hardware.camera.config import CameraConfig
from hardware.camera.driver import OpenCVMarkerCamera
from hardware.camera.emulator import EMULATOR_SETUP, CameraEmulator, FakeCapture

__all__ = ["EMULATOR_SETUP", "CameraConfig", "CameraEmulator", "FakeCapture", "OpenCVMarkerCamera"]
