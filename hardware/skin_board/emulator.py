"""Emulator of the skin readout board on a pseudo-terminal, backed by the simulated world.

A thread drains the skin twin (`rt.rig.skin.read_available()` under `rt.lock`) every
`period_s` and writes each frame, encoded with the shared wire module, to the pty master; the
driver opens the slave path that start() returns, as it would /dev/ttyACM0. The wire sequence
number is the twin's seq (+ seq_offset) modulo 2**16, board time the twin's device_t_ns in µs
modulo 2**32.

Faults, drawn per frame from a numpy Generator seeded with `seed` or injected explicitly:
  p_bit_flip        one random bit of the frame flipped (the driver rejects it: corrupt, lost)
  p_drop_byte       one random byte of the frame left out (corrupt, lost)
  p_insert_garbage  1..garbage_max random bytes sent before the frame (corrupt)
  p_drop_frame      the frame not sent at all, as when the board's TX buffer overflows (lost)
  stalls            ((at_s, duration_ms), ...) after start(): nothing written meanwhile; the
                    frames produced during a stall are lost
  unplug_at_s       close the pty this long after start() (the driver's link is lost)
and at run time `inject(*kinds)` (an explicit schedule for the next frames), `stall(duration_ms)`,
`unplug()`. `sent` keeps the latest frames written intact; `counts` what was injected.
"""

from __future__ import annotations

import os
import threading
import time
import tty
from collections import Counter, deque

import numpy as np

from hardware.skin_board.wire import FRAME_LEN, encode_frame

EMULATOR_SETUP = "platform"

FAULT_KINDS = ("bit_flip", "drop_byte", "insert_garbage", "drop_frame")
_MAX_PENDING_BYTES = 512 * FRAME_LEN  # beyond this (nobody reading) whole frames are dropped; room for the world catching up in a burst


class SkinBoardEmulator:
    """The readout board's serial stream on a pty.

    rt: a started RealtimeWorld whose rig has a skin twin. host, port: unused (a pty has no
    network address; accepted so every emulator is built the same way). period_s: how often the
    twin is drained. seq_offset: added to the twin's seq before it wraps to 16 bits (to reach
    the wrap quickly). sent_maxlen: how many intact frames `sent` remembers.
    """

    def __init__(self, rt, host: str | None = None, port: int | None = None, *, seed: int = 0,
                 p_bit_flip: float = 0.0, p_drop_byte: float = 0.0, p_insert_garbage: float = 0.0,
                 p_drop_frame: float = 0.0, garbage_max: int = 64, stalls: tuple = (),
                 unplug_at_s: float | None = None, period_s: float = 0.0015, seq_offset: int = 0,
                 sent_maxlen: int = 100_000) -> None:
        for name, p in (("p_bit_flip", p_bit_flip), ("p_drop_byte", p_drop_byte),
                        ("p_insert_garbage", p_insert_garbage), ("p_drop_frame", p_drop_frame)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name}={p!r}: must be a probability 0..1")
        if garbage_max < 1:
            raise ValueError(f"garbage_max={garbage_max!r}: must be >= 1 byte")
        if not period_s > 0:
            raise ValueError(f"period_s={period_s!r}: must be > 0 s")
        self.rt = rt
        self.rng = np.random.default_rng(seed)
        self.p = {"bit_flip": p_bit_flip, "drop_byte": p_drop_byte, "insert_garbage": p_insert_garbage,
                  "drop_frame": p_drop_frame}
        self.garbage_max = int(garbage_max)
        self.stalls = sorted((float(at), float(ms)) for at, ms in stalls)
        self.unplug_at_s = unplug_at_s
        self.period_s = float(period_s)
        self.seq_offset = int(seq_offset)
        self.sent: deque = deque(maxlen=sent_maxlen)  # TwoLayerFrames of the twin written intact
        self.counts: Counter = Counter()  # frames written, faults injected, frames lost to stalls/overflow
        self.path: str | None = None
        self._lock = threading.Lock()
        self._forced: deque[str | None] = deque()
        self._stall_until = 0.0
        self._unplug = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._pending = bytearray()
        self._t0 = 0.0
        self.error: BaseException | None = None

    # ---- life cycle ------------------------------------------------------------------------
    def start(self) -> str:
        """Open the pty and start streaming; returns the slave path for the driver."""
        if self._thread is not None:
            return self.path
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no line discipline: bytes pass unchanged
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        with self.rt.lock:
            self.rt.rig.skin.read_available()  # start with fresh frames
        self._t0 = time.monotonic()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="skin-board-emulator", daemon=True)
        self._thread.start()
        return self.path

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._close()

    def __enter__(self) -> SkinBoardEmulator:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    # ---- explicit faults ---------------------------------------------------------------------
    def inject(self, *kinds: str | None) -> None:
        """Schedule the next frames: one entry per frame, a fault kind (FAULT_KINDS) or None for an
        intact frame; e.g. inject(*["bit_flip", None] * 5) corrupts every other frame of the next 10."""
        for kind in kinds:
            if kind is not None and kind not in FAULT_KINDS:
                raise ValueError(f"fault kind {kind!r}: choose one of {FAULT_KINDS} or None")
        with self._lock:
            self._forced.extend(kinds)

    @property
    def scheduled(self) -> int:
        """Entries of the inject() schedule not yet applied."""
        with self._lock:
            return len(self._forced)

    def stall(self, duration_ms: float) -> None:
        """Write nothing for duration_ms from now (frames produced meanwhile are lost)."""
        self._stall_until = max(self._stall_until, time.monotonic() + duration_ms * 1e-3)

    def unplug(self) -> None:
        """Close the pty, as when the USB cable is pulled (the emulator then stops streaming)."""
        self._unplug.set()

    @property
    def unplugged(self) -> bool:
        return self._master is None and self.path is not None

    # ---- streaming -----------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while not self._stop.wait(self.period_s):
                now = time.monotonic()
                if self._unplug.is_set() or (self.unplug_at_s is not None and now - self._t0 >= self.unplug_at_s):
                    self.counts["unplug"] += 1
                    self._close()
                    return
                while self.stalls and now - self._t0 >= self.stalls[0][0]:
                    self.stall(self.stalls.pop(0)[1])
                with self.rt.lock:
                    frames = self.rt.rig.skin.read_available()
                if now < self._stall_until:  # the board stops scanning; bytes already queued still go out
                    self.counts["stalled_frames"] += len(frames)
                    self._flush()
                    continue
                for f in frames:
                    self._queue_frame(f)
                self._flush()
        except BaseException as exc:  # noqa: BLE001 - reported to the test or the CLI through `error`
            self.error = exc

    def _fault_for_next(self) -> str | None:
        with self._lock:
            if self._forced:
                return self._forced.popleft()
        return self._draw_fault()

    def _draw_fault(self) -> str | None:
        for kind in FAULT_KINDS:
            p = self.p[kind]
            if p > 0 and self.rng.random() < p:
                return kind
        return None

    def _queue_frame(self, f) -> None:
        if len(self._pending) > _MAX_PENDING_BYTES:
            self.counts["overflow_frames"] += 1  # nobody reads the port: the board's buffer is full
            return
        kind = self._fault_for_next()
        if kind == "drop_frame":
            self.counts[kind] += 1
            return
        data = bytearray(encode_frame(f.seq + self.seq_offset, f.device_t_ns // 1000, f.superficial, f.deep))
        if kind == "bit_flip":
            bit = int(self.rng.integers(FRAME_LEN * 8))
            data[bit // 8] ^= 1 << (bit % 8)
        elif kind == "drop_byte":
            del data[int(self.rng.integers(FRAME_LEN))]
        elif kind == "insert_garbage":
            n = int(self.rng.integers(1, self.garbage_max + 1))
            data[:0] = self.rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        if kind is None or kind == "insert_garbage":
            self.sent.append(f)  # the frame itself is intact
        if kind is not None:
            self.counts[kind] += 1
        self.counts["frames"] += 1
        self._pending += data

    def _flush(self) -> None:
        if not self._pending or self._master is None:
            return
        try:
            n = os.write(self._master, self._pending)
        except BlockingIOError:
            return
        del self._pending[:n]

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None
