"""The emulated UR controller process: dashboard, RTDE and script ports, the control script.

Runs in its own process (`python -m hardware.ur5e.controller FD HOST T0`), started by
`UR5eEmulator`, for the reason a real controller is another machine: the ur_rtde client's Python
constructors hold the GIL while they wait for the controller's answers, so a controller served
by threads of the client's own process could never answer them. The simulated arm stays in the
parent (with the world); this process sees it as a `BridgedArm`: the parent pushes the TCP pose
every 2 ms cycle over a pipe (FD, a multiprocessing Connection) and applies the moves and stops
this process sends back. Fault injection and test read-outs go over the same pipe.

One controller thread runs the 500 Hz cycle: it advances the control script (the register
protocol of the uploaded `rtde_control` script) and sends every started RTDE connection its
output recipe at the frequency it asked for. Cycle k is stamped T0 + k * 2 ms (controller time:
the world's time when the emulator started). Socket readers run one thread per connection.
"""

from __future__ import annotations

import logging
import socket
import threading
import time

import numpy as np

from hardware.ur5e import wire
from hardware.ur5e.control_script import ControlScript, Registers

log = logging.getLogger(__name__)

EMULATOR_SETUP = "gripper"

PERIOD_S = 0.002  # the controller cycle (500 Hz)

# Robot / safety / runtime constants (RTDE guide, ur_rtde's enums).
ROBOT_MODE_RUNNING = 7
SAFETY_MODE_NORMAL = 1
SAFETY_MODE_PROTECTIVE_STOP = 3
SAFETY_MODE_ROBOT_EMERGENCY_STOP = 7
SAFETY_BIT_NORMAL = 1 << 0
SAFETY_BIT_PROTECTIVE_STOPPED = 1 << 2
SAFETY_BIT_ROBOT_EMERGENCY_STOPPED = 1 << 6
SAFETY_BIT_EMERGENCY_STOPPED = 1 << 7
SAFETY_BIT_STOPPED_DUE_TO_SAFETY = 1 << 10
ROBOT_STATUS_POWER_ON = 1 << 0
ROBOT_STATUS_PROGRAM_RUNNING = 1 << 1
RUNTIME_STOPPED = 1
RUNTIME_PLAYING = 2
RUNTIME_PAUSED = 4

SAFETY_MODE_NAMES = {1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
                     6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT"}
RUNTIME_NAMES = {0: "STOPPING", 1: "STOPPED", 2: "PLAYING", 3: "PAUSING", 4: "PAUSED", 5: "RESUMING"}


class BridgedArm:
    """The simulated arm as this process sees it: state pushed by the parent's bridge every
    cycle, commands sent back to it. A command counts as moving until the parent reports it
    applied (the state it pushed before may predate the command)."""

    def __init__(self, conn) -> None:
        self.conn = conn
        self._send_lock = threading.Lock()
        self.pose = np.zeros(6)
        self.t_s = 0.0
        self.moving = False
        self.sent_id = 0
        self.applied_id = 0
        self.error: str | None = None

    def _send(self, msg: tuple) -> None:
        with self._send_lock:
            self.sent_id += 1
            self.conn.send((msg[0], self.sent_id, *msg[1:]))

    def move_linear(self, pose6, speed_m_s, accel_m_s2, angular_speed_rad_s):
        self._send(("move", np.asarray(pose6, float).tolist(), float(speed_m_s), float(accel_m_s2),
                    None if angular_speed_rad_s is None else float(angular_speed_rad_s)))

    def stop(self):
        self._send(("stop",))

    def is_moving(self):
        return self.moving or self.applied_id < self.sent_id

    def tcp_pose6(self):
        return self.pose.copy()

    def on_state(self, t_s: float, pose6, moving: bool, applied_id: int, error: str | None) -> None:
        self.t_s, self.pose, self.moving, self.applied_id = t_s, np.asarray(pose6, float), moving, applied_id
        if error is not None:
            self.error = error


class _RtdeSession:
    """One RTDE client connection: its recipes and whether it has started."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.outputs: list[tuple[wire.Recipe, int]] = []  # (recipe, send every n cycles)
        self.inputs: dict[int, wire.Recipe] = {}
        self.started = False
        self.send_lock = threading.Lock()

    def send(self, data: bytes) -> None:
        with self.send_lock:
            self.sock.sendall(data)


class URController:
    """A UR5e controller on `host` (ports fixed as on the real robot), moving `arm`.

    arm: a BridgedArm (state and commands of the simulated arm). t0_s: controller time at start.
    controller_version: what RTDE 'v' reports (major > 3: e-Series, 500 Hz).
    polyscope_version, serial_number, remote_control: dashboard answers.
    """

    def __init__(self, arm: BridgedArm, host: str = "127.0.0.2", t0_s: float = 0.0, *,
                 controller_version: tuple[int, int, int, int] = (5, 14, 0, 1123),
                 polyscope_version: str = "URSoftware 5.14.0.1123 (Jan 09 2023)",
                 serial_number: str = "20235500001", remote_control: bool = True) -> None:
        self.host, self.t0_s = host, t0_s
        self.controller_version = controller_version
        self.polyscope_version = polyscope_version
        self.serial_number = serial_number
        self.remote_control = remote_control
        self.regs = Registers()
        self.arm = arm
        self.script: ControlScript | None = None
        self.scripts_received: list[str] = []  # programs uploaded, in order
        self.dashboard_requests: list[str] = []
        self.runtime_state = RUNTIME_STOPPED
        self.safety_mode = SAFETY_MODE_NORMAL
        self.robot_mode = ROBOT_MODE_RUNNING
        self.output_paused = False  # fault injection: connections stay open, no data flows
        self._lock = threading.RLock()  # controller state (script, registers, sessions)
        self._sessions: list[_RtdeSession] = []
        self._conns: list[socket.socket] = []
        self._listeners: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()
        self._cycle = 0
        self._last_pose = np.zeros(6)
        self._last_t_s = 0.0

    # ---- life cycle ----------------------------------------------------------------------------
    def start(self) -> str:
        """Listen on the dashboard, RTDE and script ports; returns "host:30004" once ready."""
        if self._listeners:
            return f"{self.host}:{wire.PORT_RTDE}"
        self._stop.clear()
        self._open_listeners()
        self._spawn(self._controller_loop, "ur5e-emu-controller")
        return f"{self.host}:{wire.PORT_RTDE}"

    def stop(self) -> None:
        self._stop.set()
        self._close_listeners()
        self.drop_connections()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads.clear()

    def __enter__(self) -> URController:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _spawn(self, target, name: str, *args) -> None:
        t = threading.Thread(target=target, args=args, name=name, daemon=True)
        t.start()
        self._threads = [x for x in self._threads if x.is_alive()] + [t]

    def _open_listeners(self) -> None:
        handlers = {wire.PORT_DASHBOARD: self._serve_dashboard, wire.PORT_RTDE: self._serve_rtde,
                    wire.PORT_REALTIME: self._serve_script, wire.PORT_SECONDARY: self._serve_script}
        for port, handler in handlers.items():
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((self.host, port))
            except OSError as exc:
                s.close()
                self._close_listeners()
                raise OSError(f"ur5e emulator: cannot listen on {self.host}:{port} ({exc}); another emulator "
                              "or controller uses that address: give this one its own 127.x.y.z host") from exc
            s.listen(8)
            s.settimeout(0.1)
            self._listeners.append(s)
            self._spawn(self._accept_loop, f"ur5e-emu-accept-{port}", s, handler)

    def _close_listeners(self) -> None:
        for s in self._listeners:
            s.close()
        self._listeners.clear()

    def _accept_loop(self, lsock: socket.socket, handler) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = lsock.accept()
            except TimeoutError:
                continue
            except OSError:
                return  # listener closed
            conn.settimeout(None)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self._conns.append(conn)
            self._spawn(self._guard, f"ur5e-emu-conn-{lsock.getsockname()[1]}", handler, conn)

    def _guard(self, handler, conn: socket.socket) -> None:
        try:
            handler(conn)
        except OSError:
            pass  # the client went away or the emulator dropped the link
        finally:
            with self._lock:
                if conn in self._conns:
                    self._conns.remove(conn)
                self._sessions = [s for s in self._sessions if s.sock is not conn]
            conn.close()

    # ---- fault injection ------------------------------------------------------------------------
    def protective_stop(self) -> None:
        """A protective stop: the arm stops, safety mode 3, the program pauses."""
        self._safety_stop(SAFETY_MODE_PROTECTIVE_STOP)

    def emergency_stop(self) -> None:
        """A robot emergency stop (the e-stop button on the pendant)."""
        self._safety_stop(SAFETY_MODE_ROBOT_EMERGENCY_STOP)

    def _safety_stop(self, mode: int) -> None:
        self.arm.stop()
        with self._lock:
            self.safety_mode = mode
            if self.script is not None:
                self.script.halt()
            if self.runtime_state == RUNTIME_PLAYING:
                self.runtime_state = RUNTIME_PAUSED
        log.info("ur5e emulator: %s", SAFETY_MODE_NAMES[mode])

    def unlock_protective_stop(self) -> None:
        """What the pendant's / dashboard's unlock does: safety back to normal, program still paused."""
        with self._lock:
            if self.safety_mode == SAFETY_MODE_PROTECTIVE_STOP:
                self.safety_mode = SAFETY_MODE_NORMAL

    def drop_connections(self, refuse_s: float = 0.0) -> None:
        """Close every client connection (a cable pulled); for refuse_s the ports refuse new
        connections too, then it listens again. The program keeps running."""
        if refuse_s > 0:
            self._close_listeners()
            timer = threading.Timer(refuse_s, self._reopen)
            timer.daemon = True
            timer.start()
        with self._lock:
            conns, self._conns, self._sessions = list(self._conns), [], []
        for c in conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()

    def _reopen(self) -> None:
        if not self._stop.is_set() and not self._listeners:
            self._open_listeners()

    # ---- controller cycle -----------------------------------------------------------------------
    def _controller_loop(self) -> None:
        # Cycle k is stamped t0 + k * 2 ms, as a controller stamps its cycles; a cycle this
        # thread could not run at all (machine busy for > 100 ms) is skipped, and shows as a gap.
        origin = time.monotonic()
        t0_s = self.t0_s
        k = 0
        while not self._stop.is_set():
            try:
                self._cycle_once(t0_s + k * PERIOD_S)
            except Exception:  # noqa: BLE001 - a controller cycle must never kill the emulator
                log.exception("ur5e emulator: controller cycle failed")
            k += 1
            delay = origin + k * PERIOD_S - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.1:
                k = int((time.monotonic() - origin) / PERIOD_S)  # fell far behind: do not burst

    def _cycle_once(self, t_s: float) -> None:
        pose = self.arm.tcp_pose6()
        with self._lock:
            if self.arm.error is not None and self.script is not None and self.script.running:
                log.warning("ur5e emulator: control script runtime error, program stopped: %s", self.arm.error)
                self.script.running = False
                self.arm.error = None
            if self.script is not None and self.runtime_state == RUNTIME_PLAYING:
                try:
                    self.script.tick()
                except Exception as exc:  # noqa: BLE001 - a runtime error ends the program, like URControl
                    log.warning("ur5e emulator: control script runtime error, program stopped: %s", exc)
                    self.script.running = False
                if not self.script.running:
                    self.runtime_state = RUNTIME_STOPPED
            dt = t_s - self._last_t_s
            speed = (pose - self._last_pose) / dt if dt > 0 else np.zeros(6)
            self._last_pose, self._last_t_s = pose, t_s
            values = self._output_values(t_s, pose, speed)
            self._cycle += 1
            if self.output_paused:
                return
            targets = [(s, r) for s in self._sessions if s.started
                       for r, every in s.outputs if self._cycle % every == 0]
        for session, recipe in targets:
            try:
                session.send(wire.encode_data(recipe, values))
            except OSError:
                pass  # the reader thread of that connection cleans up

    def _output_values(self, t_s: float, pose: np.ndarray, speed: np.ndarray) -> dict:
        playing = self.runtime_state == RUNTIME_PLAYING
        bits = SAFETY_BIT_NORMAL
        if self.safety_mode == SAFETY_MODE_PROTECTIVE_STOP:
            bits = SAFETY_BIT_PROTECTIVE_STOPPED | SAFETY_BIT_STOPPED_DUE_TO_SAFETY
        elif self.safety_mode == SAFETY_MODE_ROBOT_EMERGENCY_STOP:
            bits = SAFETY_BIT_ROBOT_EMERGENCY_STOPPED | SAFETY_BIT_EMERGENCY_STOPPED | SAFETY_BIT_STOPPED_DUE_TO_SAFETY
        values = {
            "timestamp": t_s,
            "actual_TCP_pose": tuple(pose), "target_TCP_pose": tuple(pose),
            "actual_TCP_speed": tuple(speed), "target_TCP_speed": tuple(speed),
            "robot_mode": self.robot_mode, "safety_mode": self.safety_mode,
            "safety_status_bits": bits, "runtime_state": self.runtime_state,
            "robot_status_bits": ROBOT_STATUS_POWER_ON | (ROBOT_STATUS_PROGRAM_RUNNING if playing else 0),
            "speed_scaling": 1.0, "target_speed_fraction": 1.0, "joint_mode": (255,) * 6,
        }
        for i in range(48):
            values[f"output_int_register_{i}"] = self.regs.output_int[i]
            values[f"output_double_register_{i}"] = self.regs.output_double[i]
            values[f"input_int_register_{i}"] = self.regs.input_int[i]
            values[f"input_double_register_{i}"] = self.regs.input_double[i]
        return values

    # ---- RTDE (30004) ---------------------------------------------------------------------------
    def _serve_rtde(self, conn: socket.socket) -> None:
        session = _RtdeSession(conn)
        with self._lock:
            self._sessions.append(session)
        reader = wire.PacketReader()
        while not self._stop.is_set():
            data = conn.recv(65536)
            if not data:
                return
            for kind, payload in reader.feed(data):
                reply = self._rtde_request(session, kind, payload)
                if reply:
                    session.send(reply)

    def _rtde_request(self, session: _RtdeSession, kind: int, payload: bytes) -> bytes | None:
        if kind == wire.RTDE_REQUEST_PROTOCOL_VERSION:
            return wire.encode_accepted(kind, wire.decode_protocol_version_request(payload) in (1, 2))
        if kind == wire.RTDE_GET_URCONTROL_VERSION:
            return wire.encode_controller_version(*self.controller_version)
        if kind == wire.RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS:
            freq, names = wire.decode_setup_outputs_request(payload)
            types = [wire.variable_type(n, "output") for n in names]
            if "NOT_FOUND" in types or not 0 < freq <= 500:
                log.warning("ur5e emulator: output recipe refused (%.1f Hz, %s)", freq,
                            [n for n, t in zip(names, types, strict=True) if t == "NOT_FOUND"])
                return wire.encode_setup_reply(kind, 0, types)
            recipe = wire.Recipe(len(session.outputs) + 1, tuple(names), tuple(types))
            session.outputs.append((recipe, max(1, round(500.0 / freq))))
            return wire.encode_setup_reply(kind, recipe.recipe_id, types)
        if kind == wire.RTDE_CONTROL_PACKAGE_SETUP_INPUTS:
            names = wire.decode_setup_inputs_request(payload)
            types = [wire.variable_type(n, "input") for n in names]
            if "NOT_FOUND" in types:
                return wire.encode_setup_reply(kind, 0, types)
            recipe = wire.Recipe(len(session.inputs) + 1, tuple(names), tuple(types))
            session.inputs[recipe.recipe_id] = recipe
            return wire.encode_setup_reply(kind, recipe.recipe_id, types)
        if kind == wire.RTDE_CONTROL_PACKAGE_START:
            session.started = bool(session.outputs or session.inputs)
            return wire.encode_accepted(kind, session.started)
        if kind == wire.RTDE_CONTROL_PACKAGE_PAUSE:
            session.started = False
            return wire.encode_accepted(kind, True)
        if kind == wire.RTDE_DATA_PACKAGE:
            recipe = session.inputs.get(payload[0]) if payload else None
            if recipe is None:
                return wire.encode_text_message(f"unknown input recipe {payload[:1].hex()}", level=0)
            with self._lock:
                for name, value in recipe.decode(payload).items():
                    self._write_input(name, value)
            return None
        log.warning("ur5e emulator: RTDE package type %r not handled", chr(kind))
        return None

    def _write_input(self, name: str, value) -> None:
        if name.startswith("input_int_register_"):
            self.regs.input_int[int(name.rsplit("_", 1)[1])] = int(value)
        elif name.startswith("input_double_register_"):
            self.regs.input_double[int(name.rsplit("_", 1)[1])] = float(value)

    # ---- script upload (30003 / 30002) ----------------------------------------------------------
    def _serve_script(self, conn: socket.socket) -> None:
        buf = b""
        while not self._stop.is_set():
            data = conn.recv(65536)
            if not data:
                return
            buf += data
            while True:
                program, buf = _take_program(buf)
                if program is None:
                    break
                self._run_program(program)

    def _run_program(self, program: str) -> None:
        self.scripts_received.append(program)
        name = program.split("(", 1)[0].removeprefix("def ").strip()
        with self._lock:
            if name != "rtde_control":
                log.warning("ur5e emulator: program %r received and ignored (only rtde_control is emulated)", name)
                return
            if self.safety_mode != SAFETY_MODE_NORMAL:
                log.warning("ur5e emulator: program not started: robot is in %s",
                            SAFETY_MODE_NAMES.get(self.safety_mode, self.safety_mode))
                return
            if self.script is not None:
                self.script.halt()
            self.script = ControlScript(self.arm, self.regs)
            self.runtime_state = RUNTIME_PLAYING
        log.info("ur5e emulator: control script started (%d bytes)", len(program))

    # ---- dashboard (29999) ----------------------------------------------------------------------
    def _serve_dashboard(self, conn: socket.socket) -> None:
        conn.sendall(wire.encode_dashboard_line(wire.DASHBOARD_WELCOME))
        buf = bytearray()
        while not self._stop.is_set():
            data = conn.recv(4096)
            if not data:
                return
            buf += data
            for line in wire.dashboard_lines(buf):
                self.dashboard_requests.append(line)
                conn.sendall(wire.encode_dashboard_line(self._dashboard_answer(line)))

    def _dashboard_answer(self, line: str) -> str:
        with self._lock:
            program = "rtde_control" if self.script is not None else "<unnamed>"
            if line == "PolyscopeVersion":
                return self.polyscope_version
            if line == "get serial number":
                return self.serial_number
            if line == "is in remote control":
                return "true" if self.remote_control else "false"
            if line == "robotmode":
                return "Robotmode: RUNNING"
            if line == "safetystatus":
                return "Safetystatus: " + SAFETY_MODE_NAMES.get(self.safety_mode, "UNDEFINED")
            if line == "safetymode":
                return "Safetymode: " + SAFETY_MODE_NAMES.get(self.safety_mode, "UNDEFINED")
            if line == "programState":
                return f"{RUNTIME_NAMES[self.runtime_state]} {program}"
            if line == "running":
                return "Program running: " + ("true" if self.runtime_state == RUNTIME_PLAYING else "false")
            if line == "stop":
                if self.script is not None:
                    self.script.halt()
                    self.script.running = False
                self.runtime_state = RUNTIME_STOPPED
                self.arm.stop()
                return "Stopped"
            if line == "pause":
                if self.runtime_state == RUNTIME_PLAYING:
                    self.runtime_state = RUNTIME_PAUSED
                    self.arm.stop()
                    return "Pausing program"
                return "Failed to execute: Pause"
            if line == "play":
                if self.runtime_state == RUNTIME_PAUSED and self.safety_mode == SAFETY_MODE_NORMAL \
                        and self.script is not None and self.script.running:
                    self.runtime_state = RUNTIME_PLAYING
                    return "Starting program"
                return "Failed to execute: Play"
            if line == "unlock protective stop":
                if self.safety_mode == SAFETY_MODE_PROTECTIVE_STOP:
                    self.safety_mode = SAFETY_MODE_NORMAL
                    return "Protective stop releasing"
                return "Cannot unlock protective stop until 5s after occurrence. Always inspect cause of " \
                       "protective stop before unlocking"
            if line in ("close safety popup", "close popup"):
                return "closing safety popup" if line == "close safety popup" else "closing popup"
            if line in ("quit",):
                return "Disconnected"
            return f"could not understand: '{line}'"


def _take_program(buf: bytes) -> tuple[str | None, bytes]:
    """The first complete `def name(): ... end` program in buf (a line "end" at column 0 closes
    it), and what follows; (None, buf) while incomplete."""
    text = buf.decode("utf-8", errors="replace")
    start = text.find("def ")
    if start < 0:
        return None, buf
    i = text.find("\nend", start)
    while i >= 0:
        j = i + len("\nend")
        if j == len(text) or text[j] in "\r\n":
            end = j + 1 if j < len(text) else j
            return text[start:j], text[end:].encode()
        i = text.find("\nend", j)
    return None, buf


# ---- process entry: python -m hardware.ur5e.controller FD HOST T0 ------------------------------
def _info(ctl: URController) -> dict:
    script = ctl.script
    return {"scripts_received": len(ctl.scripts_received), "dashboard_requests": list(ctl.dashboard_requests),
            "commands": list(script.commands) if script else [],
            "unsupported": list(script.unsupported) if script else [],
            "runtime_state": ctl.runtime_state, "safety_mode": ctl.safety_mode,
            "connections": len(ctl._conns)}


def main(argv: list[str]) -> int:
    from multiprocessing.connection import Connection

    logging.basicConfig(level=logging.WARNING, format="ur5e-controller %(levelname)s %(message)s")
    conn = Connection(int(argv[0]))
    arm = BridgedArm(conn)
    ctl = URController(arm, host=argv[1], t0_s=float(argv[2]))
    try:
        where = ctl.start()
    except OSError as exc:
        conn.send(("error", 0, str(exc)))
        return 1
    arm._send(("ready", where))
    last_info = None
    try:
        while True:
            msg = conn.recv()
            kind = msg[0]
            if kind == "state":
                arm.on_state(*msg[1:])
            elif kind == "fault":
                getattr(ctl, msg[1])(*msg[2:])
            elif kind == "set":
                setattr(ctl, msg[1], msg[2])
            elif kind == "quit":
                break
            info = _info(ctl)
            if info != last_info:
                arm._send(("info", info))
                last_info = info
    except (EOFError, OSError):
        pass  # the parent went away
    finally:
        ctl.stop()
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
