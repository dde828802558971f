"""Emulator of the skin readout board on a serial line (a pty, or loopback TCP), backed by the simulated world.

The board runs in a process of its own (`hardware.skin_board.board`, which says why and how it
scans): it owns the pty, scans on its own clock and writes each frame, encoded with the shared
wire module; the driver opens the slave path that start() returns, as it would /dev/ttyACM0.
The world stays in this process: a bridge thread drains the skin twin (`rt.rig.skin.
read_available()` under `rt.lock`) every `period_s` and sends the twin frames to the board,
which writes each one once at its scan (or the newest again while the world is behind). The wire
sequence number is the board's scan count (+ seq_offset) modulo 2**16, board time the world's
time at power-on plus the scan count times the frame period, in µs modulo 2**32.

The board streams only while a host has the port open, as a USB CDC device whose host side is
not reading: frames made while the port is closed are lost, and what a host left unread is
forgotten when it closes the port, so opening the port delivers what the board sends now. Bytes
the host writes are read and discarded (the board takes no commands).

Faults (hardware.emulation's vocabulary), drawn per frame in the board process from a numpy
Generator seeded with `seed`, or scheduled with drop(n) / corrupt(n, how) / schedule(...):
  p_bit_flip        corrupt "bit_flip": one random bit flipped (the driver rejects it: corrupt, lost)
  p_drop_byte       corrupt "drop_byte": one random byte left out (corrupt, lost)
  p_insert_garbage  corrupt "insert_garbage": 1..garbage_max random bytes before the frame (corrupt)
  p_drop_frame      drop: the frame not sent, as when the board's TX buffer overflows (lost)
  stalls            ((at_s, duration_ms), ...) after start(): nothing written meanwhile; the
                    frames of a stall are lost (also stall(duration_s); in force when it returns)
  disconnect_after_s / disconnect()  the pty closes (the driver's link is lost; the port vanishes)
`sent` keeps the latest frames written intact (as the board sent them: seq without seq_offset,
board time); `counts` what was written, injected, lost, held and skipped (the board's read-out,
every 10 ms). The board's log lines go to this process's log (the run's log).
"""

from __future__ import annotations

import logging
import time
from collections import Counter, deque

from hardware.emulation import DeviceProcess, Emulator, check_serial_link
from hardware.interfaces import DeviceError
from hardware.skin_board.board import CORRUPTIONS
from layerskin_exp.types import TwoLayerFrame

log = logging.getLogger(__name__)

EMULATOR_SETUP = "platform"

START_TIMEOUT_S = 20.0
_TWIN_KEEP = 8192  # twin frames kept to fill `sent` from the board's read-out


class SkinBoardEmulator(Emulator):
    """The readout board's serial stream on a pty, served by the board's own process.

    rt: a started RealtimeWorld whose rig has a skin twin. host, port: unused (a pty has no
    network address; accepted so every emulator is built the same way). period_s: how often the
    twin is drained. seq_offset: added to the board's seq before it wraps to 16 bits (to reach
    the wrap quickly). sent_maxlen: how many intact frames `sent` remembers (4096: ~10 s of
    frames, what a test compares against; a bound, so a long run does not grow). link: "pty" (a
    port path, as /dev/ttyACM0) or "tcp" (a socket:// URL: the loopback bench's, where a pty's
    bytes would wait for a kernel worker that a busy host runs late; hardware.emulation.TcpSerialLink).
    """

    DEVICE = "skin_board"
    TWINS = ("skin",)
    CORRUPTIONS = CORRUPTIONS

    def __init__(self, rt, host: str | None = None, port: int | None = None, *, seed: int = 0,
                 p_bit_flip: float = 0.0, p_drop_byte: float = 0.0, p_insert_garbage: float = 0.0,
                 p_drop_frame: float = 0.0, garbage_max: int = 64, stalls: tuple = (),
                 period_s: float = 0.0015, seq_offset: int = 0, sent_maxlen: int = 4096,
                 stall_after_s: float | None = None, disconnect_after_s: float | None = None,
                 link: str = "pty") -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        check_serial_link(link, "skin board")
        self.link = link
        for name, p in (("p_bit_flip", p_bit_flip), ("p_drop_byte", p_drop_byte),
                        ("p_insert_garbage", p_insert_garbage), ("p_drop_frame", p_drop_frame)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name}={p!r}: must be a probability 0..1")
        if garbage_max < 1:
            raise ValueError(f"garbage_max={garbage_max!r}: must be >= 1 byte")
        if not period_s > 0:
            raise ValueError(f"period_s={period_s!r}: must be > 0 s")
        self.seed = int(seed)
        self.p = {"bit_flip": p_bit_flip, "drop_byte": p_drop_byte, "insert_garbage": p_insert_garbage}
        self.p_drop_frame = float(p_drop_frame)
        self.garbage_max = int(garbage_max)
        self.stalls = sorted((float(at), float(ms)) for at, ms in stalls)
        self.period_s = float(period_s)
        self.seq_offset = int(seq_offset)
        self.sent: deque = deque(maxlen=sent_maxlen)  # TwoLayerFrames written intact, as the board sent them
        self.counts: Counter = Counter()  # the board's read-out: frames written, faults, frames lost
        self.path: str | None = None
        self._board: DeviceProcess | None = None
        self._twin: dict[int, TwoLayerFrame] = {}
        self._twin_order: deque = deque()
        self._info: dict = {}

    # ---- life cycle ------------------------------------------------------------------------
    def _open(self) -> str:
        """Start the board process and the bridge; returns the pty path once it serves."""
        with self.rt.lock:
            self.rt.rig.skin.read_available()  # start with fresh frames
            t0_us = int(round(self.rt.world.t_s * 1e6))
            period_s = self.rt.world.skin_cfg.frame_period_ms * 1e-3
        opts = {"frame_period_s": period_s, "seq_offset": self.seq_offset, "seed": self.seed, "p": self.p,
                "p_drop_frame": self.p_drop_frame, "garbage_max": self.garbage_max,
                "stalls": self.stalls, "t0_us": t0_us, "link": self.link}
        self._board = DeviceProcess("hardware.skin_board.board", opts, self.DEVICE, log)
        self.path = self._serve_device(self._board, START_TIMEOUT_S)
        return self.path

    def _close(self) -> None:
        if self._board is not None:
            self._board.close()
            self._board = None

    @property
    def unplugged(self) -> bool:
        return bool(self._info.get("disconnected"))

    # ---- faults: carried out by the board process ---------------------------------------------
    def _on_stall(self, stalled: bool) -> None:
        """Stall or resume the board and wait until it has taken it (a driver that connects after
        stall() returns finds the board silent)."""
        if self._board is None:
            return
        if stalled:
            left = self._stall_until - time.monotonic()
            self._send(("stall", None if left == float("inf") else max(left, 0.0)))
        else:
            self._send(("resume",))
        self._board.wait_ack("stall", lambda v: v == stalled)

    def _on_disconnect(self) -> None:
        if self._board is not None:
            self._send(("disconnect",))

    SCHEDULED_KEY = "planned"

    def _device(self) -> DeviceProcess | None:
        return self._board

    # ---- bridge ----------------------------------------------------------------------------------
    def _send(self, msg: tuple) -> None:
        if self._board is None:
            raise DeviceError("skin board emulator: not started")
        self._board.send(msg)

    def _bridge(self) -> None:
        board = self._board
        try:
            while not self._stop.is_set():
                board.poll(self.period_s, lambda msg: self._readout(*msg[1:-1]))
                if board.ready.is_set() and board.error is None:
                    with self.rt.lock:
                        frames = self.rt.rig.skin.read_available()
                    if frames:
                        for f in frames:
                            self._twin[f.seq] = f
                            self._twin_order.append(f.seq)
                        while len(self._twin_order) > _TWIN_KEEP:
                            self._twin.pop(self._twin_order.popleft(), None)
                        board.send(("frames", [(f.seq, f.superficial, f.deep) for f in frames]))
        except (EOFError, OSError) as exc:
            if not self._stop.is_set():
                log.warning("skin board emulator: the board process went away (%s)", exc)
                self.error = self.error or exc
                board.went_away(exc)

    def _readout(self, counts, fault_counts, planned, sent, stalled, disconnected) -> None:
        for k, t_us, twin_seq in sent:
            twin = self._twin.get(twin_seq)
            if twin is not None:
                self.sent.append(TwoLayerFrame(twin.superficial, twin.deep, k, t_us * 1000, 0))
        self.counts = Counter(counts)
        for k in ("drop", "corrupt"):  # drawn in the board; stall and disconnect are counted here
            if fault_counts.get(k):
                self.fault_counts[k] = fault_counts[k]
        self._info = {"planned": planned, "stalled": stalled, "disconnected": disconnected}
