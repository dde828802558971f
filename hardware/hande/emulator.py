"""The Robotiq URCap gripper socket over TCP, driving the simulated Hand-E of a RealtimeWorld.

What it models: `SET VAR val ...` answered `ack` (no line end, as the URCap), `GET VAR` answered
`VAR value\\n`; registers ACT GTO ATR ADR POS SPE FOR (writable) and STA PRE OBJ FLT COU; the
activation sequence (ACT 0 -> 1: STA 0 -> 1 -> 3 after `activation_time_s`; ACT 0 resets and
clears faults); GTO 1 starts a move of the twin to POS at SPE with FOR (and a POS/SPE/FOR change
while GTO is 1 redirects it); GTO 0 stops the jaws; a GTO 1 before activation sets FLT 0x07 (ACT 0)
or 0x05 (still activating) as the gripper does; POS is the twin's latest reported opening, PRE the
position request taken by the last GTO; OBJ 0 while moving (or GTO 0), 2/1 when the jaws stopped
short of the request closing/opening (an object: the rod), 3 at the request.

Several clients at once, as the URCap's socket server serves them: a UR program's own rq_*
functions (which open the socket on the controller) and a remote client talk to one gripper at
the same time. Each connection gets its own answers; every request acts on the one set of
registers, in the order the requests arrive. No idle connection holds up another.

Not modelled: the activation's full open/close stroke, auto-release (ATR/ADR are stored only),
motor current (COU reads 0), temperature/voltage faults unless set. What the URCap answers to an
unknown variable is not publicly documented; this answers `?\\n`.

Faults (hardware.emulation's vocabulary): stall() (connections kept, nothing answered; resume()),
drop(n) (the next n replies are not sent), corrupt(n) (the next n replies arrive "garbled"),
disconnect() (every client connection is closed, as when the URCap restarts; clients may connect
again). set_fault(code): the gripper reports FLT `code` until reset (ACT 0 -> 1). reply_delay_s
(slow replies), start_active (skip the need to activate). The URCap's usual port is USUAL_PORTS.

The socket server and the gripper's registers (`HandEURCap`) run in a process of their own
(`hardware.hande.urcap`, which says why and how the jaws' state reaches it); `HandEEmulator`
starts it, keeps the simulated world, and moves and stops the world's jaws as the process asks.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from types import MappingProxyType

from hardware.emulation import DeviceProcess, Emulator
from hardware.hande import wire
from hardware.interfaces import DeviceError

log = logging.getLogger(__name__)

EMULATOR_SETUP = "gripper"


POLL_S = 0.002  # how often the bridge takes the gripper twin's records and looks at its jaws
HEARTBEAT_S = 0.01  # the jaws' state goes to the URCap process when it changes, and at least this often
START_TIMEOUT_S = 20.0
LISTEN_BACKLOG = 16


class HandEURCap(Emulator):
    """URCap socket on host:port (0 = any free port) backed by `rt.rig.gripper`, the jaws as the
    URCap's process sees them (`hardware.hande.urcap.BridgedGripper`: opening_mm,
    object_detected, is_moving(), move(), stop()). Runs in that process; `HandEEmulator` starts it."""

    DEVICE = "hande"
    TWINS = ()  # the jaws' state comes over the pipe; the parent drains the twin

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, *, activation_time_s: float = 0.05,
                 start_active: bool = False, reply_delay_s: float = 0.0, stall_after_s: float | None = None,
                 disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        self.host, self.port = host, int(port)
        self.activation_time_s = float(activation_time_s)
        self.reply_delay_s = float(reply_delay_s)
        gcfg = rt.rig.gripper.cfg
        self.cal = wire.Calibration(gcfg.stroke_mm, 0, 255, gcfg.min_speed_mm_s, gcfg.max_speed_mm_s)
        self._opening_mm = float(rt.rig.gripper.opening_mm)
        self._object = False
        self._moving = False
        self.regs: dict[str, int] = {"ACT": 0, "GTO": 0, "ATR": 0, "ADR": 0, "POS": 0, "SPE": 0, "FOR": 0,
                                     "STA": 0, "PRE": 0, "FLT": 0}
        self._act_t0 = 0.0
        if start_active:
            self.regs.update(ACT=1, STA=wire.STA_ACTIVE)
        self.requests = 0
        self.bad_requests = 0
        self.connections = 0  # accepted so far
        self._listener: socket.socket | None = None
        self._clients: set[socket.socket] = set()
        self._regs_lock = threading.Lock()  # one gripper: requests act on it one at a time

    # ---- life cycle ----------------------------------------------------------------------------
    def _open(self) -> str:
        ls = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._listener = ls
        ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        ls.bind((self.host, self.port))
        ls.listen(LISTEN_BACKLOG)
        ls.settimeout(0.02)
        self.port = ls.getsockname()[1]
        self._spawn(self._accept, "accept")
        return f"{self.host}:{self.port}"

    def _close(self) -> None:
        self._close_clients()
        if self._listener is not None:
            self._listener.close()
            self._listener = None

    def _close_clients(self) -> None:
        for conn in list(self._clients):
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    # ---- faults --------------------------------------------------------------------------------
    def _on_disconnect(self) -> None:
        self._close_clients()
        self._disconnected.clear()  # the socket server stays: clients may connect again

    def set_fault(self, code: int) -> None:
        """FLT reads `code` (e.g. 0x0E overcurrent) until the gripper is reset (ACT 0 -> 1); 0 clears it."""
        with self._regs_lock:
            self.regs["FLT"] = int(code)
            if code >= 0x08:
                self._halt()

    # ---- serving -------------------------------------------------------------------------------
    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            conn.settimeout(0.02)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.connections += 1
            self._clients.add(conn)
            self._threads = [t for t in self._threads if t.is_alive()]  # forget finished clients
            self._spawn(self._serve_client, f"client{self.connections}", conn)

    def _serve_client(self, conn: socket.socket) -> None:
        try:
            self._converse(conn)
        finally:
            self._clients.discard(conn)
            conn.close()

    def _converse(self, conn: socket.socket) -> None:
        buf = b""
        while not self._stop.is_set():
            if self.stalled:
                time.sleep(0.005)
                continue
            i = buf.find(b"\n")
            if i < 0:
                try:
                    chunk = conn.recv(4096)
                except TimeoutError:
                    continue
                except OSError:
                    return
                if not chunk:
                    return
                buf += chunk
                continue
            line, buf = buf[:i].strip(b"\r"), buf[i + 1:]
            if not line.strip():
                continue
            with self._regs_lock:
                reply = self._answer(line)
            if self.reply_delay_s:
                time.sleep(self.reply_delay_s)
            fault = self._next_fault()
            if fault is not None and fault[0] == "drop":
                continue
            if fault is not None:  # garbled: the reply's first byte changed
                reply = bytes([reply[0] ^ 0x20]) + reply[1:]
            try:
                conn.sendall(reply)
            except OSError:
                return

    def _answer(self, line: bytes) -> bytes:
        self.requests += 1
        try:
            req = wire.parse_request(line)
        except wire.HandEProtocolError as exc:
            self.bad_requests += 1
            log.warning("Hand-E emulator: %s", exc)
            return b"?\n"
        self._tick()
        if isinstance(req, wire.GetRequest):
            if req.var not in wire.READABLE:
                self.bad_requests += 1
                return b"?\n"
            return wire.encode_value(req.var, self._read(req.var))
        if any(var not in wire.WRITABLE for var, _ in req.pairs):
            self.bad_requests += 1
            return b"?\n"
        self._write(req.pairs)
        return wire.ACK

    # ---- the gripper ---------------------------------------------------------------------------
    def _tick(self) -> None:
        """Advance the activation and take the jaws' latest state (opening, object, motion)."""
        r = self.regs
        if r["STA"] == wire.STA_ACTIVATING and time.monotonic() - self._act_t0 >= self.activation_time_s:
            r["STA"] = wire.STA_ACTIVE
        with self.rt.lock:
            jaws = self.rt.rig.gripper
            self._opening_mm, self._object, self._moving = jaws.opening_mm, jaws.object_detected, jaws.is_moving()

    def _read(self, var: str) -> int:
        r = self.regs
        if var == "POS":
            return self.cal.mm_to_count(self._opening_mm)
        if var == "OBJ":
            if r["GTO"] != 1 or r["STA"] != wire.STA_ACTIVE or self._moving:
                return wire.OBJ_MOVING
            pos = self.cal.mm_to_count(self._opening_mm)
            if not self._object and abs(pos - r["PRE"]) <= 3:
                return wire.OBJ_AT_POSITION
            return wire.OBJ_CLOSING_CONTACT if r["PRE"] > pos else wire.OBJ_OPENING_CONTACT
        if var == "COU":
            return 0
        return r[var]

    def _write(self, pairs) -> None:
        r = self.regs
        redirect = False
        for var, val in pairs:
            val = min(max(int(val), 0), 255)
            if var == "ACT":
                if val == 0:
                    r.update(ACT=0, STA=wire.STA_RESET, GTO=0, FLT=0)
                    self._halt()
                elif r["ACT"] == 0:
                    r.update(ACT=1, STA=wire.STA_ACTIVATING, FLT=0)
                    self._act_t0 = time.monotonic()
            elif var == "GTO":
                if val == 0:
                    r["GTO"] = 0
                    self._halt()
                elif r["ACT"] == 0:
                    r["FLT"] = 0x07
                elif r["STA"] != wire.STA_ACTIVE:
                    r["FLT"] = 0x05
                elif r["FLT"] < 0x08:
                    r.update(GTO=1, FLT=0)
                    self._go()
            else:
                redirect |= var in ("POS", "SPE", "FOR") and r[var] != val
                r[var] = val
        if redirect and r["GTO"] == 1 and r["STA"] == wire.STA_ACTIVE and not any(v == "GTO" for v, _ in pairs):
            self._go()

    def _go(self) -> None:
        r = self.regs
        r["PRE"] = r["POS"]
        cal = self.cal
        with self.rt.lock:
            self.rt.rig.gripper.move(cal.count_to_mm(r["POS"]), cal.count_to_speed(r["SPE"]),
                                     cal.count_to_force(r["FOR"]))
            self._moving = self.rt.rig.gripper.is_moving()

    def _halt(self) -> None:
        with self.rt.lock:
            self.rt.rig.gripper.stop()


class HandEEmulator(Emulator):
    """URCap socket on host:port (0 = any free port) backed by `rt.rig.gripper`.

    The socket server and the registers (HandEURCap) run in a process of their own
    (hardware.hande.urcap, which says why); this object starts it and runs the bridge thread that
    drains the gripper twin and sends the jaws' state (latest opening and object flag, motion)
    when it changes, and applies the moves and stops the process sends back to the twin. The
    gripper's read-out (`regs`, a read-only copy of its registers, `requests`, `bad_requests`,
    `connections`) is asked of it when read.
    """

    DEVICE = "hande"
    TWINS = ("gripper",)
    USUAL_PORTS = {"port": wire.PORT}  # the URCap's gripper socket

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, *, activation_time_s: float = 0.05,
                 start_active: bool = False, reply_delay_s: float = 0.0, stall_after_s: float | None = None,
                 disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        self.host, self.port = host, int(port)
        self._options = {"host": host, "activation_time_s": float(activation_time_s),
                         "start_active": bool(start_active), "reply_delay_s": float(reply_delay_s)}
        self._urcap: DeviceProcess | None = None
        self._info: dict = {}
        self._jaws: tuple[float, bool] = (0.0, False)  # the twin's latest reported opening and object flag
        self._applied_id = 0

    # ---- the gripper's read-out -----------------------------------------------------------------
    def __getattr__(self, name: str):
        if name in ("regs", "requests", "bad_requests", "connections"):
            urcap = self.__dict__.get("_urcap")
            if urcap is not None and self.running:  # a fresh read-out: at least what the socket has answered
                urcap.send(("readout",))
                urcap.wait_ack("readout", lambda v: True)
            value = self.__dict__.get("_info", {}).get(name, {} if name == "regs" else 0)
            return MappingProxyType(value) if name == "regs" else value
        raise AttributeError(name)

    # ---- life cycle ----------------------------------------------------------------------------
    def _open(self) -> str:
        with self.rt.lock:
            twin = self.rt.rig.gripper
            twin.read_available()  # start with fresh records
            cfg = twin.cfg
            gripper = {"stroke_mm": float(cfg.stroke_mm), "min_speed_mm_s": float(cfg.min_speed_mm_s),
                       "max_speed_mm_s": float(cfg.max_speed_mm_s)}
            self._jaws = (float(cfg.initial_opening_mm), False)
        opts = {**self._options, "port": self.port, "gripper": gripper, "opening_mm": self._jaws[0]}
        self._urcap = DeviceProcess("hardware.hande.urcap", opts, self.DEVICE, log)
        where = self._serve_device(self._urcap, START_TIMEOUT_S)
        self.port = int(where.rpartition(":")[2])
        return where

    def _close(self) -> None:
        if self._urcap is not None:
            self._urcap.close()
            self._urcap = None

    # ---- faults: carried out by the URCap process ------------------------------------------------
    def _on_stall(self, stalled: bool) -> None:
        if self._urcap is None:
            return
        if stalled:
            left = self._stall_until - time.monotonic()
            self._urcap.send(("stall", None if left == float("inf") else max(left, 0.0)))
        else:
            self._urcap.send(("resume",))
        self._urcap.wait_ack("stall", lambda v: v == stalled)

    def _on_disconnect(self) -> None:
        self._disconnected.clear()  # the socket server stays: clients may connect again
        if self._urcap is not None:
            self._urcap.send(("disconnect",))
            self._urcap.wait_ack("disconnect", lambda v: True)

    def set_fault(self, code: int) -> None:
        """FLT reads `code` (e.g. 0x0E overcurrent) until the gripper is reset (ACT 0 -> 1); 0
        clears it. In force when this returns."""
        code = int(code)
        if not 0 <= code <= 0xFF:
            raise ValueError(f"hande emulator: fault code {code!r} is not a register value; use 0..255 "
                             "(0x05, 0x07 and 0x08-0x0F are the Hand-E's, see hardware.hande.wire)")
        if self._urcap is None:
            raise DeviceError("hande emulator: not started; start() it before setting a fault")
        self._urcap.send(("set_fault", code))
        self._urcap.wait_ack("set_fault", lambda v: v == code)

    def _device(self) -> DeviceProcess | None:
        return self._urcap

    # ---- bridge ----------------------------------------------------------------------------------
    def _bridge(self) -> None:
        urcap = self._urcap
        last, last_t = None, 0.0
        try:
            while not self._stop.is_set():
                urcap.poll(POLL_S, self._handle)
                if urcap.ready.is_set() and urcap.error is None:
                    with self.rt.lock:
                        twin = self.rt.rig.gripper
                        recs = twin.read_available()
                        if recs:
                            self._jaws = (float(recs[-1].position_mm), bool(recs[-1].object_detected))
                        state = (*self._jaws, bool(twin.is_moving()), self._applied_id)
                    now = time.monotonic()
                    if state != last or now - last_t > HEARTBEAT_S:
                        urcap.send(("state", *state))
                        last, last_t = state, now
        except (EOFError, OSError) as exc:
            if not self._stop.is_set():
                log.warning("Hand-E emulator: the URCap process went away (%s)", exc)
                self.error = self.error or exc
                urcap.went_away(exc)

    def _handle(self, msg: tuple) -> None:
        kind = msg[0]
        if kind == "info":
            info = msg[1]
            for k in ("drop", "corrupt"):  # applied in the URCap process; stall and disconnect are counted here
                if info["fault_counts"].get(k):
                    self.fault_counts[k] = info["fault_counts"][k]
            if info["error"] and self.error is None:
                self.error = RuntimeError(info["error"])
            self._info = info
        elif kind == "move":
            try:
                with self.rt.lock:
                    self.rt.rig.gripper.move(*msg[2:5])
            except DeviceError as exc:
                log.warning("Hand-E emulator: twin refused the move: %s", exc)
            self._applied_id = max(self._applied_id, msg[1])
        elif kind == "stop":
            with self.rt.lock:
                if self.rt.rig.gripper.is_connected:
                    self.rt.rig.gripper.stop()
            self._applied_id = max(self._applied_id, msg[1])
