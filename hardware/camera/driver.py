"""The lab marker camera: frames from an OpenCV-style capture, ArUco markers and their poses by the shared tracker.

A capture thread reads frames as they come, stamps them and runs the detector
(`layerskin_exp.vision.MarkerTracker`: tracked search, refined corners, joint layer PnP with
the calibration's distortion), so read_available() hands out detections with no image work
on the caller's side.

Time stamps: host_t_ns is time.monotonic_ns() when read() returns the frame. device_t_ns is
the capture time: the backend's frame timestamp (CAP_PROP_POS_MSEC: V4L2's buffer time, the
RealSense frame time) when it gives one (> 0), else the host receive time minus the configured
pipeline latency (latency_ms), an estimate as good as that constant.

frame_seq numbers the camera's frames since connect. A capture gives no frame numbers, so where
it gives timestamps the number advances by the frame periods (1 / fps) between two frames' capture
times, rounded: a frame the capture's ring dropped (a host that read too slowly) leaves a gap in
frame_seq and counts as lost in the stream's health. Without timestamps it advances by one per
frame read, and a dropped frame cannot be seen.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable

import cv2
import numpy as np

from hardware.camera.capture import open_capture
from hardware.camera.config import CameraConfig
from hardware.interfaces import DeviceError, MarkerCamera
from layerskin_exp.types import MarkerDetection, Pose
from layerskin_exp.vision import MarkerTracker, quat_xyzw

log = logging.getLogger(__name__)


class OpenCVMarkerCamera(MarkerCamera):
    """capture_factory(): returns an object with the cv2.VideoCapture API (isOpened, read, get, set,
    release); None opens the configured source (hardware/camera/capture.py)."""

    def __init__(self, config: CameraConfig, capture_factory: Callable[[], object] | None = None) -> None:
        super().__init__()
        self.config = config
        self.capture_factory = capture_factory or (lambda: open_capture(config))
        self.tracker = MarkerTracker(config, dist_coeffs=config.dist_coeffs)
        self._cap = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._first = threading.Event()
        self._lock = threading.Lock()
        self._buf: deque[MarkerDetection] = deque()
        self._latest: tuple[np.ndarray, int, int] | None = None
        self._last_rx_ns: int | None = None
        self._error: str | None = None
        self._seq = 0
        self._last_dev_ns: int | None = None  # capture time of the previous frame, when the capture stamps them

    def _connect(self) -> None:
        c = self.config
        self._error, self._last_rx_ns, self._latest, self._seq, self._last_dev_ns = None, None, None, 0, None
        self.tracker.reset()
        with self._lock:
            self._buf.clear()
        cap = self.capture_factory()
        if cap is None or not cap.isOpened():
            if cap is not None:
                cap.release()
            raise DeviceError(f"camera: cannot open {c.backend} source {c.source!r}; check that the camera is "
                              "plugged in, not used by another program, and hardware.camera.source")
        self._cap = cap
        self._stop.clear()
        self._first.clear()
        self._thread = threading.Thread(target=self._run, name="camera-capture", daemon=True)
        self._thread.start()
        if not self._first.wait(c.connect_timeout_s):
            reason = self._error or "no frame"
            self._shutdown()
            raise DeviceError(f"camera: {reason} from {c.backend} source {c.source!r} within {c.connect_timeout_s} s;"
                              " check the camera's cable and that it streams (e.g. with v4l2-ctl or realsense-viewer)")
        log.info("camera: streaming from %s (%s source %r)", type(cap).__name__, c.backend, c.source)

    def _disconnect(self) -> None:
        self._shutdown()

    def _shutdown(self) -> None:
        self._stop.set()
        cap, self._cap = self._cap, None
        mine = self._thread is not None and self._thread is not threading.current_thread()
        # The thread ends after the read in progress (a frame period); a capture that blocks
        # (a stalled camera) is released under it, which makes its read return.
        if mine:
            self._thread.join(timeout=3.0 / self.config.fps + 0.1)
        if cap is not None:
            cap.release()
        if mine:
            self._thread.join(timeout=2.0)
        self._thread = None

    def _run(self) -> None:
        cap, c = self._cap, self.config
        latency_ns = int(round(c.latency_ms * 1e6))
        period_ns = 1e9 / c.fps
        while not self._stop.is_set():
            try:
                ok, frame = cap.read()
            except cv2.error as exc:
                ok, frame = False, exc
            host_ns = time.monotonic_ns()
            if self._stop.is_set():
                break
            if not ok or frame is None or not hasattr(frame, "ndim"):
                self._error = f"camera: capture ended (read failed on {c.backend} source {c.source!r})"
                log.error("%s", self._error)
                break
            pos_ms = float(cap.get(cv2.CAP_PROP_POS_MSEC) or 0.0)
            dev_ns = int(round(pos_ms * 1e6)) if pos_ms > 0 else host_ns - latency_ns
            grey = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
            prev_seq = self._seq if self._seq else None
            self._seq += self._frame_steps(dev_ns if pos_ms > 0 else None, period_ns)
            seq = self._seq
            dets = []
            try:
                for d in self.tracker.detect(grey):
                    pose = Pose(d.tvec_mm * 1e-3, quat_xyzw(d.rvec), "camera", dev_ns, host_ns, seq)
                    dets.append(MarkerDetection(d.marker_id, pose, d.corners_px, seq, dev_ns, host_ns))
            except cv2.error as exc:  # a frame the detector cannot take: counted, the stream goes on
                self.health.corrupt += 1
                log.warning("camera: frame %d rejected by the detector: %s", seq, exc)
            self.health.observe_seq(prev_seq, seq)
            with self._lock:
                self._buf.extend(dets)
                self._latest = (grey, dev_ns, host_ns)
            self._last_rx_ns = host_ns
            self._first.set()

    def _frame_steps(self, dev_ns: int | None, period_ns: float) -> int:
        """How many frame periods since the previous frame: from the capture times when the
        capture stamps its frames (at least 1: a repeated or earlier stamp is not a gap), else 1."""
        prev, self._last_dev_ns = self._last_dev_ns, dev_ns
        if dev_ns is None or prev is None:
            return 1
        return max(1, round((dev_ns - prev) / period_ns))

    def read_available(self) -> list[MarkerDetection]:
        self._require_connected()
        with self._lock:
            out = list(self._buf)
            self._buf.clear()
        return out

    def latest_image(self) -> np.ndarray | None:
        """The most recent grey frame (H, W) uint8."""
        stamped = self.latest_image_stamped()
        return None if stamped is None else stamped[0]

    def latest_image_stamped(self) -> tuple[np.ndarray, int, int] | None:
        """(grey image (H, W) uint8, device_t_ns, host_t_ns) of the most recent frame."""
        with self._lock:
            return self._latest

    def calibration(self) -> dict:
        """Intrinsics, distortion and markers (for the session metadata), as the simulated camera gives them."""
        c = self.config
        return {"K": self.tracker.K.tolist(), "dist": list(c.dist_coeffs), "width_px": c.width_px,
                "height_px": c.height_px, "marker_size_mm": c.marker_size_mm, "marker_ids": list(c.marker_ids),
                "dictionary": c.dictionary, "latency_ms": c.latency_ms}

    def fault(self, now_ns: int) -> str | None:
        """A capture that ended, or no frame for longer than stall_timeout_s."""
        if self._error is not None:
            return self._error
        if self.is_connected and self._last_rx_ns is not None:
            quiet_ns = now_ns - self._last_rx_ns
            if quiet_ns > self.config.stall_timeout_s * 1e9:
                return f"camera stalled: no frame for {quiet_ns / 1e6:.0f} ms"
        return None
