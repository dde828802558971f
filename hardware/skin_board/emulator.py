"""Emulator of the skin readout board on a pseudo-terminal, backed by the simulated world.

A thread drains the skin twin (`rt.rig.skin.read_available()` under `rt.lock`) every
`period_s` and writes each frame, encoded with the shared wire module, to the pty master; the
driver opens the slave path that start() returns, as it would /dev/ttyACM0. The wire sequence
number is the twin's seq (+ seq_offset) modulo 2**16, board time the twin's device_t_ns in µs
modulo 2**32.

The board streams only while a host has the port open, as a USB CDC device whose host side is
not reading: frames made while the port is closed are lost, and what a host left unread is
forgotten when it closes the port, so opening the port delivers what the board sends now. Bytes
the host writes are read and discarded (the board takes no commands).

Faults (hardware.emulation's vocabulary), drawn per frame from a numpy Generator seeded with
`seed`, or scheduled with drop(n) / corrupt(n, how) / schedule(...):
  p_bit_flip        corrupt "bit_flip": one random bit flipped (the driver rejects it: corrupt, lost)
  p_drop_byte       corrupt "drop_byte": one random byte left out (corrupt, lost)
  p_insert_garbage  corrupt "insert_garbage": 1..garbage_max random bytes before the frame (corrupt)
  p_drop_frame      drop: the frame not sent, as when the board's TX buffer overflows (lost)
  stalls            ((at_s, duration_ms), ...) after start(): nothing written meanwhile; the
                    frames produced during a stall are lost (also stall(duration_s))
  disconnect_after_s / disconnect()  the pty closes (the driver's link is lost; the port vanishes)
`sent` keeps the latest frames written intact; `counts` what was written, injected and lost.
"""

from __future__ import annotations

import time
from collections import Counter, deque

import numpy as np

from hardware.emulation import Emulator, Pty
from hardware.skin_board.wire import FRAME_LEN, encode_frame

EMULATOR_SETUP = "platform"

CORRUPTIONS = ("bit_flip", "drop_byte", "insert_garbage")
_MAX_PENDING_BYTES = 512 * FRAME_LEN  # beyond this (the host not reading) whole frames are dropped; room for the world catching up in a burst


class SkinBoardEmulator(Emulator):
    """The readout board's serial stream on a pty.

    rt: a started RealtimeWorld whose rig has a skin twin. host, port: unused (a pty has no
    network address; accepted so every emulator is built the same way). period_s: how often the
    twin is drained. seq_offset: added to the twin's seq before it wraps to 16 bits (to reach
    the wrap quickly). sent_maxlen: how many intact frames `sent` remembers (4096: ~10 s of
    frames, what a test compares against; a bound, so a long run does not grow).
    """

    DEVICE = "skin_board"
    TWINS = ("skin",)
    CORRUPTIONS = CORRUPTIONS

    def __init__(self, rt, host: str | None = None, port: int | None = None, *, seed: int = 0,
                 p_bit_flip: float = 0.0, p_drop_byte: float = 0.0, p_insert_garbage: float = 0.0,
                 p_drop_frame: float = 0.0, garbage_max: int = 64, stalls: tuple = (),
                 period_s: float = 0.0015, seq_offset: int = 0, sent_maxlen: int = 4096,
                 stall_after_s: float | None = None, disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        for name, p in (("p_bit_flip", p_bit_flip), ("p_drop_byte", p_drop_byte),
                        ("p_insert_garbage", p_insert_garbage), ("p_drop_frame", p_drop_frame)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name}={p!r}: must be a probability 0..1")
        if garbage_max < 1:
            raise ValueError(f"garbage_max={garbage_max!r}: must be >= 1 byte")
        if not period_s > 0:
            raise ValueError(f"period_s={period_s!r}: must be > 0 s")
        self.rng = np.random.default_rng(seed)
        self.p = {"bit_flip": p_bit_flip, "drop_byte": p_drop_byte, "insert_garbage": p_insert_garbage}
        self.p_drop_frame = float(p_drop_frame)
        self.garbage_max = int(garbage_max)
        self.stalls = sorted((float(at), float(ms)) for at, ms in stalls)
        self.period_s = float(period_s)
        self.seq_offset = int(seq_offset)
        self.sent: deque = deque(maxlen=sent_maxlen)  # TwoLayerFrames of the twin written intact
        self.counts: Counter = Counter()  # frames written, faults injected, frames lost (stall, overflow, no host)
        self.path: str | None = None
        self.pty: Pty | None = None
        self._pending = bytearray()
        self._t0 = 0.0

    # ---- life cycle ------------------------------------------------------------------------
    def _open(self) -> str:
        self.pty = Pty()
        self.path = self.pty.path
        with self.rt.lock:
            self.rt.rig.skin.read_available()  # start with fresh frames
        self._t0 = time.monotonic()
        self._spawn(self._run, "stream")
        return self.path

    def _close(self) -> None:
        if self.pty is not None:
            self.pty.close()

    @property
    def unplugged(self) -> bool:
        return self.pty is not None and self.pty.closed

    # ---- streaming -----------------------------------------------------------------------------
    def _run(self) -> None:
        pty = self.pty
        attached = False
        while not self._stop.wait(self.period_s):
            now = time.monotonic()
            if self.disconnected:
                self.counts["unplug"] += 1
                pty.close()
                return
            while self.stalls and now - self._t0 >= self.stalls[0][0]:
                self.stall(self.stalls.pop(0)[1] * 1e-3)
            with self.rt.lock:
                frames = self.rt.rig.skin.read_available()
            if not pty.host_attached():
                if attached:  # the host closed the port: what it left unread is gone
                    pty.forget_unread()
                    self._pending.clear()
                    attached = False
                self.counts["no_host_frames"] += len(frames)
                continue
            if not attached:
                self.counts["host_opens"] += 1
                attached = True
            self.counts["host_bytes"] += len(pty.read())  # the board takes no commands: discarded
            if self.stalled:  # the board stops scanning; bytes already queued still go out
                self.counts["stalled_frames"] += len(frames)
                self._flush()
                continue
            for f in frames:
                self._queue_frame(f)
            self._flush()

    def _draw_fault(self):
        for how in CORRUPTIONS:
            p = self.p[how]
            if p > 0 and self.rng.random() < p:
                return ("corrupt", how)
        if self.p_drop_frame > 0 and self.rng.random() < self.p_drop_frame:
            return ("drop", None)
        return None

    def _queue_frame(self, f) -> None:
        if len(self._pending) > _MAX_PENDING_BYTES:
            self.counts["overflow_frames"] += 1  # the host does not read the port: the board's buffer is full
            return
        fault = self._next_fault()
        if fault is not None and fault[0] == "drop":
            self.counts["drop_frame"] += 1
            return
        how = None if fault is None else fault[1]
        data = bytearray(encode_frame(f.seq + self.seq_offset, f.device_t_ns // 1000, f.superficial, f.deep))
        if how == "bit_flip":
            bit = int(self.rng.integers(FRAME_LEN * 8))
            data[bit // 8] ^= 1 << (bit % 8)
        elif how == "drop_byte":
            del data[int(self.rng.integers(FRAME_LEN))]
        elif how == "insert_garbage":
            n = int(self.rng.integers(1, self.garbage_max + 1))
            data[:0] = self.rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        if how is None or how == "insert_garbage":
            self.sent.append(f)  # the frame itself is intact
        if how is not None:
            self.counts[how] += 1
        self.counts["frames"] += 1
        self._pending += data

    def _flush(self) -> None:
        if self._pending:
            del self._pending[:self.pty.write(self._pending)]
