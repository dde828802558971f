"""The marker camera on loopback: a fake VideoCapture fed with the simulated camera's frames.

Backed by the gripper setup's SimMarkerCamera twin (`rt.rig.camera`): it renders the markers for
the world's state at 30 fps of world time (which the RealtimeWorld keeps on the wall clock),
with its lens blur and sensor noise. The emulator turns on the twin's image keeping, takes each
new frame under rt.lock, and hands it to the capture at the frame's host time (exposure plus the
twin's pipeline latency), reporting the twin's device time as CAP_PROP_POS_MSEC. The twin's own
detections of the same frames are kept in `twin_detections` (frame device_t_ns -> detections),
the reference the driver's must match.

Not a network device: start() returns "fake-capture:<id>" and `capture_factory` is what the
driver takes. Covers: frames, their timestamps, frame size and rate properties. Not covered:
USB/V4L2 buffering and dropped frames, exposure and format controls (set() is accepted, ignored).
Fault injection: `stalled` (no new frames; read() keeps waiting), `end_capture()` (read() fails
from then on, as an unplugged camera's).
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque

import cv2

EMULATOR_SETUP = "gripper"
POLL_S = 0.005  # how often the emulator looks for a new twin frame
READ_SLICE_S = 0.02  # a blocked read() wakes this often to notice release()
_ids = itertools.count(1)


class FakeCapture:
    """The cv2.VideoCapture API over the emulator's frame queue (one per driver connect)."""

    def __init__(self, emulator: CameraEmulator) -> None:
        self._emu = emulator
        self._open = True
        self._pos_ms = 0.0

    def isOpened(self) -> bool:  # noqa: N802 - the VideoCapture API
        return self._open and self._emu.running

    def read(self):
        emu = self._emu
        while self._open:
            if emu.ended:
                return False, None
            with emu.cond:
                if emu.frames and emu.frames[0][2] <= time.monotonic_ns():
                    img, dev_ns, _ = emu.frames.popleft()
                    self._pos_ms = dev_ns / 1e6
                    return True, cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)  # a colour camera's BGR frame
                emu.cond.wait(READ_SLICE_S)
        return False, None

    def get(self, prop: int) -> float:
        cfg = self._emu.rt.rig.camera.cfg
        return {cv2.CAP_PROP_POS_MSEC: self._pos_ms, cv2.CAP_PROP_FRAME_WIDTH: float(cfg.width_px),
                cv2.CAP_PROP_FRAME_HEIGHT: float(cfg.height_px), cv2.CAP_PROP_FPS: float(cfg.fps)}.get(prop, 0.0)

    def set(self, prop: int, value: float) -> bool:
        return True

    def release(self) -> None:
        self._open = False


class CameraEmulator:
    """rt: a started RealtimeWorld of the "gripper" setup. host/port are unused (no network)."""

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, stalled: bool = False, max_queue: int = 8) -> None:
        self.rt = rt
        self.stalled = bool(stalled)
        self.ended = False
        self.name = f"fake-capture:{next(_ids)}"
        self.frames: deque = deque(maxlen=max_queue)  # (grey (H, W) uint8, device_t_ns, release monotonic ns)
        self.cond = threading.Condition()
        self.twin_detections: dict[int, list] = {}
        self.running = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._last_dev_ns: int | None = None

    def capture_factory(self) -> FakeCapture:
        return FakeCapture(self)

    def end_capture(self) -> None:
        """From now on read() fails, as with an unplugged camera."""
        self.ended = True
        with self.cond:
            self.cond.notify_all()

    def start(self) -> str:
        with self.rt.lock:
            self.rt.rig.camera.cfg.keep_images = True  # the twin keeps its latest frame for us
        self._stop.clear()
        self.running = True
        self._thread = threading.Thread(target=self._run, name="camera-emu", daemon=True)
        self._thread.start()
        return self.name

    def stop(self) -> None:
        self._stop.set()
        self.running = False
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        with self.cond:
            self.cond.notify_all()

    def __enter__(self) -> CameraEmulator:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _run(self) -> None:
        twin = self.rt.rig.camera
        while not self._stop.wait(POLL_S):
            with self.rt.lock:
                stamped = twin.latest_image_stamped()
                dets = twin.read_available()
            for d in dets:
                self.twin_detections.setdefault(d.device_t_ns, []).append(d)
            while len(self.twin_detections) > 64:
                del self.twin_detections[next(iter(self.twin_detections))]
            if stamped is None or stamped[1] == self._last_dev_ns:
                continue
            img, dev_ns, host_ns = stamped
            self._last_dev_ns = dev_ns
            if self.stalled:
                continue
            with self.cond:
                self.frames.append((img, dev_ns, self.rt.to_monotonic_ns(host_ns)))
                self.cond.notify_all()
