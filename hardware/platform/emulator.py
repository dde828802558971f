"""A GRBL 1.1 controller on a pseudo-terminal, driving the simulated platform of a RealtimeWorld.

What it models (from gnea/grbl 1.1h's source and interface docs):
- the welcome banner at start and after every soft reset;
- a 128-byte serial receive buffer that the protocol loop empties into its line buffer while it is
  not waiting on the planner or a dwell; bytes arriving when it is full (a host that does not count
  characters) are dropped (counted in `rx_overflow_bytes` and logged); real-time bytes `?` `!` `~`
  Ctrl-X are picked off before it;
- an 80-character line buffer: a longer line answers `error:11` and the parser goes on with the next;
- a line parser for G0/G1/G4/G20/G21/G90/G91 (+ G17/G54/G94 accepted), F/X/Y/Z/P/N words, and
  `$$`, `$#` (coordinate offsets, all zero: no G10/G92 here), `$C` (check mode: lines are parsed,
  nothing moves; leaving it resets), `$X`, `$H`, `$G`, `$I`, `$`, `$N=value`; each line answers
  `ok` or `error:N`;
- a planner queue (16 blocks): queued moves go to the twin one after the other; a line that finds
  the planner full waits (its `ok` with it) as in GRBL;
- feeds above the axes' max rates ($110-112) are clamped as GRBL's planner does (the nominal rate is
  limited to min_i(max_rate_i / |u_i|) for the move's unit vector u); G0 runs at that limit;
- soft limits ($20=1, travel $130-132): a motion target outside the travel box raises ALARM:2 and
  `[MSG:Reset to continue]`; GRBL then ignores all but `?` and Ctrl-X until reset, and comes back
  in alarm (needs `$X`). (error:15 is GRBL's answer for `$J=` jogs only, which this emulator does not
  implement.) With soft limits off, a target outside the stage's travel hits the end: ALARM:1;
- feed hold `!` (Run -> Hold:1 while decelerating -> Hold:0), resume `~`, soft reset Ctrl-X: reset
  while in motion (Run or Hold:1) raises ALARM:3 and leaves GRBL in alarm; from Idle or Hold:0 it
  does not;
- status reports `<Idle|MPos:x,y,z|FS:f,0>` with `WCO:` on the first report after a reset and every
  10th (idle) / 30th (busy) after, `Ov:` on the next.

Coordinates: MPos equals the twin's position (the skin frame). A real GRBL homed at its switches
reports MPos in [-$13x, 0]; here that box is shifted to end at the stage's workspace_max, i.e.
travel box = [workspace_max - $13x, workspace_max], so the default travel is the stage's workspace.

Not modelled: `$J=` jogging and jog cancel, G10/G28/G30/G92 offsets, arcs, probing, real homing motion
(`$H` only clears the alarm: the simulated stage knows its position), overrides, EEPROM timing, the
500 ms pause GRBL takes after printing an ALARM, baud-rate pacing.

Faults (hardware.emulation's vocabulary): stall() (stops reading and answering: a hung
controller; resume() ends it), disconnect() (closes the pty master: the host sees the port vanish),
drop(n) (the next n messages to the host are lost), corrupt(n, how) (the next n messages arrive as
"noise": line noise before the message, or "garbled": a byte of the message changed);
start_in_alarm=True (power-up alarm, as with homing enabled).
"""

from __future__ import annotations

import logging
import time
from collections import deque

import numpy as np

from hardware.emulation import Emulator, Pty
from hardware.interfaces import DeviceError
from hardware.platform import wire

log = logging.getLogger(__name__)

EMULATOR_SETUP = "platform"

_ALLOWED_G = {0.0, 1.0, 4.0, 17.0, 20.0, 21.0, 54.0, 90.0, 91.0, 94.0}
_MODAL_GROUPS = {0.0: "motion", 1.0: "motion", 4.0: "nonmodal", 17.0: "plane", 20.0: "units", 21.0: "units",
                 54.0: "wcs", 90.0: "distance", 91.0: "distance", 94.0: "feedmode"}


_LINE_KEEP = 4 * wire.LINE_BUFFER_SIZE  # raw bytes of a line kept for parsing (beyond: error:11 anyway)
_NOISE = b"\x00\xff\x13#~garbage\r\n"


class GrblEmulator(Emulator):
    """GRBL 1.1h on a pty, backed by `rt.rig.platform`; `start()` returns the slave path to open.

    host/port: accepted for the common emulator signature; a serial device has neither.
    """

    DEVICE = "platform"
    TWINS = ()  # reads the stage's position directly, as GRBL counts its own steps
    CORRUPTIONS = ("noise", "garbled")

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, *, start_in_alarm: bool = False,
                 planner_blocks: int = wire.PLANNER_BLOCKS, rx_buffer_bytes: int = wire.RX_BUFFER_BYTES,
                 tick_s: float = 0.001, stall_after_s: float | None = None,
                 disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        self.start_in_alarm = start_in_alarm
        self.planner_blocks = int(planner_blocks)
        self.rx_buffer_bytes = int(rx_buffer_bytes)
        self.tick_s = float(tick_s)
        cfg = rt.rig.platform.cfg
        self._ws_max = np.asarray(cfg.workspace_max_mm, float)
        travel = self._ws_max - np.asarray(cfg.workspace_min_mm, float)
        rate = cfg.max_speed_mm_s * 60.0
        self._twin_max_speed = float(cfg.max_speed_mm_s)
        self.settings: dict[int, float] = {
            0: 10, 1: 25, 2: 0, 3: 0, 4: 0, 5: 0, 6: 0, 10: 1, 11: 0.010, 12: 0.002, 13: 0, 20: 1, 21: 0,
            22: 1, 23: 0, 24: 25.0, 25: 500.0, 26: 250, 27: 1.0, 30: 1000, 31: 0, 32: 0,
            100: 800.0, 101: 800.0, 102: 800.0, 110: rate, 111: rate, 112: rate,
            120: cfg.max_accel_mm_s2, 121: cfg.max_accel_mm_s2, 122: cfg.max_accel_mm_s2,
            130: travel[0], 131: travel[1], 132: travel[2]}
        self._float_settings = {11, 12, 24, 25, 27, 100, 101, 102, 110, 111, 112, 120, 121, 122, 130, 131, 132}
        # counters
        self.rx_overflow_bytes = 0
        self.tx_dropped_bytes = 0
        self.lines_received = 0
        self.status_reports = 0
        self.resets = 0
        self.path: str | None = None
        self.pty: Pty | None = None
        self._reset_state(power_up=True)

    # ---- life cycle ----------------------------------------------------------------------------
    def _open(self) -> str:
        # The slave stays open here: GRBL's replies wait in the port for the host to read them.
        self.pty = Pty(hold_slave=True)
        self.path = self.pty.path
        self._emit(wire.format_banner())
        if self._state == "Alarm":
            self._emit(wire.format_feedback("MSG", "'$H'|'$X' to unlock"))
        self._spawn(self._run, "serial")
        return self.path

    def _close(self) -> None:
        if self.pty is not None:
            self.pty.close()

    @property
    def state(self) -> str:
        return self._state

    # ---- machine state -------------------------------------------------------------------------
    def _reset_state(self, power_up: bool = False) -> None:
        if power_up:
            self._state = "Alarm" if self.start_in_alarm else "Idle"
        self._critical = False  # soft/hard limit alarm: only '?' and Ctrl-X until reset
        self._hold_complete = False
        self._rx = bytearray()  # the serial receive buffer
        self._line = bytearray()  # the line being assembled from it
        self._line_over = False  # that line ran past _LINE_KEEP bytes
        self._planner: deque[tuple[np.ndarray, float]] = deque()
        self._current: tuple[np.ndarray, float] | None = None
        self._pending_line: bytes | None = None  # a line waiting on the planner or a dwell
        self._dwell_until: float | None = None
        self._motion = 0.0
        self._absolute = True
        self._unit_mm = 1.0
        self._feed_mm_min: float | None = None
        self._gc_pos: np.ndarray | None = None  # parser position; synced to the machine at first use
        self._wco_counter = 0
        self._ovr_counter = 1

    def _twin_pos(self) -> np.ndarray:
        with self.rt.lock:
            return self.rt.rig.platform.position_mm()

    def _twin_moving(self) -> bool:
        with self.rt.lock:
            return self.rt.rig.platform.is_moving()

    def _twin_stop(self) -> None:
        with self.rt.lock:
            self.rt.rig.platform.stop()

    # ---- main loop -----------------------------------------------------------------------------
    def _run(self) -> None:
        pty = self.pty
        while not self._stop.is_set():
            if self.disconnected:
                pty.close()
                return
            if self.stalled:
                time.sleep(self.tick_s)
                continue
            for b in pty.read(self.tick_s):
                self._receive_byte(b)
            self._step()

    def _emit(self, data: bytes) -> None:
        fault = self._next_fault() if data else None
        if fault is not None:
            if fault[0] == "drop":
                return
            if fault[1] == "noise":
                data = _NOISE + data
            else:  # garbled: one byte of the message changed
                data = bytearray(data)
                data[len(data) // 2] ^= 0x5A
                data = bytes(data)
        view = memoryview(data)
        while view:
            n = self.pty.write(view)
            if n == 0:
                self.tx_dropped_bytes += len(view)
                return
            view = view[n:]

    def _receive_byte(self, b: int) -> None:
        if b == 0x18:
            self._soft_reset()
        elif b == 0x3F:  # '?'
            self._report_status()
        elif b == 0x21:  # '!'
            self._feed_hold()
        elif b == 0x7E:  # '~'
            self._cycle_start()
        elif b > 0x7F:
            pass  # extended-ASCII real-time commands (overrides, jog cancel): not modelled
        elif len(self._rx) >= self.rx_buffer_bytes:
            self.rx_overflow_bytes += 1
            if self.rx_overflow_bytes == 1 or self.rx_overflow_bytes % 100 == 0:
                log.warning("GRBL emulator: receive buffer full (%d bytes); %d byte(s) dropped so far - "
                            "the host is not counting characters", self.rx_buffer_bytes, self.rx_overflow_bytes)
        else:
            self._rx.append(b)
            if self._pending_line is None and not self._critical:
                self._parse_lines()  # the protocol loop empties the buffer while it is free

    # ---- real-time commands ----------------------------------------------------------------------
    def _soft_reset(self) -> None:
        in_motion = self._state in ("Run", "Jog") or (self._state == "Hold" and not self._hold_complete)
        if in_motion:
            self._twin_stop()  # GRBL kills the steppers; position may be lost
            self._emit(wire.format_alarm(3))
            self._state = "Alarm"
        self.resets += 1
        self._reset_state()
        if self._state == "Alarm":
            self._emit(wire.format_banner())
            self._emit(wire.format_feedback("MSG", "'$H'|'$X' to unlock"))
        else:
            self._state = "Idle"
            self._emit(wire.format_banner())

    def _report_status(self) -> None:
        pos = self._twin_pos() / (25.4 if self.settings[13] else 1.0)
        sub = None
        if self._state == "Hold":
            sub = 0 if self._hold_complete else 1
        feed = self._current[1] if (self._current is not None and self._state == "Run") else 0.0
        busy = self._state in ("Run", "Hold", "Jog", "Home")
        wco = ovr = None
        if self._wco_counter > 0:
            self._wco_counter -= 1
        else:
            self._wco_counter = (30 if busy else 10) - 1
            if self._ovr_counter == 0:
                self._ovr_counter = 1
            wco = (0.0, 0.0, 0.0)
        if wco is None:
            if self._ovr_counter > 0:
                self._ovr_counter -= 1
            else:
                self._ovr_counter = (20 if busy else 10) - 1
                ovr = (100, 100, 100)
        self.status_reports += 1
        self._emit(wire.format_status(self._state, sub, pos, feed, 0.0, wco, ovr))

    def _feed_hold(self) -> None:
        if self._state in ("Alarm", "Check"):
            return
        if self._state == "Run":
            self._twin_stop()
            self._state, self._hold_complete = "Hold", False
        elif self._state == "Idle":
            self._state, self._hold_complete = "Hold", True

    def _cycle_start(self) -> None:
        if self._state == "Hold" and self._hold_complete:
            if self._current is not None:
                self._issue(self._current)
            elif self._planner:
                self._issue(self._planner.popleft())
            else:
                self._state = "Idle"

    def _issue(self, block: tuple[np.ndarray, float]) -> None:
        target, rate = block
        try:
            with self.rt.lock:
                self.rt.rig.platform.move_to(target, min(rate / 60.0, self._twin_max_speed))
        except DeviceError as exc:  # the stage's end of travel: a hard limit
            log.warning("GRBL emulator: hard limit (%s)", exc)
            self._critical_alarm(1)
            return
        self._current = block
        self._state = "Run"

    def _critical_alarm(self, code: int) -> None:
        self._twin_stop()
        self._planner.clear()
        self._current = None
        self._state = "Alarm"
        self._critical = True
        self._emit(wire.format_alarm(code))
        self._emit(wire.format_feedback("MSG", "Reset to continue"))

    # ---- execution -----------------------------------------------------------------------------
    def _step(self) -> None:
        if self._state == "Run" and not self._twin_moving():
            self._current = None
            if self._planner:
                self._issue(self._planner.popleft())
            else:
                self._state = "Idle"
        elif self._state == "Hold" and not self._hold_complete and not self._twin_moving():
            self._hold_complete = True
        if not self._critical:
            self._parse_lines()

    def _next_line(self) -> tuple[bytes | None, bool]:
        """The next complete line from the receive buffer (None: no line end yet) and whether
        it ran past what is kept of a line."""
        rx, i = self._rx, 0
        while i < len(rx):
            c = rx[i]
            i += 1
            if c in (0x0A, 0x0D):
                del rx[:i]
                line, over = bytes(self._line), self._line_over
                self._line, self._line_over = bytearray(), False
                self.lines_received += 1
                return line, over
            if len(self._line) < _LINE_KEEP:
                self._line.append(c)
            else:
                self._line_over = True
        del rx[:i]
        return None, False

    def _parse_lines(self) -> None:
        while True:
            if self._pending_line is not None:
                line = self._pending_line
            else:
                line, over = self._next_line()
                if line is None:
                    return
                if over:
                    self._emit(wire.format_error(11))
                    continue
            reply = self._execute(line)
            if reply is None:  # waiting on the planner or a dwell
                self._pending_line = line
                return
            self._pending_line = None
            self._emit(reply)
            if self._critical:
                return

    def _execute(self, raw: bytes) -> bytes | None:
        """One received line -> its response (`ok\\r\\n`/`error:N\\r\\n`, after any push messages),
        b"" when it raised a critical alarm (no response), None when it must wait."""
        block, overflow = wire.clean_line(raw)
        if overflow:
            return wire.format_error(11)
        if not block:
            return wire.format_ok()
        if block[0] == "$":
            return self._system_command(block)
        if self._state in ("Alarm", "Jog"):
            return wire.format_error(9)
        try:
            return self._gcode(block)
        except wire.GcodeError as exc:
            return wire.format_error(exc.code)

    def _system_command(self, block: str) -> bytes:
        ok = wire.format_ok()
        if block == "$":
            return wire.format_feedback("HLP", "$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x") + ok
        if block == "$#":
            if self._state not in ("Idle", "Alarm"):
                return wire.format_error(8)
            zero = "0.000,0.000,0.000"
            out = b"".join(wire.format_feedback(f"G{n}", zero) for n in (54, 55, 56, 57, 58, 59, 28, 30, 92))
            return out + wire.format_feedback("TLO", "0.000") + wire.format_feedback("PRB", zero + ":0") + ok
        if block == "$C":
            if self._state == "Check":  # leaving check mode resets GRBL's parser state
                self.resets += 1
                self._reset_state()
                self._state = "Idle"
                return wire.format_feedback("MSG", "Disabled") + ok + wire.format_banner()
            if self._state != "Idle":
                return wire.format_error(8)
            self._state = "Check"
            return wire.format_feedback("MSG", "Enabled") + ok
        if block == "$$":
            out = b""
            for n, v in sorted(self.settings.items()):
                val = f"{v:.3f}" if n in self._float_settings else str(int(v))
                out += f"${n}={val}\r\n".encode("ascii")
            return out + ok
        if block == "$X":
            if self._state == "Alarm":
                self._state = "Idle"
                return wire.format_feedback("MSG", "Caution: Unlocked") + ok
            return ok
        if block == "$H":
            if not self.settings[22]:
                return wire.format_error(5)
            if self._state not in ("Idle", "Alarm"):
                return wire.format_error(8)
            self._state = "Idle"  # the simulated stage knows its position: homing is instant
            return ok
        if block == "$G":
            mode = f"G{int(self._motion)} G54 G17 G{21 if self._unit_mm == 1.0 else 20} G{90 if self._absolute else 91}"
            return wire.format_feedback("GC", f"{mode} G94 M5 M9 T0 F{self._feed_mm_min or 0:.0f} S0") + ok
        if block == "$I":
            return (wire.format_feedback("VER", f"{wire.GRBL_VERSION}.20190830:")
                    + wire.format_feedback("OPT", f"V,{self.planner_blocks - 1},{self.rx_buffer_bytes}") + ok)
        if "=" in block and block[1:].split("=")[0].isdigit():
            num_s, val_s = block[1:].split("=", 1)
            n = int(num_s)
            if n not in self.settings:
                return wire.format_error(3)
            try:
                val = float(val_s)
            except ValueError:
                return wire.format_error(2)
            if val < 0:
                return wire.format_error(4)
            if self._state not in ("Idle", "Alarm"):
                return wire.format_error(8)
            if n == 20 and val and not self.settings[22]:
                return wire.format_error(10)
            self.settings[n] = val
            return ok
        return wire.format_error(3)

    def _gcode(self, block: str) -> bytes | None:
        words = wire.parse_words(block)
        groups: dict[str, float] = {}
        values: dict[str, float] = {}
        for letter, val in words:
            if letter == "G":
                if val not in _ALLOWED_G:
                    raise wire.GcodeError(20, f"G{val:g}")
                group = _MODAL_GROUPS[val]
                if group in groups:
                    raise wire.GcodeError(21, block)
                groups[group] = val
            elif letter in "XYZFPN":
                if letter in values:
                    raise wire.GcodeError(25, letter)
                values[letter] = val
            else:
                raise wire.GcodeError(20, f"{letter}{val:g}")
        unit = {20.0: 25.4, 21.0: 1.0}.get(groups.get("units"), self._unit_mm)
        absolute = {90.0: True, 91.0: False}.get(groups.get("distance"), self._absolute)
        motion = groups.get("motion", self._motion)
        feed = self._feed_mm_min
        if "F" in values:
            if values["F"] < 0:
                raise wire.GcodeError(4, "F")
            feed = values["F"] * unit
        axes = [a for a in "XYZ" if a in values]
        dwell = groups.get("nonmodal") == 4.0
        if dwell:
            if "P" not in values:
                raise wire.GcodeError(28, "G4 needs P")
            if values["P"] < 0:
                raise wire.GcodeError(4, "P")
            if axes and "motion" in groups:
                raise wire.GcodeError(24, block)
        target = None
        if axes and not dwell:
            if motion == 1.0 and not feed:
                raise wire.GcodeError(22, block)
            if self._gc_pos is None:
                self._gc_pos = self._twin_pos()
            target = self._gc_pos.copy()
            for i, a in enumerate("XYZ"):
                if a in values:
                    v = values[a] * unit
                    target[i] = v if absolute else target[i] + v
            if len(self._planner) + (self._current is not None) >= self.planner_blocks:
                return None  # planner full: the line waits, its ok with it
        # the block is valid: commit its modal state
        self._unit_mm, self._absolute, self._motion, self._feed_mm_min = unit, absolute, motion, feed
        if dwell:
            if self._state == "Check":
                return wire.format_ok()
            if self._state != "Idle" or self._planner:
                return None  # G4 waits for the planner to empty
            now = time.monotonic()
            if self._dwell_until is None:
                self._dwell_until = now + values["P"]
            if now < self._dwell_until:
                return None
            self._dwell_until = None
            return wire.format_ok()
        if target is not None:
            if self.settings[20] and np.any((target > self._ws_max + 1e-9) | (target < self._ws_max - self._travel() - 1e-9)):
                self._critical_alarm(2)
                return b""
            if self._state == "Check":  # parsed, not moved
                self._gc_pos = target
            elif self._plan(target, motion):
                self._gc_pos = target
        return wire.format_ok()

    def _travel(self) -> np.ndarray:
        return np.array([self.settings[130], self.settings[131], self.settings[132]], float)

    def _plan(self, target: np.ndarray, motion: float) -> bool:
        """Queue a line move (GRBL's planner); start it at once when idle (auto cycle start)."""
        delta = target - self._gc_pos
        length = float(np.linalg.norm(delta))
        if length < 1e-6:
            return False  # GRBL plans nothing for a zero-length move
        u = np.abs(delta) / length
        max_rate = np.array([self.settings[110], self.settings[111], self.settings[112]], float)
        limit = float(np.min(max_rate[u > 1e-12] / u[u > 1e-12]))
        rate = limit if motion == 0.0 else min(self._feed_mm_min, limit)
        block = (target.copy(), rate)
        if self._state == "Idle" and self._current is None and not self._planner:
            self._issue(block)
        else:
            self._planner.append(block)
        return True
