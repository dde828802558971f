"""The marker camera on loopback: a fake VideoCapture fed with the simulated camera's frames.

Backed by the gripper setup's SimMarkerCamera twin (`rt.rig.camera`): it renders the markers for
the world's state at 30 fps of world time (which the RealtimeWorld keeps on the wall clock),
with its lens blur and sensor noise. The emulator turns on the twin's image keeping, takes every
frame the twin made since its last look (`take_images`, without the world's lock), and hands
each to the capture at the frame's host time (exposure plus the twin's pipeline latency),
reporting the twin's device time as CAP_PROP_POS_MSEC. The twin's own
detections of the same frames are kept in `twin_detections` (frame device_t_ns -> detections),
the reference the driver's must match.

Not a network device: start() returns "fake-capture:<id>" and `capture_factory` is what the
driver takes. Covers: frames, their timestamps, frame size and rate properties. The capture
holds at most `max_queue` delivered frames, as a V4L2 buffer ring does: a driver that reads
slower than the camera makes loses the oldest (`overwritten` counts them; the driver sees the
gap in the frames' timestamps). Not covered: USB transfer errors, exposure and format controls
(set() is accepted, ignored). Faults (hardware.emulation's vocabulary): stall() (no new frames; read() keeps waiting;
resume()), drop(n) (the next n frames never come), corrupt(n) (the next n frames are "noise":
uniform random pixels, in which no marker is found), disconnect() (read() fails from then on, as
an unplugged camera's).

It stays in the host's process, unlike the emulators that serve a link: the driver takes frames
from a capture object in its own process (the lab camera's link is USB/V4L2 or librealsense, which
no hermetic test can serve), and the frames are rendered by the world, which is in this process
too; a process between them would add two pipe hops per 0.9 MB frame (1280 x 720 grey, 30 fps)
and leave both ends here. (The driver's stall bound is 200 ms, six frame periods.)
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import deque

import cv2
import numpy as np

from hardware.emulation import Emulator

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
        with emulator.cond:  # a device opened afresh starts with an empty buffer ring
            emulator.frames.clear()

    def isOpened(self) -> bool:  # noqa: N802 - the VideoCapture API
        return self._open and self._emu.running

    def read(self):
        emu = self._emu
        while self._open:
            if emu.disconnected:
                return False, None
            with emu.cond:
                emu.overwrite_unread(time.monotonic_ns())
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


class CameraEmulator(Emulator):
    """rt: a started RealtimeWorld of the "gripper" setup. host/port are unused (no network)."""

    DEVICE = "camera"
    TWINS = ("camera",)
    CORRUPTIONS = ("noise",)

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, max_queue: int = 8, seed: int = 0,
                 stall_after_s: float | None = None, disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        self.rng = np.random.default_rng(seed)
        self.name = f"fake-capture:{next(_ids)}"
        self.max_queue = int(max_queue)
        # (grey (H, W) uint8, device_t_ns, release monotonic ns): frames still in the camera's
        # pipeline (release time to come) and delivered ones the driver has not read
        self.frames: deque = deque()
        self.overwritten = 0  # delivered frames pushed out of the ring unread
        self.cond = threading.Condition()
        self.twin_detections: dict[int, list] = {}

    def overwrite_unread(self, now_ns: int) -> None:
        """Keep at most max_queue delivered frames (release time passed), dropping the oldest
        (call under `cond`)."""
        delivered = 0
        for _, _, release_ns in self.frames:
            if release_ns > now_ns:
                break
            delivered += 1
        for _ in range(delivered - self.max_queue):
            self.frames.popleft()
            self.overwritten += 1

    def capture_factory(self) -> FakeCapture:
        return FakeCapture(self)

    def _on_disconnect(self) -> None:
        with self.cond:
            self.cond.notify_all()

    def _open(self) -> str:
        with self.rt.lock:
            self.rt.rig.camera.cfg.keep_images = True  # the twin keeps its latest frame for us
        self._spawn(self._run, "frames")
        return self.name

    def _wake(self) -> None:
        with self.cond:
            self.cond.notify_all()

    def _run(self) -> None:
        twin = self.rt.rig.camera
        while not self._stop.wait(POLL_S):
            # every frame since the last look, not only the newest; taken without the world's
            # lock, which a world catching up on a busy host holds for a step after another (the
            # frames it makes meanwhile reach the driver as they are made, not after the catch-up)
            made = twin.take_images()
            dets = []
            if self.rt.lock.acquire(blocking=False):  # the twin's detections: the tests' reference only
                try:
                    dets = twin.read_available()
                finally:
                    self.rt.lock.release()
            for d in dets:
                self.twin_detections.setdefault(d.device_t_ns, []).append(d)
            while len(self.twin_detections) > 64:
                del self.twin_detections[next(iter(self.twin_detections))]
            for frame, dev_ns, host_ns in made:
                if self.stalled:
                    continue
                fault = self._next_fault()
                if fault is not None and fault[0] == "drop":
                    continue
                img = frame.full()
                if fault is not None:
                    img = self.rng.integers(0, 256, img.shape, dtype=np.uint8)
                with self.cond:
                    self.frames.append((img, dev_ns, self.rt.to_monotonic_ns(host_ns)))
                    self.overwrite_unread(time.monotonic_ns())
                    self.cond.notify_all()
