"""A GRBL 1.1 controller on a pseudo-terminal, driving the simulated platform of a RealtimeWorld.

What it models (from gnea/grbl 1.1h's source and interface docs):
- the welcome banner at start and after every soft reset, then the startup lines (`$N0`, `$N1`:
  `>line:ok`) when GRBL comes up idle, or `[MSG:'$H'|'$X' to unlock]` when it comes up in alarm;
- a 128-byte serial receive buffer that the protocol loop empties into its line buffer while it is
  not waiting on the planner, a dwell or a program pause; bytes arriving when it is full (a host
  that does not count characters) are dropped (counted in `rx_overflow_bytes` and logged);
  real-time bytes `?` `!` `~` Ctrl-X, jog cancel 0x85 and the feed overrides 0x90-0x94 are picked
  off before it; other bytes above 0x7F are thrown away;
- an 80-character line buffer: a longer line answers `error:11` and the parser goes on with the next;
- G-code blocks as `gcode.py` parses them (G0 G1 G4 G17 G20 G21 G53 G54 G90 G91 G94, M0 M1 M2 M30
  M3 M4 M5 M8 M9, F N P S T X Y Z); M0 waits for the planner to empty, holds (Hold:0) and answers
  `ok` after `~`; M2/M30 wait for the planner, reset the modal groups and the overrides, print
  `[MSG:Pgm End]` and answer `ok`; spindle and coolant are tracked and reported, nothing is wired;
- `$J=` jogs (state Jog; queued like moves; soft limits answer error:15 and skip the jog; no feed
  override; 0x85 or `!` cancels: decelerate, flush the queue, Idle);
- `$$`, `$#` (coordinate offsets, all zero: no G10/G92 here), `$C` (check mode: lines are parsed,
  nothing moves; leaving it resets), `$X`, `$H`, `$G`, `$I`, `$`, `$N=value`, `$N` and `$Nx=line`
  (two startup lines, validated by running them), `$SLP` (sleep: only `?` and Ctrl-X until a reset,
  which comes back in alarm), `$RST=$` / `$RST=#` / `$RST=*` (defaults back, then a reset);
  each line answers `ok` or `error:N`;
- a planner queue (16 blocks): queued moves go to the twin one after the other; a line that finds
  the planner full waits (its `ok` with it) as in GRBL;
- feeds above the axes' max rates ($110-112) are clamped as GRBL's planner does (the nominal rate is
  limited to min_i(max_rate_i / |u_i|) for the move's unit vector u); G0 runs at that limit; the
  feed override (10-200 %) scales G1 feeds within the same limit, also for the move under way;
- soft limits ($20=1, travel $130-132): a motion target outside the travel box raises ALARM:2 and
  `[MSG:Reset to continue]`; GRBL then ignores all but `?` and Ctrl-X until reset, and comes back
  in alarm (needs `$X`). With soft limits off, a target outside the stage's travel hits the end:
  ALARM:1;
- feed hold `!` (Run -> Hold:1 while decelerating -> Hold:0), resume `~`, soft reset Ctrl-X: reset
  while in motion (Run, Jog or Hold:1) raises ALARM:3 and leaves GRBL in alarm; from Idle or Hold:0
  it does not;
- status reports `<Idle|MPos:x,y,z|FS:f,s>` with `WCO:` on the first report after a reset and every
  10th (idle) / 30th (busy) after, `Ov:` (and `A:` while spindle or coolant is on) on the next and
  on the report after an override changed.

Coordinates: MPos equals the twin's position (the skin frame). A real GRBL homed at its switches
reports MPos in [-$13x, 0]; here that box is shifted to end at the stage's workspace_max, i.e.
travel box = [workspace_max - $13x, workspace_max], so the default travel is the stage's workspace.

Not modelled: G10/G28/G30/G92 offsets, arcs, probing (error:20, as unsupported commands), real
homing motion (`$H` only clears the alarm: the simulated stage knows its position), rapid and
spindle overrides (0x95-0x9E are taken and ignored: `Ov:` keeps 100 for them), `$I=` build info,
EEPROM timing, the 500 ms pause GRBL takes after printing an ALARM, baud-rate pacing.

Faults (hardware.emulation's vocabulary): stall() (stops reading and answering: a hung
controller; resume() ends it), disconnect() (closes the line's device end: the host sees the port vanish),
drop(n) (the next n messages to the host are lost), corrupt(n, how) (the next n messages arrive as
"noise": line noise before the message, or "garbled": a byte of the message changed);
start_in_alarm=True (power-up alarm, as with homing enabled).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Generator
from dataclasses import dataclass, replace

import numpy as np

from hardware.emulation import (
    DeviceProcess,
    Emulator,
    Pty,
    TcpSerialLink,
    check_serial_link,
    serial_link,
)
from hardware.interfaces import DeviceError
from hardware.platform import gcode, wire

log = logging.getLogger(__name__)

EMULATOR_SETUP = "platform"

_LINE_KEEP = 4 * wire.LINE_BUFFER_SIZE  # raw bytes of a line kept for parsing (beyond: error:11 anyway)
_NOISE = b"\x00\xff\x13#~garbage\r\n"
_STARTUP_LINES = 2  # config.h N_STARTUP_LINE
_BRIDGE_PERIOD_S = 0.002  # how often the bridge looks at the stage (it sends what changed)
_Pending = Generator[None, None, bytes]  # a line's execution waiting on the machine; returns its response
_FEED_OVR_STEP = {wire.FEED_OVR_COARSE_PLUS[0]: 10, wire.FEED_OVR_COARSE_MINUS[0]: -10,
                  wire.FEED_OVR_FINE_PLUS[0]: 1, wire.FEED_OVR_FINE_MINUS[0]: -1}


@dataclass(frozen=True)
class _Move:
    """A planner block: machine target (3,) mm, programmed rate and the axes' limit along it (mm/min)."""

    target: np.ndarray
    rate_mm_min: float
    limit_mm_min: float
    kind: str  # "feed" (G1: feed override applies), "rapid" (G0), "jog"


class GrblMachine(Emulator):
    """GRBL 1.1h on a serial line (a pty, or loopback TCP with link="tcp"), backed by
    `rt.rig.platform`; `start()` returns what to open: the pty's path or a socket:// URL.
    (Runs in the controller's own process, hardware.platform.machine; `GrblEmulator` starts it.)

    host/port: accepted for the common emulator signature; a serial device has neither.
    """

    DEVICE = "platform"
    TWINS = ()  # reads the stage's position directly, as GRBL counts its own steps
    CORRUPTIONS = ("noise", "garbled")

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, *, start_in_alarm: bool = False,
                 planner_blocks: int = wire.PLANNER_BLOCKS, rx_buffer_bytes: int = wire.RX_BUFFER_BYTES,
                 tick_s: float = 0.001, link: str = "pty", stall_after_s: float | None = None,
                 disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        self.link = link  # "pty" | "tcp" (hardware.emulation.serial_link)
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
        self._default_settings = dict(self.settings)  # this build's defaults.h: what $RST=$ restores
        self._float_settings = {11, 12, 24, 25, 27, 100, 101, 102, 110, 111, 112, 120, 121, 122, 130, 131, 132}
        self.startup_lines = [""] * _STARTUP_LINES  # $N0, $N1 (EEPROM: kept across resets)
        # counters
        self.rx_overflow_bytes = 0
        self.tx_dropped_bytes = 0
        self.lines_received = 0
        self.status_reports = 0
        self.resets = 0
        self.path: str | None = None
        self.line: Pty | TcpSerialLink | None = None  # the serial line's device end
        self._reset_state(power_up=True)

    # ---- life cycle ----------------------------------------------------------------------------
    def _open(self) -> str:
        # Held: GRBL's replies wait in the port for the host to read them.
        self.line = serial_link(self.link, hold=True)
        self.path = self.line.path
        self._come_up()
        self._spawn(self._run, "serial")
        return self.path

    def _close(self) -> None:
        if self.line is not None:
            self.line.close()

    @property
    def state(self) -> str:
        return self._state

    @property
    def feed_override(self) -> int:
        """The feed override, percent."""
        return self._feed_ovr

    # ---- machine state -------------------------------------------------------------------------
    def _reset_state(self, power_up: bool = False) -> None:
        if power_up:
            self._state = "Alarm" if self.start_in_alarm else "Idle"
        self._critical = False  # soft/hard limit alarm: only '?' and Ctrl-X until reset
        self._hold_complete = False
        self._jog_cancel = False  # a jog cancel decelerating
        self._rx = bytearray()  # the serial receive buffer
        self._line = bytearray()  # the line being assembled from it
        self._line_over = False  # that line ran past _LINE_KEEP bytes
        self._planner: deque[_Move] = deque()
        self._current: _Move | None = None
        self._waiting: _Pending | None = None
        self._then = None  # what follows a line's response ($SLP, $RST, leaving $C)
        self._modal = gcode.Modal()
        self._outputs = _outputs(self._modal)  # spindle, coolant, rpm as driven (a reset turns them off)
        self._gc_pos: np.ndarray | None = None  # parser position; synced to the machine at first use
        self._feed_ovr = 100
        self._wco_counter = 0
        self._ovr_counter = 1

    def _come_up(self) -> None:
        """What GRBL prints after power-up or a reset: the banner, then the alarm lock message or
        the startup lines."""
        self._emit(wire.format_banner())
        if self._state == "Alarm":
            self._emit(wire.format_feedback("MSG", "'$H'|'$X' to unlock"))
        else:
            self._emit(self._run_startup_lines())

    def _run_startup_lines(self) -> bytes:
        out = b""
        for line in self.startup_lines:
            if line:
                out += b">" + line.encode("ascii") + b":" + _now(self._gcode(line))
        return out

    def _twin_pos(self) -> np.ndarray:
        with self.rt.lock:
            return self.rt.rig.platform.position_mm()

    def _twin_moving(self) -> bool:
        with self.rt.lock:
            return self.rt.rig.platform.is_moving()

    def _twin_stop(self) -> None:
        with self.rt.lock:
            self.rt.rig.platform.stop()

    def _locked(self) -> bool:
        """Lines are not read: a critical alarm or sleep (only '?' and Ctrl-X act)."""
        return self._critical or self._state == "Sleep"

    # ---- main loop -----------------------------------------------------------------------------
    def _run(self) -> None:
        line = self.line
        while not self._stop.is_set():
            if self.disconnected:
                line.close()
                return
            if self.stalled:
                time.sleep(self.tick_s)
                continue
            for b in line.read(self.tick_s):
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
            n = self.line.write(view)
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
            if b == wire.JOG_CANCEL[0]:
                self._cancel_jog()
            elif b == wire.FEED_OVR_RESET[0] or b in _FEED_OVR_STEP:
                self._override_feed(b)
            # any other extended-ASCII byte: thrown away, never buffered (serial.c)
        elif len(self._rx) >= self.rx_buffer_bytes:
            self.rx_overflow_bytes += 1
            if self.rx_overflow_bytes == 1 or self.rx_overflow_bytes % 100 == 0:
                log.warning("GRBL emulator: receive buffer full (%d bytes); %d byte(s) dropped so far - "
                            "the host is not counting characters", self.rx_buffer_bytes, self.rx_overflow_bytes)
        else:
            self._rx.append(b)
            if self._waiting is None and not self._locked():
                self._parse_lines()  # the protocol loop empties the buffer while it is free

    # ---- real-time commands ----------------------------------------------------------------------
    def _soft_reset(self) -> None:
        in_motion = self._state in ("Run", "Jog") or (self._state == "Hold" and not self._hold_complete)
        if in_motion:
            self._twin_stop()  # GRBL kills the steppers; position may be lost
            self._emit(wire.format_alarm(3))
            self._state = "Alarm"
        elif self._state == "Sleep":
            self._state = "Alarm"  # the steppers were off: position is not guaranteed
        elif self._state != "Alarm":
            self._state = "Idle"
        self.resets += 1
        self._reset_state()
        self._come_up()

    def _report_status(self) -> None:
        pos = self._twin_pos() / (25.4 if self.settings[13] else 1.0)
        sub = None
        if self._state == "Hold":
            sub = 0 if self._hold_complete else 1
        moving = self._current is not None and self._state in ("Run", "Jog")
        feed = self._rate(self._current) if moving else 0.0
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
                ovr = (self._feed_ovr, 100, 100)
        spindle, coolant, _ = self._outputs
        accessories = {3: "S", 4: "C"}.get(spindle, "") + ("F" if coolant == 8 else "")
        self.status_reports += 1
        self._emit(wire.format_status(self._state, sub, pos, feed, self._spindle_rpm(), wco, ovr, accessories))

    def _spindle_rpm(self) -> float:
        """The spindle speed GRBL reports: S clamped to [$31, $30] while M3/M4 is on, 0 for S0 or M5."""
        spindle, _, s = self._outputs
        if spindle == 5 or s <= 0:
            return 0.0
        return float(min(max(s, self.settings[31]), self.settings[30]))

    def _feed_hold(self) -> None:
        if self._state in ("Alarm", "Check", "Sleep"):
            return
        if self._state == "Jog":
            self._cancel_jog()  # a hold cancels jogging (protocol.c)
        elif self._state == "Run":
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

    def _cancel_jog(self) -> None:
        """0x85: decelerate, flush the queued jogs, then Idle at wherever the stage stopped."""
        if self._state == "Jog" and not self._jog_cancel:
            self._twin_stop()
            self._planner.clear()
            self._jog_cancel = True

    def _override_feed(self, b: int) -> None:
        new = 100 if b == wire.FEED_OVR_RESET[0] else self._feed_ovr + _FEED_OVR_STEP[b]
        new = min(max(new, wire.FEED_OVR_MIN), wire.FEED_OVR_MAX)
        if new == self._feed_ovr:
            return
        self._feed_ovr = new
        self._ovr_counter = 0  # report the change on the next status report
        if self._state == "Run" and self._current is not None and self._current.kind == "feed":
            self._issue(self._current)  # the move under way changes speed

    def _rate(self, move: _Move) -> float:
        """A move's nominal rate (mm/min): feed moves scaled by the override, all within the axes' limit."""
        if move.kind == "feed":
            return min(move.rate_mm_min * self._feed_ovr / 100.0, move.limit_mm_min)
        return move.rate_mm_min

    def _issue(self, move: _Move) -> None:
        try:
            with self.rt.lock:
                self.rt.rig.platform.move_to(move.target, min(self._rate(move) / 60.0, self._twin_max_speed))
        except DeviceError as exc:  # the stage's end of travel: a hard limit
            log.warning("GRBL emulator: hard limit (%s)", exc)
            self._critical_alarm(1)
            return
        self._current = move
        self._state = "Jog" if move.kind == "jog" else "Run"

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
        if self._state in ("Run", "Jog") and not self._twin_moving():
            self._current = None
            if self._jog_cancel:
                self._jog_cancel = False
                self._gc_pos = None  # the parser takes the position where the jog stopped
                self._state = "Idle"
            elif self._planner:
                self._issue(self._planner.popleft())
            else:
                self._state = "Idle"
        elif self._state == "Hold" and not self._hold_complete and not self._twin_moving():
            self._hold_complete = True
        if not self._locked():
            self._parse_lines()

    def _busy(self) -> bool:
        """Motion queued or under way (GRBL's protocol_buffer_synchronize waits while this holds)."""
        return self._current is not None or bool(self._planner) or self._state in ("Run", "Jog")

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
            if self._waiting is not None:
                try:
                    next(self._waiting)
                    return  # still waiting on the machine
                except StopIteration as done:
                    reply = done.value
                self._waiting = None
            else:
                line, over = self._next_line()
                if line is None:
                    return
                reply = wire.format_error(11) if over else self._execute(line)
                if not isinstance(reply, bytes):
                    self._waiting = reply
                    continue  # its execution waits (polled above)
            self._emit(reply)
            if self._then is not None:
                then, self._then = self._then, None
                then()
            if self._locked():
                return

    def _execute(self, raw: bytes) -> bytes | _Pending:
        """One received line -> its response (`ok\\r\\n`/`error:N\\r\\n`, after any push messages;
        b"" when it raised a critical alarm: no response), or, when its execution waits on the
        machine, a generator to poll that returns the response."""
        block, overflow = wire.clean_line(raw)
        if overflow:
            return wire.format_error(11)
        if not block:
            return wire.format_ok()
        if block[0] == "$":
            return self._system_command(block)
        if self._state in ("Alarm", "Jog"):
            return wire.format_error(9)
        return self._gcode(block)

    def _system_command(self, block: str) -> bytes | _Pending:
        ok = wire.format_ok()
        if block == "$":
            return wire.format_feedback("HLP", "$$ $# $G $I $N $x=val $Nx=line $J=line $SLP $C $X $H ~ ! ? ctrl-x") + ok
        if block.startswith("$J"):
            if self._state not in ("Idle", "Jog"):
                return wire.format_error(8)
            if not block.startswith("$J="):
                return wire.format_error(3)
            return self._jog(block[3:])
        if block == "$C":
            if self._state == "Check":  # leaving check mode resets GRBL
                self._then = self._soft_reset
                return wire.format_feedback("MSG", "Disabled") + ok
            if self._state != "Idle":
                return wire.format_error(8)
            self._state = "Check"
            return wire.format_feedback("MSG", "Enabled") + ok
        if block == "$$":
            if self._state in ("Run", "Hold"):
                return wire.format_error(8)
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
        if block == "$G":
            return wire.format_feedback("GC", self._modal.report()) + ok
        # the rest only while Idle or in alarm (system.c)
        if self._state not in ("Idle", "Alarm"):
            return wire.format_error(8)
        if block == "$#":
            zero = "0.000,0.000,0.000"
            out = b"".join(wire.format_feedback(f"G{n}", zero) for n in (54, 55, 56, 57, 58, 59, 28, 30, 92))
            return out + wire.format_feedback("TLO", "0.000") + wire.format_feedback("PRB", zero + ":0") + ok
        if block == "$H":
            if not self.settings[22]:
                return wire.format_error(5)
            self._state = "Idle"  # the simulated stage knows its position: homing is instant
            return self._run_startup_lines() + ok
        if block == "$I":
            return (wire.format_feedback("VER", f"{wire.GRBL_VERSION}.20190830:")
                    + wire.format_feedback("OPT", f"V,{self.planner_blocks - 1},{self.rx_buffer_bytes}") + ok)
        if block.startswith("$S"):
            if block != "$SLP":
                return wire.format_error(3)
            self._then = self._sleep
            return ok
        if block.startswith("$R"):
            if len(block) != 6 or not block.startswith("$RST=") or block[5] not in "$#*":
                return wire.format_error(3)
            if block[5] in "$*":
                self.settings = dict(self._default_settings)
            if block[5] == "*":
                self.startup_lines = [""] * _STARTUP_LINES
            # ('#': the coordinate offsets, G28/G30 positions and probe result: all zero here already)
            self._then = self._soft_reset
            return wire.format_feedback("MSG", "Restoring defaults") + ok
        if block.startswith("$N"):
            return self._startup_line(block)
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
            if n == 20 and val and not self.settings[22]:
                return wire.format_error(10)
            self.settings[n] = val
            return ok
        return wire.format_error(3)

    def _startup_line(self, block: str) -> bytes | _Pending:
        """`$N` lists the startup lines; `$Nx=line` runs the line and stores it if it was valid G-code."""
        if block == "$N":
            return b"".join(f"$N{i}={line}\r\n".encode("ascii") for i, line in enumerate(self.startup_lines)) \
                + wire.format_ok()
        if self._state != "Idle":
            return wire.format_error(8)
        num, eq, line = block[2:].partition("=")
        if not num.isdigit():
            return wire.format_error(2)
        if not eq or int(num) >= _STARTUP_LINES:  # (GRBL 1.1h would write past its two EEPROM slots)
            return wire.format_error(3)
        def run_then_store() -> _Pending:
            result = self._gcode(line) if line else wire.format_ok()
            reply = result if isinstance(result, bytes) else (yield from result)
            if reply == wire.format_ok():
                self.startup_lines[int(num)] = line
            return reply

        return run_then_store()

    def _sleep(self) -> None:
        """$SLP, after its ok: steppers, spindle and coolant off; only '?' and Ctrl-X until a reset."""
        self._twin_stop()
        self._planner.clear()
        self._current = None
        self._modal = replace(self._modal, spindle=5, coolant=9)
        self._set_outputs(_outputs(self._modal))
        self._state = "Sleep"
        self._emit(wire.format_feedback("MSG", "Sleeping"))

    def _jog(self, text: str) -> bytes | _Pending:
        try:
            blk = gcode.parse_block(text, self._modal, self._parser_pos(), jog=True)
        except wire.GcodeError as exc:
            return wire.format_error(exc.code)
        target = blk.target_mm
        if self.settings[20] and self._outside_travel(target):
            return wire.format_error(15)  # the jog is skipped; no alarm (jog.c)
        return self._plan_when_free(target, blk.feed_mm_min, "jog")

    def _gcode(self, block: str) -> bytes | _Pending:
        try:
            blk = gcode.parse_block(block, self._modal, self._parser_pos())
        except wire.GcodeError as exc:
            return wire.format_error(exc.code)
        self._modal = blk.modal
        if (blk.dwell_s is None and blk.target_mm is None and blk.program_flow is None
                and (_outputs(blk.modal) == self._outputs or self._state == "Check")):
            return wire.format_ok()
        return self._run_block(blk)

    def _parser_pos(self) -> np.ndarray:
        if self._gc_pos is None:
            self._gc_pos = self._twin_pos()
        return self._gc_pos.copy()

    def _outside_travel(self, target: np.ndarray) -> bool:
        lo = self._ws_max - self._travel()
        return bool(np.any((target > self._ws_max + 1e-9) | (target < lo - 1e-9)))

    def _run_block(self, blk: gcode.Block) -> _Pending:
        """A valid block's execution, in GRBL's order: spindle and coolant, dwell, motion, program flow."""
        check = self._state == "Check"
        if _outputs(blk.modal) != self._outputs and not check:
            while self._busy():  # spindle_sync/coolant_sync: switched once the queued moves are done
                yield
            self._set_outputs(_outputs(blk.modal))
        if blk.dwell_s is not None and not check:
            while self._busy():  # G4 waits for the planner to empty
                yield
            until = time.monotonic() + blk.dwell_s
            while time.monotonic() < until:
                yield
        if blk.target_mm is not None:
            if self.settings[20] and self._outside_travel(blk.target_mm):
                self._critical_alarm(2)
                return b""
            if check:  # parsed, not moved
                self._gc_pos = blk.target_mm
            else:
                yield from self._plan_when_free(blk.target_mm, blk.feed_mm_min, "rapid" if blk.rapid else "feed")
        if blk.program_flow is None:
            return wire.format_ok()
        while self._busy():
            yield
        if blk.program_flow == 0:  # M0: a feed hold once the planner is empty; ok after '~'
            if not check:
                self._state, self._hold_complete = "Hold", True
                while self._state == "Hold":
                    yield
            return wire.format_ok()
        self._modal = self._modal.program_end()
        self._feed_ovr = 100  # RESTORE_OVERRIDES_AFTER_PROGRAM_END (config.h default)
        if not check:
            self._wco_counter = 0
            self._set_outputs(_outputs(self._modal))
        return wire.format_feedback("MSG", "Pgm End") + wire.format_ok()

    def _plan_when_free(self, target: np.ndarray, rate_mm_min: float, kind: str) -> _Pending:
        """Queue a line move once the planner has room (GRBL's planner); start it when idle."""
        while len(self._planner) + (self._current is not None) >= self.planner_blocks:
            yield
        delta = target - self._parser_pos()
        self._gc_pos = target.copy()
        length = float(np.linalg.norm(delta))
        if length < 1e-6:
            return wire.format_ok()  # GRBL plans nothing for a zero-length move
        u = np.abs(delta) / length
        max_rate = np.array([self.settings[110], self.settings[111], self.settings[112]], float)
        limit = float(np.min(max_rate[u > 1e-12] / u[u > 1e-12]))
        rate = limit if kind == "rapid" else min(rate_mm_min, limit)
        move = _Move(target.copy(), rate, limit, kind)
        if self._state in ("Idle", "Jog") and self._current is None and not self._planner:
            self._issue(move)
        else:
            self._planner.append(move)
        return wire.format_ok()

    def _set_outputs(self, outputs: tuple[int, int, float]) -> None:
        if outputs != self._outputs:
            self._outputs = outputs
            self._ovr_counter = 0  # GRBL reports a spindle or coolant change on the next report

    def _travel(self) -> np.ndarray:
        return np.array([self.settings[130], self.settings[131], self.settings[132]], float)


class GrblEmulator(Emulator):
    """GRBL 1.1h on a serial line (a pty, or loopback TCP with link="tcp"), backed by
    `rt.rig.platform`; `start()` returns what to open: the pty's path or a socket:// URL.

    The controller (GrblMachine) runs in a process of its own (hardware.platform.machine, which
    says why); this object starts it and runs the bridge thread that, every millisecond, pushes
    the stage's position and motion (taken under `rt.lock`) and applies the moves and stops the
    controller sends back to `rt.rig.platform`. The controller's state and counters (state,
    feed_override, rx_overflow_bytes, ...) are asked of it when read. host/port: accepted for the common emulator
    signature; a serial device has neither.
    """

    DEVICE = "platform"
    TWINS = ()  # reads the stage's position directly, as GRBL counts its own steps
    CORRUPTIONS = GrblMachine.CORRUPTIONS

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, *, start_in_alarm: bool = False,
                 planner_blocks: int = wire.PLANNER_BLOCKS, rx_buffer_bytes: int = wire.RX_BUFFER_BYTES,
                 tick_s: float = 0.001, link: str = "pty", stall_after_s: float | None = None,
                 disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        check_serial_link(link, "GRBL")
        self._options = {"start_in_alarm": bool(start_in_alarm), "planner_blocks": int(planner_blocks),
                         "rx_buffer_bytes": int(rx_buffer_bytes), "tick_s": float(tick_s), "link": link}
        self.tick_s = float(tick_s)
        self.path: str | None = None
        self._machine: DeviceProcess | None = None
        self._info: dict = {"state": "Alarm" if start_in_alarm else "Idle", "feed_override": 100}
        self._applied_id = 0

    # ---- the controller's read-out --------------------------------------------------------------
    def __getattr__(self, name: str):
        if name in ("state", "feed_override", "rx_overflow_bytes", "tx_dropped_bytes", "lines_received",
                    "status_reports", "resets"):
            machine = self.__dict__.get("_machine")
            if machine is not None and self.running:  # a fresh read-out: at least what the port has shown
                machine.send(("readout",))
                machine.wait_ack("readout", lambda v: True)
            return self.__dict__.get("_info", {}).get(name, 0)
        raise AttributeError(name)

    def _twin_pos(self) -> np.ndarray:
        with self.rt.lock:
            return self.rt.rig.platform.position_mm()

    # ---- life cycle ----------------------------------------------------------------------------
    def _open(self) -> str:
        cfg = self.rt.rig.platform.cfg
        stage = {k: np.asarray(getattr(cfg, k), float).tolist() if k.startswith("workspace") else float(getattr(cfg, k))
                 for k in ("workspace_min_mm", "workspace_max_mm", "max_speed_mm_s", "max_accel_mm_s2")}
        opts = {**self._options, "stage": stage, "position": self._twin_pos().tolist()}
        self._machine = DeviceProcess("hardware.platform.machine", opts, self.DEVICE, log)
        self.path = self._serve_device(self._machine)
        return self.path

    def _close(self) -> None:
        if self._machine is not None:
            self._machine.close()
            self._machine = None

    # ---- faults: carried out by the controller process -------------------------------------------
    def _on_stall(self, stalled: bool) -> None:
        if self._machine is None:
            return
        if stalled:
            left = self._stall_until - time.monotonic()
            self._machine.send(("stall", None if left == float("inf") else max(left, 0.0)))
        else:
            self._machine.send(("resume",))
        self._machine.wait_ack("stall", lambda v: v == stalled)

    def _on_disconnect(self) -> None:
        if self._machine is not None:
            self._machine.send(("disconnect",))

    def _device(self) -> DeviceProcess | None:
        return self._machine

    # ---- bridge ----------------------------------------------------------------------------------
    def _bridge(self) -> None:
        machine = self._machine
        last, last_t = None, 0.0
        try:
            while not self._stop.is_set():
                machine.poll(max(self.tick_s, _BRIDGE_PERIOD_S), self._handle)
                if machine.ready.is_set() and machine.error is None:
                    with self.rt.lock:
                        stage = self.rt.rig.platform
                        state = (stage.position_mm().tolist(), bool(stage.is_moving()), self._applied_id)
                    now = time.monotonic()
                    if state != last or now - last_t > 0.01:  # what changed, and a heartbeat
                        machine.send(("state", *state))
                        last, last_t = state, now
        except (EOFError, OSError) as exc:
            if not self._stop.is_set():
                log.warning("GRBL emulator: the controller process went away (%s)", exc)
                self.error = self.error or exc
                machine.went_away(exc)

    def _handle(self, msg: tuple) -> None:
        kind = msg[0]
        if kind == "info":
            info = msg[1]
            for k in ("drop", "corrupt"):  # applied in the controller; stall and disconnect are counted here
                if info["fault_counts"].get(k):
                    self.fault_counts[k] = info["fault_counts"][k]
            if info["error"] and self.error is None:
                self.error = RuntimeError(info["error"])
            self._info = info
        elif kind == "move":
            try:
                with self.rt.lock:
                    self.rt.rig.platform.move_to(np.asarray(msg[2], float), msg[3])
            except DeviceError as exc:
                log.warning("GRBL emulator: %s", exc)
            self._applied_id = max(self._applied_id, msg[1])
        elif kind == "stop":
            with self.rt.lock:
                self.rt.rig.platform.stop()
            self._applied_id = max(self._applied_id, msg[1])


def _now(result: bytes | _Pending) -> bytes:
    """A startup line's response: GRBL runs it to the end before going on (a dwell in one is not
    waited for here)."""
    if isinstance(result, bytes):
        return result
    try:
        next(result)
    except StopIteration as done:
        return done.value
    return wire.format_ok()


def _outputs(modal: gcode.Modal) -> tuple[int, int, float]:
    """What the spindle and coolant pins are told: direction, coolant, and the speed while on."""
    return modal.spindle, modal.coolant, modal.spindle_rpm if modal.spindle != 5 else 0.0
