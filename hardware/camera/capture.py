"""Frame sources with the cv2.VideoCapture API (isOpened, read, get, set, release).

The driver takes any such object; here are the default ones: OpenCV's capture (V4L2 for a
device index) and, when the config asks for it and pyrealsense2 is installed, the RealSense
colour stream behind the same API (its frame timestamp as CAP_PROP_POS_MSEC).
"""

from __future__ import annotations

import cv2
import numpy as np

from hardware.camera.config import CameraConfig
from hardware.interfaces import DeviceError


def open_capture(cfg: CameraConfig):
    """The configured source, opened (isOpened() may still be False: the driver reports that)."""
    if cfg.backend == "realsense":
        return RealSenseCapture(cfg)
    source: int | str = int(cfg.source) if cfg.source.strip().isdigit() else cfg.source
    if cfg.backend == "v4l2" and isinstance(source, int):
        cap = cv2.VideoCapture(source, cv2.CAP_V4L2)
    else:
        cap = cv2.VideoCapture(source)
    if cap.isOpened():
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, cfg.width_px)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, cfg.height_px)
        cap.set(cv2.CAP_PROP_FPS, cfg.fps)
    return cap


class RealSenseCapture:
    """The D435 colour stream through pyrealsense2, as a VideoCapture (grey frames, device timestamps)."""

    def __init__(self, cfg: CameraConfig) -> None:
        try:
            import pyrealsense2 as rs
        except ImportError as exc:
            raise DeviceError("camera: backend 'realsense' needs the pyrealsense2 package (pip install "
                              "pyrealsense2), or set hardware.camera.backend=v4l2") from exc
        self._rs = rs
        self._pipe = rs.pipeline()
        rs_cfg = rs.config()
        if not cfg.source.strip().isdigit():
            rs_cfg.enable_device(cfg.source)  # a serial number
        rs_cfg.enable_stream(rs.stream.color, cfg.width_px, cfg.height_px, rs.format.bgr8, int(round(cfg.fps)))
        self._timeout_ms = int(max(1000, 5000 / cfg.fps))
        self._t_ms = 0.0
        self._size = (cfg.width_px, cfg.height_px, cfg.fps)
        try:
            self._pipe.start(rs_cfg)
            self._open = True
        except RuntimeError:
            self._open = False

    def isOpened(self) -> bool:  # noqa: N802 - the VideoCapture API
        return self._open

    def read(self):
        try:
            frames = self._pipe.wait_for_frames(self._timeout_ms)
        except RuntimeError:
            return False, None
        color = frames.get_color_frame()
        if not color:
            return False, None
        self._t_ms = float(color.get_timestamp())
        return True, np.asanyarray(color.get_data()).copy()

    def get(self, prop: int) -> float:
        if prop == cv2.CAP_PROP_POS_MSEC:
            return self._t_ms
        return {cv2.CAP_PROP_FRAME_WIDTH: self._size[0], cv2.CAP_PROP_FRAME_HEIGHT: self._size[1],
                cv2.CAP_PROP_FPS: self._size[2]}.get(prop, 0.0)

    def set(self, prop: int, value: float) -> bool:
        return False  # fixed by the stream configuration

    def release(self) -> None:
        if self._open:
            self._open = False
            self._pipe.stop()
