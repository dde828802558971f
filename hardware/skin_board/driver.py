"""Driver of the skin readout board: frames streamed over a serial (USB CDC) link.

A receive thread reads whatever bytes the port has, feeds the shared FrameParser (resync after
garbage, CRC rejection) and turns the wire frames into TwoLayerFrames: sequence number and board
time unwrapped, `device_t_ns` = board µs * 1000, `host_t_ns` = time.monotonic_ns() when the
read returned. Sequence gaps count into `health.lost`, parser rejections into `health.corrupt`;
both are logged (the first at once, then at most one summary a second).

A stall is judged by the board's own clock, not by when the receive thread last ran: fault()
first drains what the OS holds for the port, then estimates when the newest frame was made on
the host clock (hardware.watchdog.DeviceClock: its board time plus the smallest host-minus-board
offset seen, which follows clock drift). A receive thread that was not scheduled while frames queued up in the OS is not a
silent board; a board that stopped scanning is reported once its newest frame is too old.

The board streams on its own once powered; the host never writes to it.
"""

from __future__ import annotations

import logging
import select
import threading
import time
from collections import deque

import serial

from hardware.interfaces import DeviceError, SkinReader
from hardware.serial_port import bytes_waiting, open_port
from hardware.skin_board.config import SkinBoardConfig
from hardware.skin_board.wire import VERSION, FrameParser, Unwrapper
from hardware.watchdog import DeviceClock
from layerskin_exp.config import SkinConfig
from layerskin_exp.types import TwoLayerFrame

log = logging.getLogger(__name__)

_LOG_EVERY_NS = 1_000_000_000
_REFILL_WAIT_S = 0.001
_FAULT_DRAINS = 8  # fault() reads on while each read fills a chunk (a backlog), this many chunks at most


class SkinBoardReader(SkinReader):
    """The two-layer readout board on a serial port.

    cfg: where the board is and the driver's timeouts. skin: the sensor's geometry and readout
    (frame period used to unwrap sequence numbers over long gaps; reported by calibration()).
    """

    def __init__(self, cfg: SkinBoardConfig, skin: SkinConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg
        self.skin = skin if skin is not None else SkinConfig()
        self.parser = FrameParser()
        self._unwrap = Unwrapper(self.skin.frame_period_ms * 1e3)
        self._ring: deque[TwoLayerFrame] = deque(maxlen=cfg.ring_frames)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._first_frame = threading.Event()
        self._thread: threading.Thread | None = None
        self._ser: serial.Serial | None = None
        self._last_seq: int | None = None
        self._board_clock = DeviceClock()  # when the board made its newest frame, on the host clock
        self._rx_lock = threading.Lock()  # one reader of the port at a time: bytes reach the parser in order
        self._link_error: str | None = None
        self._ever_connected = False
        self.bytes_received = 0
        # on_frames(frames) is called with each batch as it arrives (the rig's skin guards), in the
        # receive thread or in fault()'s caller when it drains the port; quick, never blocking.
        self.on_frames = None
        self.ring_dropped = 0  # frames dropped because read_available() was not called for too long
        self._reported = (0, 0, 0)  # lost, corrupt, ring_dropped at the last log line
        self._last_log_ns = 0

    # ---- Device ------------------------------------------------------------------------------
    def _connect(self) -> None:
        cfg = self.cfg
        if self._thread is not None:  # connect() again without disconnect(): start afresh
            self._shutdown()
        deadline = time.monotonic() + cfg.connect_timeout_s
        ser = self._open(deadline)
        # the unwrapper and the last seq carry over: frames missed while disconnected count as lost
        self.parser.reset()
        self._board_clock.reset()  # the board may have restarted its clock
        self._link_error = None
        self._first_frame.clear()
        self._stop.clear()
        self._ser = ser
        self._thread = threading.Thread(target=self._run, name="skin-board-rx", daemon=True)
        self._thread.start()
        if not self._first_frame.wait(max(0.0, deadline - time.monotonic())):
            why = self._link_error
            self._shutdown()
            p = self.parser
            raise DeviceError(
                f"skin board on {cfg.port}: no valid frame within {cfg.connect_timeout_s} s "
                f"({self.bytes_received} bytes read, {p.crc_failures} CRC failures, {p.bad_version} frames of "
                f"another protocol version{', ' + why if why else ''}); check that the board is powered and runs "
                f"protocol version {VERSION} firmware, and that {cfg.port} is the board")
        if self._ever_connected:
            self.health.reconnects += 1
        self._ever_connected = True
        log.info("skin board on %s streaming (first frame seq %s)", cfg.port, self._last_seq)

    def _open(self, deadline: float) -> serial.Serial:
        """Open the port, retrying while it is absent (USB still enumerating) until the deadline."""
        cfg = self.cfg
        while True:
            try:
                return open_port(cfg.port, cfg.baud, timeout=cfg.read_timeout_s, exclusive=True)
            except (serial.SerialException, OSError, ValueError) as exc:
                if time.monotonic() + 0.05 >= deadline:
                    raise DeviceError(
                        f"skin board: cannot open serial port {cfg.port} within {cfg.connect_timeout_s} s ({exc}); "
                        "check the USB cable, that the port exists (ls /dev/ttyACM*), that no other program "
                        "holds it, and that this user may open it (group dialout)") from exc
                time.sleep(0.05)

    def _disconnect(self) -> None:
        self._shutdown()

    def _shutdown(self) -> None:
        """Stop the receive thread and close the port; safe from any thread, bounded time."""
        self._stop.set()
        ser = self._ser
        if ser is not None:
            try:
                ser.cancel_read()
            except Exception:  # noqa: BLE001 - the port may already be gone
                pass
        t = self._thread
        if t is not None and t is not threading.current_thread():
            t.join(timeout=max(1.0, 10 * self.cfg.read_timeout_s))
        self._thread = None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: BLE001 - closing an unplugged port may fail; it is closed either way
                pass
        self._ser = None

    def fault(self, now_ns: int) -> str | None:
        if not self._connected:
            return None
        if self._link_error is not None:
            return f"skin: link lost ({self._link_error}) on {self.cfg.port}"
        silent_ns = self._board_clock.silent_ns(now_ns)
        if silent_ns is not None and silent_ns > self.cfg.stall_timeout_s * 1e9:
            for _ in range(_FAULT_DRAINS):  # frames the receive thread has not been scheduled to read yet
                if self._drain() < self.cfg.read_chunk_bytes:
                    break
            silent_ns = self._board_clock.silent_ns(now_ns)
            if silent_ns is not None and silent_ns > self.cfg.stall_timeout_s * 1e9:
                return (f"skin stalled: no frame for {silent_ns / 1e6:.0f} ms on {self.cfg.port} (board time of "
                        f"the newest frame, seq {self._last_seq}); check the board's power and USB link")
        return None

    # ---- SkinReader --------------------------------------------------------------------------
    def read_available(self) -> list[TwoLayerFrame]:
        self._require_connected()
        with self._lock:
            out = list(self._ring)
            self._ring.clear()
        return out

    def calibration(self) -> dict:
        s = self.skin
        return {"board_id": self.cfg.board_id, "backend": "lab", "n_taxels": s.n_taxels, "pitch_mm": s.pitch_mm,
                "electrode_mm": s.electrode_mm, "adc_bits": s.adc_bits, "frame_period_ms": s.frame_period_ms,
                "layers": list(s.layers), "port": self.cfg.port, "protocol_version": VERSION}

    # ---- receive thread ----------------------------------------------------------------------
    def _run(self) -> None:
        ser = self._ser
        while not self._stop.is_set():
            try:
                if self._wait_readable(ser):
                    self._drain(until_empty=False)
            except (serial.SerialException, OSError, TypeError, AttributeError, ValueError) as exc:
                if self._stop.is_set():
                    break  # closed by disconnect()
                self._link_error = f"{type(exc).__name__}: {exc}"
                log.error("skin board on %s: link lost: %s", self.cfg.port, self._link_error)
                break

    def _wait_readable(self, ser: serial.Serial) -> bool:
        """Block up to read_timeout_s for bytes (outside the read lock, so fault() may drain)."""
        return bool(select.select([ser.fileno()], [], [], self.cfg.read_timeout_s)[0])

    def _drain(self, until_empty: bool = True) -> int:
        """Read and parse what the OS holds for the port, without blocking; returns the bytes
        read (at most read_chunk_bytes). From the receive thread (until_empty=False, after select
        said readable: a readable port with nothing waiting is an unplugged one, whose read
        raises) or from fault() (errors left to the receive thread, which reports them)."""
        ser = self._ser
        if ser is None:
            return 0
        with self._rx_lock:
            data = b""
            try:
                # the tty layer hands over its buffer a few KiB at a time, refilling it just after a
                # read: after each read that found bytes, a short wait for the next part. A poll,
                # unlike the byte count, first hands the line discipline what the kernel's tty
                # buffer holds (its worker runs tens of ms late on a busy host): fault() asks that way.
                while len(data) < self.cfg.read_chunk_bytes:
                    waiting = bytes_waiting(ser)
                    if not waiting and (data or until_empty) and select.select(
                            [ser.fileno()], [], [], _REFILL_WAIT_S if data else 0)[0]:
                        waiting = bytes_waiting(ser)
                    if waiting:
                        data += ser.read(min(waiting, self.cfg.read_chunk_bytes - len(data)))
                    elif not data and not until_empty and select.select([ser.fileno()], [], [], 0)[0]:
                        data = ser.read(1)  # readable yet empty: raises on an unplugged port
                    else:
                        break
            except (serial.SerialException, OSError, TypeError, AttributeError, ValueError):
                if not until_empty:
                    if data:
                        self._receive(data, time.monotonic_ns())
                    raise
            if data:
                self._receive(data, time.monotonic_ns())
            return len(data)

    def _receive(self, data: bytes, host_ns: int) -> None:
        self.bytes_received += len(data)
        wire = self.parser.feed(data)
        self.health.corrupt = self.parser.corrupt
        if wire:
            frames = []
            for w in wire:
                seq, t_us = self._unwrap(w.seq, w.device_t_us)
                frames.append(TwoLayerFrame(w.superficial, w.deep, seq, t_us * 1000, host_ns))
            self._last_seq = self.health.observe_seqs(self._last_seq, [f.seq for f in frames])
            with self._lock:
                overflow = len(self._ring) + len(frames) - self.cfg.ring_frames
                self._ring.extend(frames)  # a bounded deque: the oldest frames go first
            if overflow > 0:
                self.ring_dropped += overflow
            self._board_clock.observe(frames[-1].device_t_ns, host_ns)
            self._first_frame.set()
            if self.on_frames is not None:
                self.on_frames(frames)
        self._log_health(host_ns)

    def _log_health(self, now_ns: int) -> None:
        """One warning for new gaps/corruption: at once after a quiet second, else once a second."""
        now = (self.health.lost, self.health.corrupt, self.ring_dropped)
        if now == self._reported or now_ns - self._last_log_ns < _LOG_EVERY_NS:
            return
        lost, corrupt, dropped = (a - b for a, b in zip(now, self._reported, strict=True))
        p = self.parser
        log.warning("skin board on %s: %d frames lost (sequence gaps), %d corrupt (CRC failures %d, resyncs %d, "
                    "%d bytes skipped so far)%s; last seq %s", self.cfg.port, lost, corrupt, p.crc_failures,
                    p.resyncs, p.skipped_bytes,
                    f", {dropped} frames dropped from a full buffer (read_available not called)" if dropped else "",
                    self._last_seq)
        self._reported = now
        self._last_log_ns = now_ns
