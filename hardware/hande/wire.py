"""Robotiq URCap gripper socket (TCP 63352 on the UR controller): ASCII requests and replies; no I/O.

Shared by the driver and the emulator. The dialect, as public clients use it (e.g. the
`robotiq_gripper.py` example shipped with ur_rtde and its many forks):

- `SET VAR val [VAR val ...]\\n` sets one or more registers and is answered `ack` (three bytes; the
  URCap sends no line end after it, clients compare the reply with b"ack").
- `GET VAR\\n` is answered `VAR value\\n` (the variable name echoed, a decimal value).
- Registers: ACT activate (1; 0 resets and clears faults), GTO go-to (1 moves to POS; 0 stops),
  ATR auto-release, ADR auto-release direction, POS requested position 0..255 (0 open,
  255 closed), SPE speed 0..255, FOR force 0..255; read-only STA activation status (0 reset,
  1 activating, 3 active), PRE echo of the requested position, OBJ object detection
  (0 moving, 1 stopped on an object while opening, 2 stopped on an object while closing,
  3 at the requested position), FLT fault code (0 none; see FAULT_CODES), COU motor current.
- Requests and replies strictly alternate on one connection; a client must not pipeline.

What the URCap answers to an unknown variable is not documented publicly; the emulator answers
`?` and the driver treats any reply that is not the expected one as a protocol error.
"""

from __future__ import annotations

from dataclasses import dataclass

PORT = 63352
ACK = b"ack"
WRITABLE = ("ACT", "GTO", "ATR", "ADR", "POS", "SPE", "FOR")
READABLE = WRITABLE + ("STA", "PRE", "OBJ", "FLT", "COU")

STA_RESET, STA_ACTIVATING, STA_ACTIVE = 0, 1, 3
OBJ_MOVING, OBJ_OPENING_CONTACT, OBJ_CLOSING_CONTACT, OBJ_AT_POSITION = 0, 1, 2, 3

# gFLT codes (Hand-E instruction manual, gripper status register); 0x05-0x07 are minor faults
# cleared by the next valid command or activation, 0x08 and above need a reset (ACT 0 -> 1).
FAULT_CODES: dict[int, str] = {
    0x00: "no fault",
    0x05: "action delayed: activation (re-activation) must complete first",
    0x07: "the activation bit must be set before the action",
    0x08: "maximum operating temperature exceeded",
    0x09: "no communication for at least 1 second",
    0x0A: "under minimum operating voltage",
    0x0B: "automatic release in progress",
    0x0C: "internal fault",
    0x0D: "activation fault: check that nothing obstructs the fingers",
    0x0E: "overcurrent triggered",
    0x0F: "automatic release completed",
}


class HandEProtocolError(ValueError):
    """A reply that does not answer the request (wrong variable, not a number, not `ack`)."""


def describe_fault(code: int) -> str:
    return FAULT_CODES.get(code, "unknown fault code")


# ---- requests (driver side) -------------------------------------------------------------------
def encode_set(pairs) -> bytes:
    """[("POS", 128), ("GTO", 1)] -> b"SET POS 128 GTO 1\\n"."""
    pairs = list(pairs)
    if not pairs:
        raise ValueError("SET needs at least one variable")
    parts = ["SET"]
    for var, val in pairs:
        if var not in WRITABLE:
            raise ValueError(f"{var!r} is not a writable gripper register ({', '.join(WRITABLE)})")
        v = int(val)
        if not 0 <= v <= 255:
            raise ValueError(f"{var}={v}: registers hold 0..255")
        parts += [var, str(v)]
    return (" ".join(parts) + "\n").encode("ascii")


def encode_get(var: str) -> bytes:
    if var not in READABLE:
        raise ValueError(f"{var!r} is not a readable gripper register ({', '.join(READABLE)})")
    return f"GET {var}\n".encode("ascii")


def take_ack(buf: bytes) -> tuple[bool, bytes] | None:
    """Split the reply to a SET off buf: (True, rest) for `ack`, None when more bytes are needed.

    Leading line ends (left by a reply that ended in one) are skipped; anything else raises.
    """
    data = buf.lstrip(b"\r\n")
    if len(data) < len(ACK):
        if ACK.startswith(data):
            return None
        raise HandEProtocolError(f"expected 'ack' to a SET, got {bytes(data)!r}")
    if data[:3] != ACK:
        end = data.find(b"\n")
        raise HandEProtocolError(f"expected 'ack' to a SET, got {bytes(data[: end if end >= 0 else 40])!r}")
    return True, bytes(data[3:])


def take_value(buf: bytes, var: str) -> tuple[int, bytes] | None:
    """Split the reply to `GET var` off buf: (value, rest), None when the line is not complete."""
    data = buf.lstrip(b"\r\n")
    end = data.find(b"\n")
    if end < 0:
        if len(data) > 64:
            raise HandEProtocolError(f"no line end in the reply to GET {var}: {bytes(data[:64])!r}")
        return None
    line, rest = bytes(data[:end]).strip(), bytes(data[end + 1:])
    parts = line.split()
    if len(parts) != 2 or parts[0].decode("ascii", "replace") != var:
        raise HandEProtocolError(f"reply {line!r} does not answer GET {var}")
    try:
        return int(parts[1]), rest
    except ValueError:
        raise HandEProtocolError(f"reply {line!r} to GET {var} is not an integer") from None


# ---- requests (emulator side) -----------------------------------------------------------------
@dataclass(frozen=True)
class SetRequest:
    pairs: tuple[tuple[str, int], ...]


@dataclass(frozen=True)
class GetRequest:
    var: str


def parse_request(line: bytes) -> SetRequest | GetRequest:
    """One request line (without its `\\n`); HandEProtocolError for anything else."""
    parts = line.decode("ascii", "replace").split()
    if len(parts) == 2 and parts[0] == "GET":
        return GetRequest(parts[1])
    if len(parts) >= 3 and len(parts) % 2 == 1 and parts[0] == "SET":
        pairs = []
        for var, val in zip(parts[1::2], parts[2::2], strict=True):
            try:
                pairs.append((var, int(float(val))))
            except ValueError:
                raise HandEProtocolError(f"SET {var} {val!r}: not a number") from None
        return SetRequest(tuple(pairs))
    raise HandEProtocolError(f"not a SET or GET request: {line!r}")


def encode_value(var: str, value: int) -> bytes:
    return f"{var} {int(value)}\n".encode("ascii")


# ---- units -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Calibration:
    """Jaw opening <-> POS counts, speed mm/s <-> SPE, force % <-> FOR.

    open_count/closed_count: the POS values at full opening (stroke_mm) and fully closed (0 mm),
    found by the gripper's auto-calibration (nominally 0 and 255). Speed 0..255 spans the Hand-E's
    min..max jaw speed linearly; force 0..255 spans 0..100 %.
    """

    stroke_mm: float = 50.0
    open_count: int = 0
    closed_count: int = 255
    min_speed_mm_s: float = 20.0
    max_speed_mm_s: float = 150.0

    def mm_to_count(self, opening_mm: float) -> int:
        frac = min(max(opening_mm / self.stroke_mm, 0.0), 1.0)
        return int(round(self.closed_count + frac * (self.open_count - self.closed_count)))

    def count_to_mm(self, count: int) -> float:
        frac = (count - self.closed_count) / (self.open_count - self.closed_count)
        return min(max(frac, 0.0), 1.0) * self.stroke_mm + 0.0  # no -0.0

    def speed_to_count(self, speed_mm_s: float) -> int:
        frac = (speed_mm_s - self.min_speed_mm_s) / (self.max_speed_mm_s - self.min_speed_mm_s)
        return int(round(min(max(frac, 0.0), 1.0) * 255))

    def count_to_speed(self, count: int) -> float:
        return self.min_speed_mm_s + count / 255.0 * (self.max_speed_mm_s - self.min_speed_mm_s)

    @staticmethod
    def force_to_count(force_pct: float) -> int:
        return int(round(min(max(force_pct / 100.0, 0.0), 1.0) * 255))

    @staticmethod
    def count_to_force(count: int) -> float:
        return count / 255.0 * 100.0
