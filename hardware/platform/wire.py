"""GRBL 1.1 serial dialect: line framing, message parsing, encoding; no I/O.

Shared by the driver (`driver.py`) and the emulator (`emulator.py`) so they cannot drift.
The interface is GRBL 1.1's (gnea/grbl `doc/markdown/interface.md`, `commands.md`, `settings.md`):

- Lines the host sends end in `\\n` alone. GRBL ends a line at `\\r` *or* `\\n`, so `\\r\\n` would be
  two lines and draw two responses; character counting needs exactly one response per line.
- Every line draws one response message, `ok` or `error:N`. Everything else GRBL prints is a push
  message: `<...>` status reports, `ALARM:N`, `Grbl 1.1h ['$' for help]` (the welcome banner,
  printed after power-up and after every soft reset), `[MSG:...]` and other `[...]` feedback,
  `$N=value` settings, `>line:ok` startup-line results.
- Real-time commands are single bytes picked off the serial stream before the receive buffer:
  `?` status report, `!` feed hold, `~` cycle start/resume, 0x18 (Ctrl-X) soft reset.
- Character counting: GRBL's serial receive buffer holds 128 bytes; the host may have at most that
  many bytes of unanswered lines in flight (each line's bytes, newline included, are freed by
  that line's `ok`/`error`). `CharCounter` does the accounting.
"""

from __future__ import annotations

import re
from collections import deque
from dataclasses import dataclass, field

RX_BUFFER_BYTES = 128  # GRBL's serial receive buffer (serial.h RX_BUFFER_SIZE)
LINE_BUFFER_SIZE = 80  # GRBL's line buffer (protocol.h); longer lines draw error:11
PLANNER_BLOCKS = 16  # GRBL's look-ahead planner (config.h BLOCK_BUFFER_SIZE on the Uno)

STATUS_QUERY = b"?"
FEED_HOLD = b"!"
SOFT_RESET = b"\x18"
# Extended-ASCII real-time commands (GRBL 1.1 config.h CMD_*); bytes above 0x7F that GRBL does not
# know are thrown away, never buffered.
JOG_CANCEL = b"\x85"
FEED_OVR_RESET = b"\x90"  # feed override back to 100 %
FEED_OVR_COARSE_PLUS = b"\x91"  # +10 %
FEED_OVR_COARSE_MINUS = b"\x92"  # -10 %
FEED_OVR_FINE_PLUS = b"\x93"  # +1 %
FEED_OVR_FINE_MINUS = b"\x94"  # -1 %
FEED_OVR_MIN, FEED_OVR_MAX = 10, 200  # config.h MIN/MAX_FEED_RATE_OVERRIDE (percent)

GRBL_VERSION = "1.1h"

# error:N meanings (interface.md "Grbl Response Messages"), shortened.
ERROR_CODES: dict[int, str] = {
    1: "G-code word without a letter",
    2: "bad or missing number",
    3: "'$' system command not recognised",
    4: "negative value where a positive one is expected",
    5: "homing cycle not enabled in settings",
    6: "step pulse time below 3 us",
    7: "EEPROM read failed; defaults restored",
    8: "'$' command only allowed while idle",
    9: "G-code locked out during alarm or jog",
    10: "soft limits need homing enabled",
    11: "line longer than the line buffer",
    12: "setting exceeds the maximum step rate",
    13: "safety door open",
    14: "build info or startup line too long",
    15: "jog target exceeds machine travel",
    16: "invalid jog command",
    17: "laser mode needs PWM output",
    20: "unsupported or invalid G-code command",
    21: "two G-code commands from the same modal group",
    22: "feed rate not set",
    23: "G-code command needs an integer value",
    24: "two G-code commands that both need axis words",
    25: "G-code word repeated in the block",
    26: "G-code command needs axis words, none given",
    27: "line number out of range",
    28: "missing P or L value word",
    29: "unsupported work coordinate system",
    30: "G53 needs G0 or G1 motion mode",
    31: "axis words with G80 motion cancel",
    32: "arc without axis words in the plane",
    33: "invalid motion target",
    34: "arc radius definition error",
    35: "arc offset definition missing IJK",
    36: "unused leftover G-code words",
    37: "tool length offset on an unsupported axis",
    38: "tool number too large",
}

# ALARM:N meanings (interface.md "Alarm Message").
ALARM_CODES: dict[int, str] = {
    1: "hard limit triggered; machine position likely lost, re-home",
    2: "soft limit: G-code motion target exceeds machine travel; position retained, unlock with $X",
    3: "reset while in motion; position may be lost, re-home",
    4: "probe fail: probe not in the expected initial state",
    5: "probe fail: no contact within the programmed travel",
    6: "homing fail: reset during homing",
    7: "homing fail: safety door opened during homing",
    8: "homing fail: could not clear the limit switch on pull-off",
    9: "homing fail: limit switch not found within the search distance",
}

MOVING_STATES = frozenset({"Run", "Jog", "Home"})


class GrblParseError(ValueError):
    """A line from GRBL that is none of the 1.1 message types (noise, a corrupted line)."""


def describe_error(code: int) -> str:
    return ERROR_CODES.get(code, "unknown error code")


def describe_alarm(code: int) -> str:
    return ALARM_CODES.get(code, "unknown alarm code")


# ---- messages GRBL sends ---------------------------------------------------------------------
@dataclass(frozen=True)
class Ok:
    pass


@dataclass(frozen=True)
class Error:
    code: int

    def __str__(self) -> str:
        return f"error:{self.code} ({describe_error(self.code)})"


@dataclass(frozen=True)
class Alarm:
    code: int

    def __str__(self) -> str:
        return f"ALARM:{self.code} ({describe_alarm(self.code)})"


@dataclass(frozen=True)
class Banner:
    version: str


@dataclass(frozen=True)
class Feedback:
    """A `[KIND:text]` message: MSG, GC, HLP, VER, OPT, echo, G54..., PRB ..."""

    kind: str
    text: str


@dataclass(frozen=True)
class Setting:
    number: int
    value: str


@dataclass(frozen=True)
class StartupLine:
    line: str
    result: str


@dataclass(frozen=True)
class Status:
    """A `<...>` real-time status report. Positions (3,) in the report's units (mm unless $13=1).

    state: Idle, Run, Hold, Jog, Alarm, Door, Check, Home, Sleep; substate e.g. 0/1 for Hold.
    Exactly one of mpos/wpos is given (per $10); wco appears intermittently.
    """

    state: str
    substate: int | None
    mpos: tuple[float, float, float] | None
    wpos: tuple[float, float, float] | None
    wco: tuple[float, float, float] | None = None
    feed: float | None = None
    spindle: float | None = None
    fields: dict = field(default_factory=dict, compare=False)

    @property
    def moving(self) -> bool:
        """Axes in motion: Run/Jog/Home, and Hold:1 (decelerating into a hold), Door:2/3."""
        if self.state in MOVING_STATES:
            return True
        if self.state == "Hold":
            return self.substate != 0
        if self.state == "Door":
            return self.substate in (2, 3)
        return False


Message = Ok | Error | Alarm | Banner | Feedback | Setting | StartupLine | Status

_STATES = frozenset({"Idle", "Run", "Hold", "Jog", "Alarm", "Door", "Check", "Home", "Sleep"})
_BANNER = re.compile(r"^Grbl (\S+) \['\$' for help\]$")
_FEEDBACK = re.compile(r"^\[([A-Za-z0-9]+):(.*)\]$")
_SETTING = re.compile(r"^\$(\d+)=(\S*)$")


def _floats(text: str, n: int | None, what: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise GrblParseError(f"{what}: {text!r} is not a list of numbers") from None
    if n is not None and len(vals) < n:
        raise GrblParseError(f"{what}: {text!r} has {len(vals)} values, expected {n}")
    return vals


def parse_status(line: str) -> Status:
    """Parse `<State[:sub]|MPos:x,y,z|FS:f,s|...>` (fields after the state in any order)."""
    if not (line.startswith("<") and line.endswith(">")):
        raise GrblParseError(f"status report {line!r} is not enclosed in <>")
    parts = line[1:-1].split("|")
    state, _, sub = parts[0].partition(":")
    if state not in _STATES:
        raise GrblParseError(f"status report {line!r}: unknown machine state {state!r}")
    substate = None
    if sub:
        if not sub.isdigit():
            raise GrblParseError(f"status report {line!r}: bad sub-state {sub!r}")
        substate = int(sub)
    fields: dict[str, str] = {}
    for p in parts[1:]:
        key, sep, val = p.partition(":")
        if not sep:
            raise GrblParseError(f"status report {line!r}: field {p!r} has no ':'")
        fields[key] = val
    mpos = wpos = wco = None
    if "MPos" in fields:
        mpos = _floats(fields["MPos"], 3, "MPos")[:3]
    if "WPos" in fields:
        wpos = _floats(fields["WPos"], 3, "WPos")[:3]
    if mpos is None and wpos is None:
        raise GrblParseError(f"status report {line!r} carries neither MPos nor WPos")
    if "WCO" in fields:
        wco = _floats(fields["WCO"], 3, "WCO")[:3]
    feed = spindle = None
    if "FS" in fields:
        fs = _floats(fields["FS"], 2, "FS")
        feed, spindle = fs[0], fs[1]
    elif "F" in fields:
        feed = _floats(fields["F"], 1, "F")[0]
    return Status(state, substate, mpos, wpos, wco, feed, spindle, fields)


def _code(text: str, line: str) -> int:
    if not text.isdigit():
        raise GrblParseError(f"{line!r}: code {text!r} is not a number")
    return int(text)


def parse_line(line: str) -> Message:
    """One line from GRBL (without its line ending) -> a message; GrblParseError otherwise."""
    if line == "ok":
        return Ok()
    if line.startswith("error:"):
        return Error(_code(line[6:], line))
    if line.startswith("ALARM:"):
        return Alarm(_code(line[6:], line))
    if line.startswith("<"):
        return parse_status(line)
    m = _BANNER.match(line)
    if m:
        return Banner(m.group(1))
    m = _FEEDBACK.match(line)
    if m:
        return Feedback(m.group(1), m.group(2))
    m = _SETTING.match(line)
    if m:
        return Setting(int(m.group(1)), m.group(2))
    if line.startswith(">"):
        if line.endswith(":ok"):
            return StartupLine(line[1:-3], "ok")
        i = line.rfind(":error:")
        if i > 0:
            return StartupLine(line[1:i], line[i + 1:])
    raise GrblParseError(f"unrecognised line from GRBL: {line!r}")


class LineSplitter:
    """Bytes from the port -> complete lines (`\\r\\n` or `\\n` ended, blank lines dropped).

    A line that is not ASCII comes out with replacement characters (the parser rejects it).
    """

    def __init__(self, max_line: int = 512) -> None:
        self._buf = bytearray()
        self.max_line = max_line
        self.overlong = 0  # lines dropped for exceeding max_line (noise without line ends)

    def feed(self, data: bytes) -> list[str]:
        self._buf += data
        out: list[str] = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                if len(self._buf) > self.max_line:
                    self._buf.clear()
                    self.overlong += 1
                return out
            raw = bytes(self._buf[:i]).strip(b"\r")
            del self._buf[: i + 1]
            if raw:
                out.append(raw.decode("ascii", errors="replace"))

    def clear(self) -> None:
        self._buf.clear()


# ---- what the host sends --------------------------------------------------------------------
def _num(v: float) -> str:
    return f"{v:.3f}"


def encode_move(target_mm, feed_mm_min: float) -> bytes:
    """`G21G90G1X..Y..Z..F..\\n`: a straight feed move to machine target (3,) mm at feed mm/min.

    The line restates G21 (mm) and G90 (absolute) so it means the same after a soft reset or a
    startup line changed the parser's modal state.
    """
    x, y, z = (float(v) for v in target_mm)
    line = f"G21G90G1X{_num(x)}Y{_num(y)}Z{_num(z)}F{feed_mm_min:.1f}\n"
    if len(line) >= LINE_BUFFER_SIZE:
        raise ValueError(f"move line {line!r} is longer than GRBL's {LINE_BUFFER_SIZE - 1}-character line buffer")
    return line.encode("ascii")


def encode_line(text: str) -> bytes:
    """A command line (`$X`, `G21G90`, ...) with its single `\\n`."""
    if "\n" in text or "\r" in text:
        raise ValueError(f"line {text!r} must not contain line endings")
    if any(c in text for c in "?!~\x18"):
        raise ValueError(f"line {text!r} contains a real-time command character")
    return (text + "\n").encode("ascii")


class CharCounter:
    """Host-side accounting of GRBL's receive buffer for character-counting streaming.

    sent(n) when a line of n bytes (newline included) goes out; acked() when its `ok`/`error`
    arrives (FIFO: responses come in line order); clear() after a soft reset (GRBL empties its
    buffer). fits(n): whether a further n-byte line can be sent without overflowing.
    """

    def __init__(self, capacity: int = RX_BUFFER_BYTES) -> None:
        if capacity < 2:
            raise ValueError(f"capacity={capacity}: must be >= 2 bytes")
        self.capacity = capacity
        self._lines: deque[int] = deque()
        self.outstanding = 0

    def fits(self, n: int) -> bool:
        return self.outstanding + n <= self.capacity

    def sent(self, n: int) -> None:
        if n > self.capacity:
            raise ValueError(f"a {n}-byte line can never fit GRBL's {self.capacity}-byte receive buffer")
        if not self.fits(n):
            raise ValueError(f"{n} bytes would overflow: {self.outstanding} of {self.capacity} in flight")
        self._lines.append(n)
        self.outstanding += n

    def acked(self) -> int:
        """Free the oldest line; returns its size. A response with nothing in flight -> ValueError."""
        if not self._lines:
            raise ValueError("response with no line in flight")
        n = self._lines.popleft()
        self.outstanding -= n
        return n

    @property
    def in_flight(self) -> int:
        return len(self._lines)

    def clear(self) -> None:
        self._lines.clear()
        self.outstanding = 0


# ---- what GRBL sends (the emulator's side) ---------------------------------------------------
def format_banner(version: str = GRBL_VERSION) -> bytes:
    return f"\r\nGrbl {version} ['$' for help]\r\n".encode("ascii")


def format_ok() -> bytes:
    return b"ok\r\n"


def format_error(code: int) -> bytes:
    return f"error:{code}\r\n".encode("ascii")


def format_alarm(code: int) -> bytes:
    return f"ALARM:{code}\r\n".encode("ascii")


def format_feedback(kind: str, text: str) -> bytes:
    return f"[{kind}:{text}]\r\n".encode("ascii")


def _fmt_rate(v: float) -> str:
    return f"{v:.0f}"  # GRBL prints mm/min rates with no decimals


def format_status(state: str, substate: int | None, mpos, feed_mm_min: float = 0.0, spindle: float = 0.0,
                  wco=None, overrides: tuple[int, int, int] | None = None, accessories: str = "") -> bytes:
    """`<Idle|MPos:0.000,0.000,0.000|FS:0,0[|WCO:...][|Ov:...[|A:...]]>\\r\\n` as GRBL 1.1 prints it.

    accessories: the `A:` letters (S spindle CW, C CCW, F flood coolant), printed with `Ov:` only."""
    head = state if substate is None else f"{state}:{substate}"
    parts = [head, "MPos:" + ",".join(_num(v) for v in mpos), f"FS:{_fmt_rate(feed_mm_min)},{spindle:.0f}"]
    if wco is not None:
        parts.append("WCO:" + ",".join(_num(v) for v in wco))
    if overrides is not None:
        parts.append("Ov:" + ",".join(str(int(v)) for v in overrides))
        if accessories:
            parts.append("A:" + accessories)
    return ("<" + "|".join(parts) + ">\r\n").encode("ascii")


# ---- G-code blocks (the emulator's parser) -----------------------------------------------------
class GcodeError(ValueError):
    """A block GRBL would reject; `code` is the error:N it answers."""

    def __init__(self, code: int, detail: str = "") -> None:
        super().__init__(f"error:{code} ({describe_error(code)}){': ' + detail if detail else ''}")
        self.code = code


def clean_line(raw: bytes) -> tuple[str, bool]:
    """GRBL's pre-parse of one received line: drop whitespace/control characters, `(...)` and `;`
    comments and `/`, upper-case letters. Returns (block, overflow) where overflow means the block
    reached GRBL's line buffer size (answered with error:11)."""
    out: list[str] = []
    paren = semi = False
    for c in raw.decode("latin-1"):
        if paren:
            if c == ")":
                paren = False
            continue
        if semi:
            continue
        if c <= " " or c == "/":
            continue
        if c == "(":
            paren = True
        elif c == ";":
            semi = True
        else:
            out.append(c.upper())
    block = "".join(out)
    return block, len(block) >= LINE_BUFFER_SIZE - 1


_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")


def parse_words(block: str) -> list[tuple[str, float]]:
    """`G1X1.5F600` -> [("G", 1.0), ("X", 1.5), ("F", 600.0)]; GcodeError(1|2) when malformed."""
    words: list[tuple[str, float]] = []
    i = 0
    while i < len(block):
        if not block[i].isalpha():
            raise GcodeError(1, f"{block[i:]!r}")
        m = _WORD.match(block, i)
        if not m:
            raise GcodeError(2, f"{block[i:]!r}")
        words.append((m.group(1), float(m.group(2))))
        i = m.end()
    return words
