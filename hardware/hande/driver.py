"""Robotiq Hand-E driver over the Robotiq URCap's socket service (TCP 63352 on the UR controller).

One TCP connection carries strictly alternating request/reply pairs, so every exchange holds one
socket lock: the poll thread's GETs and a stop() from another thread interleave pair by pair and
a stop() waits for at most one reply in flight. The poll thread reads POS, OBJ, PRE, STA, FLT
and GTO at `poll_rate_hz`; each cycle becomes one GripperState. The URCap reports no device
time, so `device_t_ns` is the host time at which the POS reply arrived (= `host_t_ns`).

is_moving(): a move just commanded counts as moving until a poll cycle that began after its SET
was acknowledged shows PRE equal to the requested count (the gripper took the request); from
then on OBJ decides: 0 moving (while GTO is 1), 1/2 stopped on an object, 3 at the position.

Stall: judged by the gripper's answers (hardware.watchdog.ReplyWatch): silence counts only while
a request has waited for its reply longer than the bound less one poll period, and a reply that
sits unread in the socket (the poll thread not scheduled) is an answer. A poll thread the host
did not run asks nothing: that is a busy host, not a silent gripper.
"""

from __future__ import annotations

import logging
import select
import socket
import threading
import time
from collections import deque

from hardware.hande import wire
from hardware.hande.config import HandEConfig
from hardware.interfaces import DeviceError, Gripper
from hardware.watchdog import ReplyWatch
from layerskin_exp.types import GripperState

log = logging.getLogger(__name__)

_POLL_VARS = ("POS", "OBJ", "PRE", "STA", "FLT", "GTO")


class HandEGripper(Gripper):
    """Hand-E jaw opening in mm (0 closed .. stroke_mm open), speed mm/s, force %."""

    def __init__(self, cfg: HandEConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self.cal = cfg.calibration
        self._io_lock = threading.Lock()  # one request/reply pair at a time
        self._lock = threading.Lock()  # the state below
        self._stop_poll = threading.Event()
        self._poller: threading.Thread | None = None
        self._sock: socket.socket | None = None
        self._reset_state()

    def _reset_state(self) -> None:
        self._rx = b""
        self._buf: deque[GripperState] = deque()
        self._seq = 0
        self._link_error: str | None = None
        self._last_reply_ns = 0
        # silence counts once a request waits longer than the bound less a poll period
        self._replies = ReplyWatch((self.cfg.stall_timeout_s - 1.0 / self.cfg.poll_rate_hz) * 1e9)
        self._snapshot: dict[str, int] = {}
        self._epoch = 0  # bumped after every acknowledged move/stop
        self._pending = False
        self._cmd_count = -1
        self._spe = 0
        self._for = 0
        self._last_flt = 0

    @property
    def address(self) -> str:
        return f"{self.cfg.host}:{self.cfg.port}"

    # ---- life cycle ----------------------------------------------------------------------------
    def _connect(self) -> None:
        self._reset_state()
        try:
            sock = socket.create_connection((self.cfg.host, self.cfg.port), timeout=self.cfg.connect_timeout_s)
        except OSError as exc:
            raise DeviceError(f"gripper: cannot reach the Robotiq URCap socket at {self.address} within "
                              f"{self.cfg.connect_timeout_s} s ({exc}); check that the UR controller is on the "
                              "network, the Robotiq Grippers URCap is installed and the gripper is connected") from exc
        sock.settimeout(self.cfg.reply_timeout_s)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        try:
            self._activate()
            self._spe, self._for = self._get("SPE"), self._get("FOR")
            self._snapshot = {v: self._get(v) for v in _POLL_VARS}
        except BaseException:
            self._close()
            raise
        self._stop_poll.clear()
        self._poller = threading.Thread(target=self._poll_loop, name="hande-poll", daemon=True)
        self._poller.start()

    def _activate(self) -> None:
        """Activate unless already active without a fault: reset (ACT 0, clears faults), ACT 1,
        wait for STA == 3. (Activation makes a real Hand-E open and close fully.)"""
        if self._get("ACT") == 1 and self._get("STA") == wire.STA_ACTIVE and self._get("FLT") == 0:
            return
        deadline = time.monotonic() + self.cfg.activation_timeout_s
        self._set([("ACT", 0)])
        self._set([("ATR", 0)])
        while self._get("STA") != wire.STA_RESET:
            if time.monotonic() > deadline:
                raise DeviceError(f"gripper: Hand-E at {self.address} did not reset (STA != 0) within "
                                  f"{self.cfg.activation_timeout_s} s")
            time.sleep(0.01)
        self._set([("ACT", 1)])
        while True:
            sta = self._get("STA")
            if sta == wire.STA_ACTIVE:
                return
            flt = self._get("FLT")
            if time.monotonic() > deadline or flt >= 0x08:
                raise DeviceError(f"gripper: Hand-E at {self.address} did not activate within "
                                  f"{self.cfg.activation_timeout_s} s (STA={sta}, FLT=0x{flt:02X}: "
                                  f"{wire.describe_fault(flt)}); check that nothing blocks the fingers")
            time.sleep(0.01)

    def _disconnect(self) -> None:
        self._close()

    def _close(self) -> None:
        self._stop_poll.set()
        if self._poller is not None and self._poller is not threading.current_thread():
            self._poller.join(timeout=2.0)
        self._poller = None
        if self._sock is not None:
            try:
                self._sock.close()
            except OSError:
                pass
            self._sock = None

    # ---- Gripper interface -----------------------------------------------------------------------
    def move(self, opening_mm: float, speed_mm_s: float, force_pct: float) -> None:
        """SET POS/SPE/FOR and GTO 1 in one request; returns once the URCap acknowledged it."""
        self._require_connected()
        cfg = self.cfg
        if not (opening_mm == opening_mm and 0 <= opening_mm <= cfg.stroke_mm):
            raise DeviceError(f"gripper: opening {opening_mm!r} mm is outside the stroke 0..{cfg.stroke_mm} mm")
        if not (cfg.min_speed_mm_s <= speed_mm_s <= cfg.max_speed_mm_s):
            raise DeviceError(f"gripper: speed {speed_mm_s!r} mm/s is outside the Hand-E's "
                              f"{cfg.min_speed_mm_s}..{cfg.max_speed_mm_s} mm/s")
        if not (0 <= force_pct <= 100):
            raise DeviceError(f"gripper: force {force_pct!r} % is outside 0..100 %")
        reason = self._blocking_fault()
        if reason:
            raise DeviceError(f"{reason}; cannot move")
        pos = self.cal.mm_to_count(opening_mm)
        spe = self.cal.speed_to_count(speed_mm_s)
        frc = self.cal.force_to_count(force_pct)
        with self._lock:
            self._pending, self._cmd_count = True, pos
        try:
            self._set([("POS", pos), ("SPE", spe), ("FOR", frc), ("GTO", 1)])
        except DeviceError:
            with self._lock:
                self._pending = False
            raise
        with self._lock:
            self._epoch += 1
            self._spe, self._for = spe, frc
            self._snapshot["GTO"] = 1

    def stop(self) -> None:
        """SET GTO 0: the jaws stop where they are. Safe from any thread; waits at most for the
        reply in flight and its own (reply_timeout_s each)."""
        self._require_connected()
        with self._lock:
            self._pending = False
        self._set([("GTO", 0)])
        with self._lock:
            self._epoch += 1
            self._snapshot["GTO"] = 0

    def is_moving(self) -> bool:
        self._require_connected()
        with self._lock:
            if self._pending:
                return True
            s = self._snapshot
            return s.get("GTO") == 1 and s.get("OBJ") == wire.OBJ_MOVING and s.get("STA") == wire.STA_ACTIVE

    def read_available(self) -> list[GripperState]:
        self._require_connected()
        with self._lock:
            out = list(self._buf)
            self._buf.clear()
        return out

    def fault(self, now_ns: int) -> str | None:
        with self._lock:
            if self._link_error:
                return self._link_error
            flt = self._snapshot.get("FLT", 0)
            if flt:
                return f"gripper: Hand-E fault 0x{flt:02X} ({wire.describe_fault(flt)})"
            sta = self._snapshot.get("STA", wire.STA_ACTIVE)
            if sta != wire.STA_ACTIVE:
                return f"gripper: Hand-E not active (STA={sta}); reconnect to re-activate"
            silent_ns = self._replies.silent_ns(now_ns)
            if (self._connected and silent_ns is not None and silent_ns > self.cfg.stall_timeout_s * 1e9
                    and not self._reply_waiting()):
                sent = self._replies.asked_after_answer_ns()
                return (f"gripper stalled: no reply from the URCap socket for {silent_ns / 1e6:.0f} ms (a request "
                        f"unanswered, sent {sent / 1e6:.0f} ms after the last reply) at {self.address}")
        return None

    def _reply_waiting(self) -> bool:
        """Whether bytes of a reply sit unread in the socket (the poll thread not yet run to read
        them): the gripper answered."""
        sock = self._sock
        if sock is None:
            return False
        try:  # (select first: a socket with a timeout would wait for data before a recv, flags or not)
            return bool(select.select([sock], [], [], 0)[0] and sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT))
        except (OSError, ValueError):  # nothing waiting, or the link went: the exchange reports that
            return False

    # ---- polling ---------------------------------------------------------------------------------
    def _poll_loop(self) -> None:
        period = 1.0 / self.cfg.poll_rate_hz
        next_t = time.monotonic()
        while not self._stop_poll.wait(max(0.0, next_t - time.monotonic())):
            next_t += period
            if next_t < time.monotonic():
                next_t = time.monotonic() + period
            with self._lock:
                epoch0 = self._epoch
            values: dict[str, int] = {}
            try:
                for var in _POLL_VARS:
                    values[var] = self._get(var)
                    if var == "POS":
                        pos_ns = self._last_reply_ns
            except DeviceError:
                if self._link_error:
                    return
                continue  # a garbled reply: counted, the connection resynchronised
            rec = GripperState(self.cal.count_to_mm(values["POS"]), self.cal.count_to_mm(values["PRE"]),
                               self._spe, self._for, values["OBJ"] in (wire.OBJ_OPENING_CONTACT,
                                                                       wire.OBJ_CLOSING_CONTACT),
                               values["FLT"], pos_ns, pos_ns, self._seq)
            with self._lock:
                self._seq += 1
                self.health.received += 1
                self._buf.append(rec)
                if self._epoch == epoch0:  # no move/stop acknowledged during this cycle
                    self._snapshot = values
                    if self._pending and values["PRE"] == self._cmd_count:
                        self._pending = False
                else:
                    self._snapshot.update(STA=values["STA"], FLT=values["FLT"])
            if values["FLT"] != self._last_flt:
                if values["FLT"]:
                    log.error("gripper: Hand-E reports fault 0x%02X (%s)", values["FLT"], wire.describe_fault(values["FLT"]))
                self._last_flt = values["FLT"]

    # ---- request / reply -------------------------------------------------------------------------
    def _get(self, var: str) -> int:
        return self._exchange(wire.encode_get(var), var)

    def _set(self, pairs) -> None:
        self._exchange(wire.encode_set(pairs), None)

    def _exchange(self, request: bytes, var: str | None) -> int:
        what = request.decode("ascii").strip()
        if not self._io_lock.acquire(timeout=2 * self.cfg.reply_timeout_s):
            raise DeviceError(f"gripper: socket busy for {2 * self.cfg.reply_timeout_s} s; could not send {what!r}")
        try:
            if self._link_error:
                raise DeviceError(self._link_error)
            sock = self._sock
            if sock is None:
                raise DeviceError("gripper: socket closed")
            try:
                sock.sendall(request)
                self._replies.asked(time.monotonic_ns())  # once sent: a thread descheduled before asked nothing
                while True:
                    got = wire.take_ack(self._rx) if var is None else wire.take_value(self._rx, var)
                    if got is not None:
                        value, self._rx = got
                        self._last_reply_ns = time.monotonic_ns()
                        self._replies.answered(self._last_reply_ns)
                        return int(value)
                    chunk = sock.recv(1024)
                    if not chunk:
                        raise ConnectionError("connection closed by the URCap")
                    self._rx += chunk
            except wire.HandEProtocolError as exc:
                self.health.corrupt += 1
                log.warning("gripper: %s; resynchronising", exc)
                self._resync(sock)
                raise DeviceError(f"gripper: bad reply to {what!r}: {exc}") from exc
            except (OSError, ConnectionError) as exc:
                why = f"no reply within {self.cfg.reply_timeout_s:.3g} s" if isinstance(exc, TimeoutError) else str(exc)
                self._lose_link(f"{why} to {what!r}")
                raise DeviceError(self._link_error) from exc
        finally:
            self._io_lock.release()

    def _resync(self, sock: socket.socket) -> None:
        """Drop whatever is buffered or still arriving (a late or garbled reply) so the next
        request's reply is read from a clean stream."""
        self._rx = b""
        sock.settimeout(0.02)
        try:
            while sock.recv(4096):
                pass
        except OSError:
            pass
        finally:
            sock.settimeout(self.cfg.reply_timeout_s)

    def _lose_link(self, why: str) -> None:
        with self._lock:
            if self._link_error is None:
                self._link_error = f"gripper: link lost ({why}) at {self.address}"
                log.error(self._link_error)

    def _blocking_fault(self) -> str | None:
        with self._lock:
            if self._link_error:
                return self._link_error
            flt = self._snapshot.get("FLT", 0)
            if flt >= 0x08:
                return f"gripper: Hand-E fault 0x{flt:02X} ({wire.describe_fault(flt)})"
        return None
