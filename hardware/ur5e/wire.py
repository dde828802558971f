"""UR controller wire protocols: RTDE (port 30004) packets and the dashboard (29999) lines.

Pure encode/decode, no I/O; the emulator uses all of it, the tests check it on bytes captured
from the `ur_rtde` client. The driver itself talks through `ur_rtde`, which carries its own
implementation of the same protocol; this module is the reference the emulator answers with.

RTDE (UR "Real-Time Data Exchange" guide, protocol version 2): every package is
`>HB` (size including the 3-byte header, type) followed by a payload, big-endian throughout.

    type  client -> controller                       controller -> client
    'V'   uint16 protocol version                    uint8 accepted
    'v'   (empty)                                    uint32 major, minor, bugfix, build
    'O'   double frequency + names "a,b,c"           uint8 recipe id + types "DOUBLE,INT32,..."
    'I'   names "a,b,c"                              uint8 recipe id + types
    'S'   (empty)                                    uint8 accepted
    'P'   (empty)                                    uint8 accepted
    'U'   uint8 recipe id + values (input recipe)    uint8 recipe id + values (output recipe)
    'M'   -                                          uint8 len, text, uint8 len, source, uint8 level

A name the controller does not know gets type "NOT_FOUND"; an input already taken by another
client "IN_USE".
"""

from __future__ import annotations

import re
import struct
import time
from dataclasses import dataclass

HEADER = struct.Struct(">HB")
HEADER_SIZE = HEADER.size

RTDE_REQUEST_PROTOCOL_VERSION = ord("V")
RTDE_GET_URCONTROL_VERSION = ord("v")
RTDE_TEXT_MESSAGE = ord("M")
RTDE_DATA_PACKAGE = ord("U")
RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS = ord("O")
RTDE_CONTROL_PACKAGE_SETUP_INPUTS = ord("I")
RTDE_CONTROL_PACKAGE_START = ord("S")
RTDE_CONTROL_PACKAGE_PAUSE = ord("P")

PORT_DASHBOARD = 29999
PORT_RTDE = 30004
PORT_SECONDARY = 30002  # script upload, as the ur_rtde client uses it (see README)
PORT_REALTIME = 30003

# ---- controller state words (RTDE guide, "robot_mode", "safety_mode", "runtime_state",
# "robot_status_bits", "safety_status_bits"); the driver reads them, the emulator writes them ----
ROBOT_MODE_NAMES = {-1: "NO_CONTROLLER", 0: "DISCONNECTED", 1: "CONFIRM_SAFETY", 2: "BOOTING", 3: "POWER_OFF",
                    4: "POWER_ON", 5: "IDLE", 6: "BACKDRIVE", 7: "RUNNING", 8: "UPDATING_FIRMWARE"}
ROBOT_MODE_POWER_OFF = 3
ROBOT_MODE_IDLE = 5
ROBOT_MODE_RUNNING = 7

SAFETY_MODE_NAMES = {1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
                     6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT"}
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3
SAFETY_MODE_SYSTEM_EMERGENCY_STOP = 6
SAFETY_MODE_ROBOT_EMERGENCY_STOP = 7

RUNTIME_NAMES = {0: "STOPPING", 1: "STOPPED", 2: "PLAYING", 3: "PAUSING", 4: "PAUSED", 5: "RESUMING"}
RUNTIME_STOPPED = 1
RUNTIME_PLAYING = 2
RUNTIME_PAUSED = 4

ROBOT_STATUS_POWER_ON = 1 << 0
ROBOT_STATUS_PROGRAM_RUNNING = 1 << 1

SAFETY_BIT_NORMAL = 1 << 0
SAFETY_BIT_PROTECTIVE_STOPPED = 1 << 2
SAFETY_BIT_SYSTEM_EMERGENCY_STOPPED = 1 << 5
SAFETY_BIT_ROBOT_EMERGENCY_STOPPED = 1 << 6
SAFETY_BIT_EMERGENCY_STOPPED = 1 << 7  # set with either of the two above
SAFETY_BIT_STOPPED_DUE_TO_SAFETY = 1 << 10
SAFETY_EMERGENCY_STOPPED = SAFETY_BIT_SYSTEM_EMERGENCY_STOPPED | SAFETY_BIT_ROBOT_EMERGENCY_STOPPED \
    | SAFETY_BIT_EMERGENCY_STOPPED


def safety_status_bits(safety_mode: int) -> int:
    """safety_status_bits as the controller reports them in safety_mode."""
    if safety_mode == SAFETY_MODE_PROTECTIVE_STOP:
        return SAFETY_BIT_PROTECTIVE_STOPPED | SAFETY_BIT_STOPPED_DUE_TO_SAFETY
    if safety_mode == SAFETY_MODE_ROBOT_EMERGENCY_STOP:
        return SAFETY_BIT_ROBOT_EMERGENCY_STOPPED | SAFETY_BIT_EMERGENCY_STOPPED | SAFETY_BIT_STOPPED_DUE_TO_SAFETY
    if safety_mode == SAFETY_MODE_SYSTEM_EMERGENCY_STOP:
        return SAFETY_BIT_SYSTEM_EMERGENCY_STOPPED | SAFETY_BIT_EMERGENCY_STOPPED | SAFETY_BIT_STOPPED_DUE_TO_SAFETY
    return SAFETY_BIT_NORMAL

# RTDE type name -> struct format of one value.
TYPE_FORMATS = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}

ZERO = {"BOOL": False, "UINT8": 0, "UINT32": 0, "UINT64": 0, "INT32": 0, "DOUBLE": 0.0,
        "VECTOR3D": (0.0,) * 3, "VECTOR6D": (0.0,) * 6, "VECTOR6INT32": (0,) * 6, "VECTOR6UINT32": (0,) * 6}

# Controller outputs (RTDE guide, PolyScope 5.x) by name -> type.
_OUTPUTS = {
    "timestamp": "DOUBLE",
    "target_q": "VECTOR6D", "target_qd": "VECTOR6D", "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D", "target_moment": "VECTOR6D",
    "actual_q": "VECTOR6D", "actual_qd": "VECTOR6D", "actual_current": "VECTOR6D",
    "actual_current_window": "VECTOR6D", "actual_current_as_torque": "VECTOR6D",
    "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D", "actual_TCP_speed": "VECTOR6D", "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D", "target_TCP_speed": "VECTOR6D",
    "actual_digital_input_bits": "UINT64", "joint_temperatures": "VECTOR6D",
    "actual_execution_time": "DOUBLE", "robot_mode": "INT32", "joint_mode": "VECTOR6INT32",
    "safety_mode": "INT32", "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D", "speed_scaling": "DOUBLE",
    "target_speed_fraction": "DOUBLE", "actual_momentum": "DOUBLE",
    "actual_main_voltage": "DOUBLE", "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE", "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64", "runtime_state": "UINT32",
    "elbow_position": "VECTOR3D", "elbow_velocity": "VECTOR3D",
    "robot_status_bits": "UINT32", "safety_status_bits": "UINT32",
    "analog_io_types": "UINT32",
    "standard_analog_input0": "DOUBLE", "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE", "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE",
    "euromap67_input_bits": "UINT32", "euromap67_output_bits": "UINT32",
    "euromap67_24V_voltage": "DOUBLE", "euromap67_24V_current": "DOUBLE",
    "tool_mode": "UINT32", "tool_analog_input_types": "UINT32",
    "tool_analog_input0": "DOUBLE", "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32", "tool_output_current": "DOUBLE", "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE",
    "output_bit_registers0_to_31": "UINT32", "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "ft_raw_wrench": "VECTOR6D", "payload": "DOUBLE", "payload_cog": "VECTOR3D",
    "payload_inertia": "VECTOR6D", "script_control_line": "UINT32",
    "joint_position_deviation_ratio": "DOUBLE", "collision_detection_ratio": "DOUBLE",
    "time_scale_source": "UINT32",
}

# Controller inputs by name -> type.
_INPUTS = {
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8", "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8", "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": "VECTOR6D",
}

_REGISTER = re.compile(r"^(input|output)_(bit|int|double)_register_(\d+)$")


def variable_type(name: str, direction: str) -> str:
    """RTDE type of variable `name` for direction "output" (controller -> client) or "input",
    "NOT_FOUND" when the controller has no such variable."""
    m = _REGISTER.match(name)
    if m:
        kind, index = m.group(2), int(m.group(3))
        if kind == "bit":
            return "BOOL" if 64 <= index <= 127 else "NOT_FOUND"
        if index > 47:
            return "NOT_FOUND"
        return "INT32" if kind == "int" else "DOUBLE"
    table = _OUTPUTS if direction == "output" else _INPUTS
    return table.get(name, "NOT_FOUND")


@dataclass(frozen=True)
class Recipe:
    """A set-up recipe: its id, variable names and their types, and the struct packing them."""

    recipe_id: int
    names: tuple[str, ...]
    types: tuple[str, ...]

    @property
    def fmt(self) -> struct.Struct:
        return struct.Struct(">B" + "".join(TYPE_FORMATS[t] for t in self.types))

    def encode(self, values: dict) -> bytes:
        """Payload of a 'U' package: recipe id, then each variable's value in recipe order
        (zero for a variable missing from values)."""
        flat: list = []
        for name, kind in zip(self.names, self.types, strict=True):
            v = values.get(name)
            if v is None:
                v = ZERO[kind]
            if TYPE_FORMATS[kind][0].isdigit():
                flat.extend(v)
            else:
                flat.append(v)
        return self.fmt.pack(self.recipe_id, *flat)

    def decode(self, payload: bytes) -> dict:
        """Values of a 'U' payload by name (vectors as tuples)."""
        flat = self.fmt.unpack(payload)
        if flat[0] != self.recipe_id:
            raise ValueError(f"RTDE data package for recipe {flat[0]}, expected {self.recipe_id}")
        out, i = {}, 1
        for name, kind in zip(self.names, self.types, strict=True):
            f = TYPE_FORMATS[kind]
            n = int(f[:-1]) if f[0].isdigit() else 1
            out[name] = tuple(flat[i:i + n]) if n > 1 else flat[i]
            i += n
        return out


# ---- framing ---------------------------------------------------------------------------------
def pack(kind: int, payload: bytes = b"") -> bytes:
    """One RTDE package of type `kind` (an ord('X') value)."""
    return HEADER.pack(HEADER_SIZE + len(payload), kind) + payload


class PacketReader:
    """Splits a byte stream into (type, payload) packages; feed() what arrives, in any chunks."""

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        self._buf += data
        out = []
        while len(self._buf) >= HEADER_SIZE:
            size, kind = HEADER.unpack_from(self._buf)
            if size < HEADER_SIZE:
                raise ValueError(f"RTDE package size {size} < header size {HEADER_SIZE}")
            if len(self._buf) < size:
                break
            out.append((kind, bytes(self._buf[HEADER_SIZE:size])))
            del self._buf[:size]
        return out


# ---- requests (client -> controller) and replies ---------------------------------------------
def encode_protocol_version_request(version: int = 2) -> bytes:
    return pack(RTDE_REQUEST_PROTOCOL_VERSION, struct.pack(">H", version))


def decode_protocol_version_request(payload: bytes) -> int:
    return struct.unpack(">H", payload)[0]


def encode_accepted(kind: int, accepted: bool) -> bytes:
    """Reply to 'V', 'S' or 'P'."""
    return pack(kind, struct.pack(">B", 1 if accepted else 0))


def encode_controller_version(major: int, minor: int, bugfix: int, build: int) -> bytes:
    return pack(RTDE_GET_URCONTROL_VERSION, struct.pack(">IIII", major, minor, bugfix, build))


def decode_controller_version(payload: bytes) -> tuple[int, int, int, int]:
    return struct.unpack(">IIII", payload)


def encode_setup_outputs_request(frequency_hz: float, names: list[str]) -> bytes:
    """An 'O' request (protocol version 2): output frequency and the variables wanted."""
    return pack(RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS, struct.pack(">d", frequency_hz) + ",".join(names).encode())


def decode_setup_outputs_request(payload: bytes) -> tuple[float, list[str]]:
    """(frequency in Hz, variable names) of an 'O' request (protocol version 2)."""
    (freq,) = struct.unpack_from(">d", payload)
    return freq, _names(payload[8:])


def decode_setup_inputs_request(payload: bytes) -> list[str]:
    return _names(payload)


def encode_setup_reply(kind: int, recipe_id: int, types: list[str]) -> bytes:
    """Reply to 'O' or 'I': recipe id (0 when refused) and each variable's type."""
    return pack(kind, struct.pack(">B", recipe_id) + ",".join(types).encode())


def decode_setup_reply(payload: bytes) -> tuple[int, list[str]]:
    return payload[0], _names(payload[1:])


def encode_data(recipe: Recipe, values: dict) -> bytes:
    return pack(RTDE_DATA_PACKAGE, recipe.encode(values))


def encode_text_message(text: str, source: str = "emulator", level: int = 1) -> bytes:
    """'M' package (version 2): message, source, warning level (0 exception .. 3 info)."""
    t, s = text.encode()[:255], source.encode()[:255]
    return pack(RTDE_TEXT_MESSAGE, bytes([len(t)]) + t + bytes([len(s)]) + s + bytes([level]))


def _names(raw: bytes) -> list[str]:
    text = raw.decode("ascii", errors="replace").strip("\x00")
    return [n for n in text.split(",") if n]


def probe_stream(host: str, timeout_s: float, frequency_hz: float = 125.0) -> str | None:
    """Ask the controller at host for one RTDE data package, as a client does (protocol version 2,
    an output recipe of `timestamp`, start) on plain sockets, so a signal can end the wait.
    Returns None when a data package arrived within timeout_s, else what was missing."""
    import socket

    deadline = time.monotonic() + timeout_s
    reader = PacketReader()
    with socket.create_connection((host, PORT_RTDE), timeout=timeout_s) as sock:

        def reply(kind: int) -> bytes | None:
            while (left := deadline - time.monotonic()) > 0:
                sock.settimeout(left)
                try:
                    data = sock.recv(4096)
                except TimeoutError:
                    return None
                if not data:
                    return None
                for k, payload in reader.feed(data):
                    if k == kind:
                        return payload
            return None

        steps = ((encode_protocol_version_request(2), RTDE_REQUEST_PROTOCOL_VERSION, "protocol version"),
                 (encode_setup_outputs_request(frequency_hz, ["timestamp"]), RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS,
                  "output set-up"),
                 (pack(RTDE_CONTROL_PACKAGE_START), RTDE_CONTROL_PACKAGE_START, "start"),
                 (b"", RTDE_DATA_PACKAGE, "data"))
        for request, kind, what in steps:
            if request:
                sock.sendall(request)
            if reply(kind) is None:
                return f"no {what} reply within {timeout_s:g} s"
        try:
            sock.sendall(pack(RTDE_CONTROL_PACKAGE_PAUSE))
        except OSError:
            pass
    return None


# ---- dashboard server (29999): one text line per request and per answer --------------------
DASHBOARD_WELCOME = "Connected: Universal Robots Dashboard Server"
DASHBOARD_MAX_LINE_BYTES = 65536  # a longer "line" is dropped unanswered (no command is that long)


def dashboard_lines(buf: bytearray) -> list[str]:
    """Complete request lines taken off the front of buf (newline-terminated, stripped)."""
    out = []
    while True:
        i = buf.find(b"\n")
        if i < 0:
            return out
        out.append(bytes(buf[:i]).decode("utf-8", errors="replace").strip())
        del buf[:i + 1]


def encode_dashboard_line(text: str) -> bytes:
    return (text + "\n").encode()
