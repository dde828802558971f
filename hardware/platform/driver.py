"""GRBL 1.1 driver for the three-axis platform (pyserial).

Threads: a reader parses every line GRBL sends (responses, status reports, alarms, banners,
feedback); a poller writes `?` at `status_rate_hz`. Every status report becomes one
StagePosition. GRBL has no clock of its own to report, so `device_t_ns` is the host receive
time (the same value as `host_t_ns`); GRBL answers `?` within ~5-20 ms on real hardware, which
bounds how stale a position can be.

Lines are streamed by character counting: GRBL's receive buffer holds 128 bytes and a line's
bytes stay there (as far as the host knows) until its `ok`/`error:N` arrives, so a line is only
written when it fits. Real-time bytes (`?`, `!`, Ctrl-X) bypass that buffer and are written at
any time, from any thread, under the same write lock as lines.

stop(): feed hold `!` decelerates along the path without losing steps (GRBL's Hold:1 -> Hold:0).
Held, GRBL would resume the rest of the move, and any queued moves, on `~` or on the next
auto cycle start; so once a status shows Hold:0 the reader sends a soft reset (Ctrl-X), which
flushes the planner and receive buffer. A reset from Hold:0 (or Idle) keeps the position and
raises no alarm; only a reset while the axes still move raises ALARM:3 (position lost), which
is why the reset waits for Hold:0.

is_moving(): from the latest status (Run/Jog/Home/Hold:1 moving; Idle/Hold:0 not), except that a
move just commanded counts as moving until a status shows motion, or until its `ok` arrived and
two later statuses show Idle (a zero-length or instantly finished move): right after move_to
the status may still say Idle.

Stall: GRBL's reports carry no clock, so a stall is judged by its answers to `?`
(hardware.watchdog.ReplyWatch): silence counts only while a query has gone unanswered for
longer than the bound less one poll period, and fault() first reads what the OS holds for the
port (a status report may sit there unread while the reader thread is not scheduled). A poller
the host did not run leaves no query unanswered: that is a busy host, not a silent GRBL.

The port is opened with pyserial's `serial_for_url`: a device path (/dev/ttyUSB0, a pty) or a
URL such as socket://HOST:PORT (a serial device server, a networked GRBL such as Grbl_ESP32; the
loopback bench serves GRBL this way, see hardware.emulation.TcpSerialLink).
"""

from __future__ import annotations

import logging
import select
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from hardware.interfaces import DeviceError, Platform
from hardware.platform import wire
from hardware.platform.config import GrblPlatformConfig
from hardware.serial_port import bytes_waiting, open_port
from hardware.watchdog import ReplyWatch
from layerskin_exp.types import StagePosition

log = logging.getLogger(__name__)

_UNLOCK_MSG = "'$H'|'$X' to unlock"


@dataclass
class _Line:
    """A line in GRBL's receive buffer, awaiting its response."""

    text: str
    nbytes: int
    move_id: int = 0  # > 0 for move lines
    done: threading.Event = field(default_factory=threading.Event)
    result: object = None  # wire.Ok | wire.Error | str (why it will never be answered)


class GrblPlatform(Platform):
    """The platform behind a GRBL 1.1 controller. Positions in the skin frame, mm."""

    def __init__(self, cfg: GrblPlatformConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self._ser = None
        self._write_lock = threading.Lock()  # every byte written to the port
        self._send_lock = threading.Lock()  # one line sender at a time (keeps FIFO = counter order)
        self._rx_lock = threading.Lock()  # one reader of the port at a time: lines in order
        self._cv = threading.Condition()  # guards the state below
        self._stop_threads = threading.Event()
        self._threads: list[threading.Thread] = []
        self._offset = np.asarray(cfg.offset_mm, float)
        self.settings: dict[int, str] = {}  # `$N=value` lines seen (after a `$$`)
        self._reset_link_state()

    def _reset_link_state(self) -> None:
        self._counter = wire.CharCounter(self.cfg.rx_buffer_bytes)
        self._inflight: deque[_Line] = deque()
        self._splitter = wire.LineSplitter()
        self._buf: deque[StagePosition] = deque()
        self._seq = 0
        self._status: wire.Status | None = None
        # answers to `?`: silence counts once a query waits longer than the bound less a poll period
        self._replies = ReplyWatch((self.cfg.stall_timeout_s - 1.0 / self.cfg.status_rate_hz) * 1e9)
        self._wco = np.zeros(3)
        self._banners = 0
        self._version = ""
        self._connecting = False
        self._expected_resets = 0
        self._resetting = False  # our Ctrl-X is out, its banner not yet in
        self._alarm_locked = False
        self._link_error: str | None = None
        self._device_fault: str | None = None
        self._stop_ns: int | None = None  # feed hold sent, reset not yet
        self._move_id = 0
        self._pending_move = False
        self._move_acked = False
        self._idle_after_ack = 0
        self._recent: deque[str] = deque(maxlen=5)

    # ---- life cycle ----------------------------------------------------------------------------
    def _connect(self) -> None:
        import serial  # pyserial

        cfg = self.cfg
        self._reset_link_state()
        try:
            self._ser = open_port(cfg.port, cfg.baudrate, timeout=0.005, write_timeout=0.5)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceError(f"platform: cannot open the GRBL serial port {cfg.port!r} ({exc}); check the USB "
                              "cable, that the port exists, and that no other program (a G-code sender) holds it") from exc
        self._stop_threads.clear()
        self._connecting = True
        self._threads = [threading.Thread(target=self._read_loop, name="grbl-reader", daemon=True)]
        self._threads[0].start()
        try:
            self._handshake()
        except BaseException:
            self._close()
            raise
        self._connecting = False

    def _handshake(self) -> None:
        cfg = self.cfg
        deadline = time.monotonic() + cfg.connect_timeout_s
        # Opening the port resets an Arduino (DTR); a soft reset wakes any other board. Either
        # prints the welcome banner once GRBL has (re)initialised.
        with self._cv:
            self._expected_resets += 1
        self._write(wire.SOFT_RESET)
        if not self._wait(lambda: self._banners > 0 or self._link_error, deadline):
            raise DeviceError(f"platform: no GRBL welcome banner on {cfg.port} within {cfg.connect_timeout_s} s "
                              f"(received: {list(self._recent) or 'nothing'}); check the baud rate "
                              f"({cfg.baudrate}; GRBL 1.1 uses 115200), power, and that the board runs GRBL 1.1")
        self._raise_link_error()
        if not self._version.startswith("1.1"):
            raise DeviceError(f"platform: {cfg.port} runs Grbl {self._version}; this driver speaks the GRBL 1.1 dialect")
        poller = threading.Thread(target=self._poll_loop, name="grbl-status", daemon=True)
        self._threads.append(poller)
        poller.start()
        if not self._wait(lambda: self._status is not None or self._link_error, deadline):
            raise DeviceError(f"platform: GRBL on {cfg.port} sent its banner but no status report to '?' within "
                              f"{cfg.connect_timeout_s} s")
        self._raise_link_error()
        if self._status.state == "Alarm" or self._alarm_locked:
            if not cfg.unlock_alarm:
                raise DeviceError(f"platform: GRBL on {cfg.port} starts in alarm (homing required, or a limit or reset "
                                  "during motion); home it with $H, or set hardware.platform.unlock_alarm=true to "
                                  "unlock with $X when the position is known to be right")
            self._command("$X")
            with self._cv:
                self._alarm_locked = False
                self._device_fault = None
        self._command("G21G90")

    def _disconnect(self) -> None:
        self._close()

    def _close(self) -> None:
        self._stop_threads.set()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout=2.0)
        self._threads = []
        if self._ser is not None:
            try:
                self._ser.close()
            except Exception:  # noqa: BLE001 - closing a dead port
                pass
            self._ser = None

    # ---- Platform interface ----------------------------------------------------------------------
    def move_to(self, target_mm: np.ndarray, speed_mm_s: float) -> None:
        """Start a straight feed move (G1) to target (3,) skin-frame mm at speed mm/s; returns once
        the line is written (GRBL plans it and answers `ok`; errors surface through fault())."""
        self._require_connected()
        target = np.asarray(target_mm, dtype=float).reshape(-1)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise DeviceError(f"platform: target {target_mm!r} must be three finite values (x, y, z mm)")
        if not (np.isfinite(speed_mm_s) and speed_mm_s > 0):
            raise DeviceError(f"platform: speed {speed_mm_s!r} mm/s must be finite and > 0")
        reason = self._blocking_fault()
        if reason:
            raise DeviceError(f"{reason}; cannot start a move")
        line = wire.encode_move(target - self._offset, float(speed_mm_s) * 60.0)
        with self._cv:
            self._move_id += 1
            move_id = self._move_id
            self._pending_move, self._move_acked, self._idle_after_ack = True, False, 0
        try:
            self._send_line(line, move_id)
        except DeviceError:
            with self._cv:
                if self._move_id == move_id:
                    self._pending_move = False
            raise

    def stop(self) -> None:
        """Feed hold now; the reader soft-resets once the hold completes. Never blocks on GRBL."""
        self._require_connected()
        with self._cv:
            if self._stop_ns is None:
                self._stop_ns = time.monotonic_ns()
            self._pending_move = False
        self._write(wire.FEED_HOLD)

    def is_moving(self) -> bool:
        self._require_connected()
        with self._cv:
            if self._pending_move or self._stop_ns is not None or self._resetting:
                return True
            return self._status is not None and self._status.moving

    def read_available(self) -> list[StagePosition]:
        self._require_connected()
        with self._cv:
            out = list(self._buf)
            self._buf.clear()
        return out

    def fault(self, now_ns: int) -> str | None:
        if self._connected and (self._replies.silent_ns(now_ns) or 0) > self.cfg.stall_timeout_s * 1e9:
            self._drain()  # status reports the reader thread has not been scheduled to read yet
        with self._cv:
            if self._link_error:
                return self._link_error
            if self._device_fault:
                return self._device_fault
            if self._stop_ns is not None and now_ns - self._stop_ns > self.cfg.stop_timeout_s * 1e9:
                state = self._status_text()
                return f"platform: feed hold not complete {self.cfg.stop_timeout_s} s after stop() (GRBL state {state})"
            silent_ns = self._replies.silent_ns(now_ns)
            if self._connected and silent_ns is not None and silent_ns > self.cfg.stall_timeout_s * 1e9:
                return (f"platform stalled: no status report for {silent_ns / 1e6:.0f} ms (a '?' unanswered; "
                        f"last state {self._status_text()}); check GRBL's power and USB link")
        return None

    # ---- extras ----------------------------------------------------------------------------------
    @property
    def state(self) -> str:
        """GRBL's machine state from the latest status report ("Idle", "Run", "Hold:0", ...)."""
        with self._cv:
            return self._status_text()

    @property
    def in_flight_bytes(self) -> int:
        """Bytes of unanswered lines in GRBL's receive buffer, as the host counts them."""
        with self._cv:
            return self._counter.outstanding

    def wait_acknowledged(self, timeout_s: float | None = None) -> None:
        """Block until every line sent so far is answered; DeviceError on error/alarm/timeout."""
        timeout_s = self.cfg.command_timeout_s if timeout_s is None else timeout_s
        with self._cv:
            last = self._inflight[-1] if self._inflight else None
        if last is not None:
            self._await(last, timeout_s)

    def recover(self, unlock: bool | None = None) -> None:
        """Clear a latched error or alarm: soft reset (flushes everything) and, if GRBL comes back
        locked and `unlock` (default: config unlock_alarm) allows it, `$X`. Blocks up to
        command_timeout_s per step."""
        self._require_connected()
        unlock = self.cfg.unlock_alarm if unlock is None else unlock
        self._soft_reset()
        deadline = time.monotonic() + self.cfg.command_timeout_s
        if not self._wait(lambda: not self._resetting or self._link_error, deadline):
            raise DeviceError(f"platform: no GRBL banner within {self.cfg.command_timeout_s} s of a soft reset")
        self._raise_link_error()
        n0 = self._seq
        self._wait(lambda: self._seq > n0 or self._link_error, time.monotonic() + self.cfg.command_timeout_s)
        with self._cv:
            locked = self._alarm_locked or (self._status is not None and self._status.state == "Alarm")
        if locked:
            if not unlock:
                raise DeviceError("platform: GRBL is in alarm after the reset; home it ($H) or recover(unlock=True)")
            self._command("$X")
        with self._cv:
            self._alarm_locked = False
            self._device_fault = None
            self._stop_ns = None

    # ---- sending ---------------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        ser = self._ser
        if ser is None:
            raise DeviceError("platform: port closed")
        try:
            with self._write_lock:
                ser.write(data)
        except Exception as exc:  # noqa: BLE001 - SerialException, SerialTimeoutException, OSError
            self._lose_link(f"write failed: {exc}")
            raise DeviceError(self._link_error) from exc

    def _send_line(self, data: bytes, move_id: int = 0) -> _Line:
        """Write one line once it fits GRBL's receive buffer (character counting)."""
        n = len(data)
        entry = _Line(data.decode("ascii").strip(), n, move_id)
        deadline = time.monotonic() + self.cfg.command_timeout_s
        with self._send_lock:
            with self._cv:
                while self._resetting or not self._counter.fits(n):
                    if self._link_error:
                        raise DeviceError(self._link_error)
                    remaining = deadline - time.monotonic()
                    if remaining <= 0:
                        why = "a soft reset is not complete" if self._resetting else (
                            f"{self._counter.outstanding} of {self._counter.capacity} bytes in flight, unanswered: "
                            f"{[e.text for e in self._inflight]}")
                        raise DeviceError(f"platform: no room in GRBL's receive buffer for {entry.text!r} within "
                                          f"{self.cfg.command_timeout_s} s ({why}); is GRBL still answering?")
                    self._cv.wait(remaining)
                self._counter.sent(n)
                self._inflight.append(entry)
            self._write(data)
        return entry

    def _command(self, text: str) -> None:
        """Send a line and wait for its `ok`; DeviceError naming error:N otherwise."""
        self._await(self._send_line(wire.encode_line(text)), self.cfg.command_timeout_s)

    def _await(self, entry: _Line, timeout_s: float) -> None:
        if not entry.done.wait(timeout_s):
            raise DeviceError(f"platform: GRBL did not answer {entry.text!r} within {timeout_s} s")
        if isinstance(entry.result, wire.Error):
            raise DeviceError(f"platform: GRBL rejected {entry.text!r} with {entry.result}")
        if isinstance(entry.result, str):
            raise DeviceError(f"platform: {entry.text!r} was not executed: {entry.result}")

    def _soft_reset(self) -> None:
        with self._cv:
            self._expected_resets += 1
            self._resetting = True
            self._stop_ns = None
        self._write(wire.SOFT_RESET)

    # ---- receiving -------------------------------------------------------------------------------
    def _read_loop(self) -> None:
        ser = self._ser
        while not self._stop_threads.is_set():
            try:
                if self._wait_readable(ser):
                    self._drain(from_reader=True)
            except Exception as exc:  # noqa: BLE001 - SerialException / OSError: the port went away
                if not self._stop_threads.is_set():
                    self._lose_link(f"read failed: {exc}")
                return

    def _wait_readable(self, ser) -> bool:
        """Block up to 5 ms for bytes (outside the read lock, so fault() may drain)."""
        return bool(select.select([ser.fileno()], [], [], 0.005)[0])

    def _drain(self, from_reader: bool = False) -> None:
        """Read and handle what the OS holds for the port. From the reader (after select said
        readable: a readable port with nothing waiting is an unplugged one, whose read raises)
        or from fault() (without blocking; errors left to the reader, which reports them)."""
        ser = self._ser
        if ser is None:
            return
        with self._rx_lock:
            try:
                waiting = bytes_waiting(ser)
                if not waiting and not from_reader:
                    # a poll hands the line discipline what the kernel's tty buffer still holds (the
                    # byte count does not): under load its worker moves bytes tens of ms late
                    if select.select([ser.fileno()], [], [], 0)[0]:
                        waiting = bytes_waiting(ser)
                    if not waiting:
                        return
                data = ser.read(max(1, waiting))
            except Exception:  # noqa: BLE001 - the reader reports a lost port
                if from_reader:
                    raise
                return
            if not data:
                return
            host_ns = time.monotonic_ns()
            overlong = self._splitter.overlong
            for line in self._splitter.feed(data):
                self._handle(line, host_ns)
            if self._splitter.overlong != overlong:
                self.health.corrupt += self._splitter.overlong - overlong
                log.warning("platform: dropped %d byte run(s) without a line end", self._splitter.overlong - overlong)

    def _poll_loop(self) -> None:
        period = 1.0 / self.cfg.status_rate_hz
        next_t = time.monotonic()
        while not self._stop_threads.wait(max(0.0, next_t - time.monotonic())):
            next_t += period
            if next_t < time.monotonic():
                next_t = time.monotonic() + period
            sending_ns = time.monotonic_ns()
            try:
                self._write(wire.STATUS_QUERY)
            except DeviceError:
                return
            # asked once the byte is on its way: a poller descheduled before writing asked nothing yet;
            # a report the reader took since sending began answered it (or a later '?')
            self._replies.asked(time.monotonic_ns(), sending_ns)

    def _handle(self, line: str, host_ns: int) -> None:
        self._recent.append(line)
        try:
            msg = wire.parse_line(line)
        except wire.GrblParseError as exc:
            self.health.corrupt += 1
            log.warning("platform: %s", exc)
            return
        if isinstance(msg, wire.Status):
            self._on_status(msg, host_ns)
        elif isinstance(msg, (wire.Ok, wire.Error)):
            self._on_response(msg)
        elif isinstance(msg, wire.Alarm):
            self._on_alarm(msg)
        elif isinstance(msg, wire.Banner):
            self._on_banner(msg)
        elif isinstance(msg, wire.Feedback):
            log.info("platform: GRBL [%s:%s]", msg.kind, msg.text)
            if msg.kind == "MSG" and msg.text == _UNLOCK_MSG:
                with self._cv:
                    self._alarm_locked = True
        elif isinstance(msg, wire.Setting):
            self.settings[msg.number] = msg.value
        else:
            log.info("platform: GRBL %s", msg)

    def _on_status(self, st: wire.Status, host_ns: int) -> None:
        scale = self.cfg.mm_per_unit
        if st.wco is not None:
            self._wco = np.asarray(st.wco, float)
        mpos = np.asarray(st.mpos, float) if st.mpos is not None else np.asarray(st.wpos, float) + self._wco
        pos = mpos * scale + self._offset
        reset = False
        with self._cv:
            self._status = st
            self._replies.answered(host_ns)
            self._buf.append(StagePosition(pos, self._seq, host_ns, host_ns))
            self._seq += 1
            self.health.received += 1
            if self._pending_move:
                if st.moving or st.state == "Hold":
                    self._pending_move = False
                elif self._move_acked and st.state in ("Idle", "Alarm"):
                    self._idle_after_ack += 1
                    if self._idle_after_ack >= 2 or st.state == "Alarm":
                        self._pending_move = False
            if self._stop_ns is not None and not self._resetting:
                if st.state == "Hold" and st.substate == 0:
                    reset = True
                elif st.state == "Alarm":
                    self._stop_ns = None  # GRBL ignores a hold in alarm; nothing moves
            self._cv.notify_all()
        if reset:
            try:
                self._soft_reset()
            except DeviceError:
                pass  # link loss is reported by fault()

    def _on_response(self, msg: wire.Ok | wire.Error) -> None:
        with self._cv:
            if not self._inflight:
                self.health.corrupt += 1
                log.warning("platform: GRBL response %s with no line in flight", msg)
                return
            entry = self._inflight.popleft()
            self._counter.acked()
            entry.result = msg
            entry.done.set()
            if entry.move_id:
                if isinstance(msg, wire.Error):
                    self._device_fault = f"platform: GRBL rejected {entry.text!r} with {msg}"
                    log.error(self._device_fault)
                    if entry.move_id == self._move_id:
                        self._pending_move = False
                elif entry.move_id == self._move_id:
                    self._move_acked = True
            self._cv.notify_all()

    def _on_alarm(self, msg: wire.Alarm) -> None:
        with self._cv:
            self._device_fault = f"platform: GRBL {msg}"
            self._pending_move = False
            self._cv.notify_all()
        log.error(self._device_fault)

    def _on_banner(self, msg: wire.Banner) -> None:
        with self._cv:
            self._banners += 1
            self._version = msg.version
            expected = self._connecting or self._expected_resets > 0
            self._expected_resets = max(0, self._expected_resets - 1)
            self._resetting = False
            self._stop_ns = None
            self._pending_move = False
            self._alarm_locked = False  # the unlock message follows the banner if still locked
            # A reset empties GRBL's receive buffer: the lines in flight will never be answered.
            for entry in self._inflight:
                entry.result = "GRBL was reset before executing it"
                entry.done.set()
            self._inflight.clear()
            self._counter.clear()
            if not expected:
                self._device_fault = ("platform: GRBL reset itself (welcome banner without a reset from the host): "
                                      "check power and the USB link; moves in progress were lost")
            self._cv.notify_all()
        if expected:
            log.info("platform: Grbl %s ready", msg.version)
        else:
            log.error(self._device_fault)

    # ---- helpers ---------------------------------------------------------------------------------
    def _lose_link(self, why: str) -> None:
        with self._cv:
            if self._link_error is None:
                self._link_error = f"platform: link lost ({why}) on {self.cfg.port}"
                log.error(self._link_error)
            for entry in self._inflight:
                entry.result = self._link_error
                entry.done.set()
            self._cv.notify_all()

    def _raise_link_error(self) -> None:
        if self._link_error:
            raise DeviceError(self._link_error)

    def _blocking_fault(self) -> str | None:
        with self._cv:
            return self._link_error or self._device_fault

    def _wait(self, pred, deadline: float) -> bool:
        with self._cv:
            while not pred():
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._cv.wait(min(remaining, 0.05))
            return True

    def _status_text(self) -> str:
        st = self._status
        if st is None:
            return "unknown"
        return st.state if st.substate is None else f"{st.state}:{st.substate}"

