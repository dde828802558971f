"""ATI Net F/T Raw Data Transfer (RDT) over UDP, and the box's calibration XML: pure code, no I/O.

Requests (host -> box, port 49152), 8 bytes big-endian `>HHI`: header 0x1234, command,
sample count (0 = stream until told to stop). Commands: 0x0000 stop streaming, 0x0002 start
high-speed real-time streaming (one record per datagram), 0x0003 start buffered streaming
(several records per datagram), 0x0041 reset the threshold latch, 0x0042 set software bias.

Records (box -> host), 36 bytes big-endian `>III6i`: rdt_sequence (position of the record in
the current stream, from 1, wrapping at 2**32), ft_sequence (the box's internal sample
counter, wrapping at 2**32), status (0 = healthy; bit meanings in STATUS_BITS), then Fx, Fy,
Fz, Tx, Ty, Tz in counts. Force = counts / counts_per_force, in the box's configured force
unit; torque likewise. A buffered datagram is several records back to back.

Calibration: http://<box>/netftapi2.xml carries cfgcpf / cfgcpt (counts per force / torque
unit, whole numbers) and scfgfu / scfgtu (the unit names); the rest of the box's web server is in
`web.py`.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

import numpy as np

RDT_PORT = 49152
HEADER = 0x1234
CMD_STOP = 0x0000
CMD_START_REALTIME = 0x0002
CMD_START_BUFFERED = 0x0003
CMD_RESET_LATCH = 0x0041
CMD_BIAS = 0x0042
COMMANDS = {CMD_STOP: "stop", CMD_START_REALTIME: "start real-time", CMD_START_BUFFERED: "start buffered",
            CMD_RESET_LATCH: "reset latch", CMD_BIAS: "set software bias"}

REQUEST = struct.Struct(">HHI")
RECORD = struct.Struct(">III6i")
U32 = 1 << 32

# Status word bits (ATI Net F/T manual); the top bit summarises any error.
STATUS_BITS = {
    0x80000000: "error summary",
    0x40000000: "CPU or RAM error",
    0x20000000: "digital board error",
    0x10000000: "analog board error",
    0x08000000: "serial link communication error",
    0x02000000: "halted due to configuration errors",
    0x00800000: "configuration incompatible with calibration",
    0x00100000: "RDT communication error",
    0x00020000: "transducer saturation or A/D error",
    0x00010000: "monitor condition latched",
    0x00004000: "watchdog timeout error",
    0x00000200: "excessive strain gage excitation current",
    0x00000100: "insufficient strain gage excitation current",
    0x00000004: "internal temperature error",
}

# Unit names as the box spells them (scfgfu / scfgtu), and what one unit is in N or N·m.
FORCE_UNITS_N = {"N": 1.0, "kN": 1e3, "lbf": 4.4482216152605, "klbf": 4448.2216152605, "kgf": 9.80665}
TORQUE_UNITS_NM = {"N-m": 1.0, "Nm": 1.0, "N-mm": 1e-3, "Nmm": 1e-3, "kN-m": 1e3, "lbf-in": 0.1129848290276167,
                   "lbf-ft": 1.3558179483314004, "kgf-cm": 0.0980665, "kg-cm": 0.0980665}


class RDTError(ValueError):
    """Bytes that are not a valid RDT request, record or calibration document."""


@dataclass(frozen=True, slots=True)
class RDTRecord:
    """One decoded record: counts (6,) int64 are Fx, Fy, Fz, Tx, Ty, Tz."""

    rdt_sequence: int
    ft_sequence: int
    status: int
    counts: tuple[int, int, int, int, int, int]


@dataclass(frozen=True, slots=True)
class Calibration:
    """Counts per force / torque unit and the units: what turns record counts into N and N·m."""

    counts_per_force: float
    counts_per_torque: float
    force_unit: str = "N"
    torque_unit: str = "N-m"

    def __post_init__(self) -> None:
        if not (self.counts_per_force > 0 and self.counts_per_torque > 0):
            raise RDTError(f"counts per unit must be > 0, got cfgcpf={self.counts_per_force!r}, "
                           f"cfgcpt={self.counts_per_torque!r}")
        if self.force_unit not in FORCE_UNITS_N:
            raise RDTError(f"unknown force unit {self.force_unit!r}; known: {sorted(FORCE_UNITS_N)}")
        if self.torque_unit not in TORQUE_UNITS_NM:
            raise RDTError(f"unknown torque unit {self.torque_unit!r}; known: {sorted(TORQUE_UNITS_NM)}")

    @property
    def n_per_count(self) -> float:
        return FORCE_UNITS_N[self.force_unit] / self.counts_per_force

    @property
    def nm_per_count(self) -> float:
        return TORQUE_UNITS_NM[self.torque_unit] / self.counts_per_torque

    def to_si(self, counts) -> tuple[np.ndarray, np.ndarray]:
        """(6,) counts -> force (3,) N, torque (3,) N·m."""
        c = np.asarray(counts, np.float64)
        return c[:3] * self.n_per_count, c[3:] * self.nm_per_count

    def to_counts(self, force_n, torque_nm) -> tuple[int, ...]:
        """Force (3,) N and torque (3,) N·m -> (6,) counts, rounded and held to the int32 range."""
        c = np.concatenate([np.asarray(force_n, np.float64) / self.n_per_count,
                            np.asarray(torque_nm, np.float64) / self.nm_per_count])
        return tuple(int(v) for v in np.clip(np.rint(c), -(1 << 31), (1 << 31) - 1))


def encode_request(command: int, count: int = 0) -> bytes:
    """An 8-byte RDT request; count 0 = stream until stopped."""
    return REQUEST.pack(HEADER, command, count)


def decode_request(data: bytes) -> tuple[int, int]:
    """(command, sample count) of one request datagram."""
    if len(data) != REQUEST.size:
        raise RDTError(f"RDT request must be {REQUEST.size} bytes, got {len(data)}: {data[:16].hex()}")
    header, command, count = REQUEST.unpack(data)
    if header != HEADER:
        raise RDTError(f"RDT request header 0x{header:04x}, expected 0x{HEADER:04x}")
    return command, count


def encode_record(rdt_sequence: int, ft_sequence: int, status: int, counts) -> bytes:
    """One 36-byte record; sequence numbers are taken modulo 2**32."""
    return RECORD.pack(rdt_sequence % U32, ft_sequence % U32, status % U32, *counts)


def decode_records(data: bytes) -> list[RDTRecord]:
    """The records of one datagram (one in real-time mode, several when buffered)."""
    if not data or len(data) % RECORD.size:
        raise RDTError(f"RDT datagram of {len(data)} bytes is not a whole number of {RECORD.size}-byte records")
    out = []
    for off in range(0, len(data), RECORD.size):
        rdt, ft, status, *counts = RECORD.unpack_from(data, off)
        out.append(RDTRecord(rdt, ft, status, tuple(counts)))
    return out


def decode_status(status: int) -> str:
    """The status word's set bits, named ("healthy" for 0)."""
    if status == 0:
        return "healthy"
    names = [name for bit, name in STATUS_BITS.items() if status & bit]
    return ", ".join(names) if names else f"status 0x{status:08x}"


def seq_delta(new: int, old: int) -> int:
    """new - old for 32-bit wrapping counters, in [-2**31, 2**31)."""
    return (new - old + (1 << 31)) % U32 - (1 << 31)


def calibration_xml(cal: Calibration, product: str = "Net F/T") -> str:
    """A netftapi2.xml excerpt with the calibration fields (the emulator serves the full page,
    `web.py`). Counts per unit are written as the box writes them: whole numbers."""
    return ("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<netft>\n"
            f"<prodname>{product}</prodname>\n<cfgcpf>{cal.counts_per_force:.0f}</cfgcpf>\n"
            f"<cfgcpt>{cal.counts_per_torque:.0f}</cfgcpt>\n<scfgfu>{cal.force_unit}</scfgfu>\n"
            f"<scfgtu>{cal.torque_unit}</scfgtu>\n</netft>\n")


def parse_calibration_xml(text: str) -> Calibration:
    """Calibration from the box's netftapi2.xml (cfgcpf, cfgcpt, scfgfu, scfgtu; units default to N, N-m)."""
    def field(tag: str) -> str | None:
        found = re.findall(rf"<{tag}>\s*([^<]*?)\s*</{tag}>", text)
        if len(found) > 1:
            raise RDTError(f"netftapi2.xml: <{tag}> appears {len(found)} times")
        return found[0] if found else None

    values = {}
    for tag in ("cfgcpf", "cfgcpt"):
        raw = field(tag)
        if raw is None:
            raise RDTError(f"netftapi2.xml has no <{tag}> (counts per unit); is this a Net F/T calibration page?")
        try:
            values[tag] = float(raw)
        except ValueError:
            raise RDTError(f"netftapi2.xml: <{tag}>{raw}</{tag}> is not a number") from None
    return Calibration(values["cfgcpf"], values["cfgcpt"], field("scfgfu") or "N", field("scfgtu") or "N-m")
