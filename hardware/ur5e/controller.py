"""The emulated UR controller process: dashboard, RTDE and script ports, the control script.

Runs in its own process (`python -m hardware.ur5e.controller FD OPTIONS_JSON`: host, t0_s,
limits), started by `UR5eEmulator` through `hardware.emulation.DeviceProcess`, for the reason a real controller is another machine: the ur_rtde client's Python
constructors hold the GIL while they wait for the controller's answers, so a controller served
by threads of the client's own process could never answer them. The simulated arm stays in the
parent (with the world); this process sees it as a `BridgedArm`: the parent pushes the TCP pose
every 2 ms cycle over a pipe (FD, a multiprocessing Connection) and applies the moves and stops
this process sends back. Fault injection and test read-outs go over the same pipe.

One controller thread runs the 500 Hz cycle: it advances the control script (the register
protocol of the uploaded `rtde_control` script) and queues for every started RTDE connection its
output recipe at the frequency it asked for. Cycle k is stamped T0 + k * 2 ms (controller time:
the world's time when the emulator started). Socket readers run one thread per connection; each
RTDE connection also has a writer thread, so neither the cycle nor another client ever waits on a
client that stopped reading (see _RtdeSession). The dashboard answers from its reader thread,
which holds no lock while it sends.
"""

from __future__ import annotations

import contextlib
import logging
import math
import socket
import struct
import threading
import time
from collections import deque

import numpy as np

from hardware.ur5e import wire
from hardware.ur5e.control_script import ControlScript, Registers, ToolSettings
from hardware.ur5e.wire import (
    ROBOT_MODE_IDLE,
    ROBOT_MODE_NAMES,
    ROBOT_MODE_POWER_OFF,
    ROBOT_MODE_RUNNING,
    ROBOT_STATUS_POWER_ON,
    ROBOT_STATUS_PROGRAM_RUNNING,
    RUNTIME_NAMES,
    RUNTIME_PAUSED,
    RUNTIME_PLAYING,
    RUNTIME_STOPPED,
    SAFETY_MODE_NAMES,
    SAFETY_MODE_NORMAL,
    SAFETY_MODE_PROTECTIVE_STOP,
    SAFETY_MODE_ROBOT_EMERGENCY_STOP,
)

log = logging.getLogger(__name__)

EMULATOR_SETUP = "gripper"

PERIOD_S = 0.002  # the controller cycle (500 Hz)

# One program upload at most this long (ur_rtde's control script is 42 kB); longer text, or a
# line this long outside a program, is dropped so a stray upload cannot fill the memory.
MAX_PROGRAM_BYTES = 1 << 20
ROBOT_MODEL = "UR5"  # what the dashboard's "get robot model" answers for a UR5e
PROGRAMS_DIR = "/programs"  # where PolyScope keeps .urp programs ("load" paths are relative to it)
# What one RTDE client's outbox holds (data packages and replies) before the controller cycle
# drops that client's packages: 0.1 s of 500 Hz output, on top of what the sockets buffer.
OUTBOX_PACKAGES = 50
FLUSH_S = 1.0  # how long a closing RTDE connection's last messages (an "M" before a close) may take


class BridgedArm:
    """The simulated arm as this process sees it: state pushed by the parent's bridge every
    cycle, commands sent back to it. A command counts as moving until the parent reports it
    applied (the state it pushed before may predate the command)."""

    def __init__(self, conn, limits: dict | None = None) -> None:
        self.conn = conn
        # the twin's ARM_LIMITS (workspace box: the safety planes; speed limits); None: unlimited
        self.limits = limits
        self._send_lock = threading.Lock()
        self.pose = np.zeros(6)
        self.speed = np.zeros(6)  # TCP twist [v (m/s), w (rad/s)], base frame
        self.t_s = 0.0
        self.moving = False
        self.sent_id = 0
        self.applied_id = 0
        self.error: str | None = None

    def _send(self, msg: tuple) -> None:
        """msg to the parent, numbered (the parent reports the highest number it applied)."""
        with self._send_lock:
            self.sent_id += 1
            self.conn.send((msg[0], self.sent_id, *msg[1:]))

    def post(self, msg: tuple) -> None:
        """msg to the parent as it is (ready, error, log: kept by the parent's DeviceProcess)."""
        with self._send_lock:
            self.conn.send(msg)

    def move_linear(self, pose6, speed_m_s, accel_m_s2, angular_speed_rad_s, stop_at_workspace=False):
        """stop_at_workspace: end the move where it would leave the twin's workspace (speedl)
        instead of refusing it (movel to a target outside)."""
        self._send(("move", np.asarray(pose6, float).tolist(), float(speed_m_s), float(accel_m_s2),
                    None if angular_speed_rad_s is None else float(angular_speed_rad_s), bool(stop_at_workspace)))

    def stop(self):
        self._send(("stop",))

    def is_moving(self):
        return self.moving or self.applied_id < self.sent_id

    def tcp_pose6(self):
        return self.pose.copy()

    def within_safety_limits(self, pose6) -> bool:
        """Whether a TCP pose is inside the safety planes (the twin's workspace box)."""
        p = np.asarray(pose6, float)
        if p.shape != (6,) or not np.all(np.isfinite(p)):
            return False
        if self.limits is None:
            return True
        lo, hi = (np.asarray(self.limits[k], float) for k in ("workspace_min_m", "workspace_max_m"))
        return bool(np.all(p[:3] >= lo) and np.all(p[:3] <= hi))

    def on_state(self, t_s: float, pose6, moving: bool, applied_id: int, error: str | None, speed6) -> None:
        """speed6: the twin's TCP twist (its motion state, not a difference of sampled poses: the
        bridge and the world advance on clocks of their own)."""
        self.t_s, self.pose, self.moving, self.applied_id = t_s, np.asarray(pose6, float), moving, applied_id
        self.speed = np.asarray(speed6, float)
        if error is not None:
            self.error = error


class _RtdeSession:
    """One RTDE client connection: its recipes, whether it has started, and its outbox.

    Nothing that serves other clients waits on this client's socket: what goes to it is queued
    (at most OUTBOX_PACKAGES) and one writer thread per connection sends it. The controller
    cycle offers its data packages and never waits: where this client's outbox is full (a
    client that stopped reading) the package is dropped and counted, the client sees a gap in
    the timestamps, and every other client and the control script go on. The connection's
    reader queues its replies, waiting only for room in this outbox (the client's own flow
    control: a client that sends requests and never reads the answers stops being read).
    """

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.outputs: list[tuple[wire.Recipe, int]] = []  # (recipe, send every n cycles)
        self.inputs: dict[int, wire.Recipe] = {}
        self.started = False
        self.dropped = 0  # data packages this client's full outbox could not take
        self._out: deque[bytes] = deque()
        self._cv = threading.Condition()
        self._closing = False  # no more queueing; the writer sends what is queued and ends

    def offer(self, data: bytes) -> None:
        """A data package from the controller cycle: queued, or dropped if the outbox is full."""
        with self._cv:
            if self._closing:
                return
            if len(self._out) >= OUTBOX_PACKAGES:
                self.dropped += 1
                return
            self._out.append(data)
            self._cv.notify_all()

    def send(self, data: bytes) -> None:
        """A reply from this connection's reader: queued in order, waiting for room if need be.
        OSError once the connection is closing (the writer failed or the link was dropped)."""
        with self._cv:
            while len(self._out) >= OUTBOX_PACKAGES and not self._closing:
                self._cv.wait()
            if self._closing:
                raise OSError("RTDE connection closing")
            self._out.append(data)
            self._cv.notify_all()

    def write_loop(self) -> None:
        """The writer thread: send the outbox in order until the session closes and is flushed."""
        while True:
            with self._cv:
                while not self._out and not self._closing:
                    self._cv.wait()
                if not self._out:
                    return
                data = self._out.popleft()
                self._cv.notify_all()
            try:
                self.sock.sendall(data)
            except OSError:
                self.close()
                with self._cv:
                    self._out.clear()
                return

    def close(self) -> None:
        """Queue nothing more; the writer sends what is already queued, then ends."""
        with self._cv:
            self._closing = True
            self._cv.notify_all()


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
        self.dashboard_requests: deque[str] = deque(maxlen=200)  # the latest, for tests
        self.runtime_state = RUNTIME_STOPPED
        self.safety_mode = SAFETY_MODE_NORMAL
        self.robot_mode = ROBOT_MODE_RUNNING  # powered on, brakes released
        self.loaded_program: str | None = None  # dashboard "load" (a .urp path)
        self.urp_playing = False  # the loaded program was started by dashboard "play" (it moves nothing)
        self.tool = ToolSettings()  # the installation's TCP and payload (a program may set its own)
        # Standard I/O set over RTDE (RTDEIOInterface): digital outputs (bits 0-7 standard, 8-15
        # configurable, 16-17 tool, as actual_digital_output_bits), analog outputs, speed slider.
        self.digital_outputs = 0
        self.analog_outputs = [0.0, 0.0]
        self.analog_output_types = 0  # analog_io_types bits 2, 3: output 0, 1 (0 current, 1 voltage)
        self.speed_fraction = 1.0
        self.output_paused = False  # fault injection: connections stay open, no data flows
        self._lock = threading.RLock()  # controller state (script, registers, sessions)
        self._sessions: list[_RtdeSession] = []
        self._conns: list[socket.socket] = []
        self._listeners: list[socket.socket] = []
        self._threads: list[threading.Thread] = []
        self._stop = threading.Event()
        self._cycle = 0

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
            with contextlib.suppress(OSError):
                s.shutdown(socket.SHUT_RDWR)  # wakes the thread in accept() now (close alone does not)
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
        except Exception as exc:  # noqa: BLE001 - one client's bad input must not end the emulator
            log.warning("ur5e emulator: connection to port %s closed after an error: %r",
                        conn.getsockname()[1] if conn.fileno() >= 0 else "?", exc)
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
            if self.script is not None and self.runtime_state == RUNTIME_PLAYING and not self.urp_playing:
                try:
                    self.script.tick()
                except Exception as exc:  # noqa: BLE001 - a runtime error ends the program, like URControl
                    log.warning("ur5e emulator: control script runtime error, program stopped: %s", exc)
                    self.script.running = False
                if not self.script.running:
                    self.runtime_state = RUNTIME_STOPPED
            if self.script is not None:
                self.script.speed_fraction = self.speed_fraction
            values = self._output_values(t_s, pose, self.arm.speed.copy())
            self._cycle += 1
            if self.output_paused:
                return
            targets = [(s, r) for s in self._sessions if s.started
                       for r, every in s.outputs if self._cycle % every == 0]
        for session, recipe in targets:
            session.offer(wire.encode_data(recipe, values))  # never waits on a client's socket

    def _output_values(self, t_s: float, pose: np.ndarray, speed: np.ndarray) -> dict:
        playing = self.runtime_state == RUNTIME_PLAYING
        tool = self.script.tool if self.script is not None and self.script.running else self.tool
        powered = self.robot_mode > ROBOT_MODE_POWER_OFF
        values = {
            "timestamp": t_s,
            "actual_TCP_pose": tuple(pose), "target_TCP_pose": tuple(pose),
            "actual_TCP_speed": tuple(speed), "target_TCP_speed": tuple(speed),
            "robot_mode": self.robot_mode, "safety_mode": self.safety_mode,
            "safety_status_bits": wire.safety_status_bits(self.safety_mode), "runtime_state": self.runtime_state,
            "robot_status_bits": (ROBOT_STATUS_POWER_ON if powered else 0)
            | (ROBOT_STATUS_PROGRAM_RUNNING if playing else 0),
            # speed_scaling: the trajectory limiter's (the script's); the slider is target_speed_fraction
            # (clients multiply the two, as Universal Robots' ROS driver does)
            "speed_scaling": self.script.speed_scaling if playing and self.script is not None else 1.0,
            "target_speed_fraction": self.speed_fraction,
            "joint_mode": (255,) * 6,
            "payload": tool.payload_kg, "payload_cog": tuple(tool.payload_cog_m),
            "actual_digital_output_bits": self.digital_outputs,
            "standard_analog_output0": self.analog_outputs[0], "standard_analog_output1": self.analog_outputs[1],
            "analog_io_types": self.analog_output_types << 2,
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
        writer = threading.Thread(target=session.write_loop, name="ur5e-emu-rtde-out", daemon=True)
        writer.start()
        with self._lock:
            self._sessions.append(session)
        reader = wire.PacketReader()
        bad = 0  # malformed packages on this connection: the first is logged, the rest counted
        try:
            while not self._stop.is_set():
                data = conn.recv(65536)
                if not data:
                    return
                try:
                    packages = reader.feed(data)
                except ValueError as exc:  # a size below the header: the stream cannot be framed any more
                    bad += 1
                    (log.warning if bad == 1 else log.info)("ur5e emulator: RTDE connection closed: %s", exc)
                    session.send(wire.encode_text_message(f"malformed package: {exc}", level=0))
                    return
                for kind, payload in packages:
                    try:
                        reply = self._rtde_request(session, kind, payload)
                    except (ValueError, IndexError, struct.error, UnicodeError) as exc:
                        bad += 1
                        if bad == 1:
                            log.warning("ur5e emulator: malformed RTDE package %r (%d bytes) refused: %s",
                                        chr(kind), len(payload), exc)
                        reply = _refusal(kind, str(exc))
                    if reply:
                        session.send(reply)
        finally:
            session.close()  # the writer sends what is queued (an "M" before a close), then ends
            writer.join(FLUSH_S)
            if writer.is_alive():  # a client that does not read: wake the writer from its send
                with contextlib.suppress(OSError):
                    conn.shutdown(socket.SHUT_RDWR)
                writer.join(FLUSH_S)
            if bad > 1:
                log.info("ur5e emulator: %d malformed RTDE packages on one connection", bad)
            if session.dropped:
                log.warning("ur5e emulator: %d RTDE data packages dropped for a client that did not read them",
                            session.dropped)

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
            if "NOT_FOUND" in types or not names:
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
            values = recipe.decode(payload)
            with self._lock:
                self._apply_inputs(values)
            return None
        raise ValueError(f"unknown package type {kind}")

    def _apply_inputs(self, values: dict) -> None:
        """One input package: registers, and the standard I/O and speed slider under their masks."""
        for name, value in values.items():
            if name.startswith("input_int_register_"):
                self.regs.input_int[int(name.rsplit("_", 1)[1])] = int(value)
            elif name.startswith("input_double_register_"):
                self.regs.input_double[int(name.rsplit("_", 1)[1])] = float(value)
        for group, shift in (("standard", 0), ("configurable", 8), ("tool", 16)):
            mask = int(values.get(f"{group}_digital_output_mask", 0))
            if mask:
                level = int(values.get(f"{group}_digital_output", 0))
                if group == "tool":
                    mask &= 0b11  # two tool outputs
                self.digital_outputs = (self.digital_outputs & ~(mask << shift)) | ((level & mask) << shift)
        mask = int(values.get("standard_analog_output_mask", 0))
        kinds = int(values.get("standard_analog_output_type", 0))
        for i in (0, 1):
            if mask & (1 << i):
                self.analog_outputs[i] = min(max(float(values.get(f"standard_analog_output_{i}", 0.0)), 0.0), 1.0)
                self.analog_output_types = (self.analog_output_types & ~(1 << i)) | (kinds & (1 << i))
        if int(values.get("speed_slider_mask", 0)) & 1:
            fraction = float(values.get("speed_slider_fraction", 1.0))
            if math.isfinite(fraction):
                self.speed_fraction = min(max(fraction, 0.0), 1.0)

    # ---- script upload (30003 / 30002) ----------------------------------------------------------
    def _serve_script(self, conn: socket.socket) -> None:
        reader = ScriptReader(MAX_PROGRAM_BYTES)
        try:
            while not self._stop.is_set():
                data = conn.recv(65536)
                if not data:
                    return
                for program in reader.feed(data):
                    self._run_program(program)
        finally:
            if reader.ignored_lines or reader.dropped_bytes:
                log.warning("ur5e emulator: script connection closed; %d script lines outside a program ignored, "
                            "%d bytes over the %d-byte program limit dropped", reader.ignored_lines,
                            reader.dropped_bytes, MAX_PROGRAM_BYTES)

    def _run_program(self, program: str) -> None:
        name = program.split("(", 1)[0].split(None, 1)[-1].strip()
        self.scripts_received.append(name)
        with self._lock:
            if name != "rtde_control":
                log.warning("ur5e emulator: program %r received and ignored (only rtde_control is emulated)", name)
                return
            if self.robot_mode != ROBOT_MODE_RUNNING:
                log.warning("ur5e emulator: program not started: robot mode %s",
                            ROBOT_MODE_NAMES.get(self.robot_mode, self.robot_mode))
                return
            if self.safety_mode != SAFETY_MODE_NORMAL:
                log.warning("ur5e emulator: program not started: robot is in %s",
                            SAFETY_MODE_NAMES.get(self.safety_mode, self.safety_mode))
                return
            if self.script is not None:
                self.script.halt()
            self.script = ControlScript(self.arm, self.regs, protective_stop=self.protective_stop)
            self.runtime_state = RUNTIME_PLAYING
            self.urp_playing = False  # an uploaded script replaces the program that was running
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
                if line == "quit":
                    return  # the server closes the connection after "Disconnected"
            if len(buf) > wire.DASHBOARD_MAX_LINE_BYTES:  # no newline in sight: not a command
                log.warning("ur5e emulator: dashboard line over %d bytes dropped", wire.DASHBOARD_MAX_LINE_BYTES)
                buf.clear()

    def _stop_program(self) -> None:
        if self.script is not None:
            self.script.halt()
            self.script.running = False
        self.urp_playing = False
        self.runtime_state = RUNTIME_STOPPED
        self.arm.stop()

    def _dashboard_answer(self, line: str) -> str:
        """The Dashboard server's answer (Universal Robots, "Dashboard server e-Series", PolyScope 5)."""
        command, _, argument = line.partition(" ")
        with self._lock:
            if self.script is not None and self.script.running and not self.urp_playing:
                program = "rtde_control"
            else:
                program = self.loaded_program.rsplit("/", 1)[-1] if self.loaded_program else "<unnamed>"
            if line == "PolyscopeVersion":
                return self.polyscope_version
            if line == "get serial number":
                return self.serial_number
            if line == "get robot model":
                return ROBOT_MODEL
            if line == "is in remote control":
                return "true" if self.remote_control else "false"
            if line == "robotmode":
                return "Robotmode: " + ROBOT_MODE_NAMES.get(self.robot_mode, "UNDEFINED")
            if line == "safetystatus":
                return "Safetystatus: " + SAFETY_MODE_NAMES.get(self.safety_mode, "UNDEFINED")
            if line == "safetymode":
                return "Safetymode: " + SAFETY_MODE_NAMES.get(self.safety_mode, "UNDEFINED")
            if line == "programState":
                return f"{RUNTIME_NAMES[self.runtime_state]} {program}"
            if line == "running":
                return "Program running: " + ("true" if self.runtime_state == RUNTIME_PLAYING else "false")
            if line == "get loaded program":
                return f"Loaded program: {self.loaded_program}" if self.loaded_program else "No program loaded"
            if command == "load" and argument and not argument.startswith("installation"):
                # There is no program store: any .urp name counts as present.
                if not argument.endswith(".urp"):
                    return f"File not found: {argument}"
                self.loaded_program = argument if argument.startswith("/") else f"{PROGRAMS_DIR}/{argument}"
                return f"Loading program: {argument}"
            if line == "power on":
                if self.robot_mode <= ROBOT_MODE_POWER_OFF:
                    self.robot_mode = ROBOT_MODE_IDLE
                return "Powering on"
            if line == "brake release":
                if self.robot_mode <= ROBOT_MODE_IDLE:  # powers the arm on first where it is off
                    self.robot_mode = ROBOT_MODE_RUNNING
                return "Brake releasing"
            if line == "power off":
                self._stop_program()
                self.robot_mode = ROBOT_MODE_POWER_OFF
                return "Powering off"
            if line == "stop":
                self._stop_program()
                return "Stopped"
            if line == "pause":
                if self.runtime_state == RUNTIME_PLAYING:
                    self.runtime_state = RUNTIME_PAUSED
                    self.arm.stop()
                    return "Pausing program"
                return "Failed to execute: Pause"
            if line == "play":
                if self.runtime_state == RUNTIME_PAUSED and self.safety_mode == SAFETY_MODE_NORMAL \
                        and self.robot_mode == ROBOT_MODE_RUNNING and self.script is not None and self.script.running:
                    self.runtime_state = RUNTIME_PLAYING
                    return "Starting program"
                # the loaded .urp (dashboard "load"): started from stopped, resumed from paused
                script_runs = self.script is not None and self.script.running and not self.urp_playing
                if self.loaded_program is not None and not script_runs and self.safety_mode == SAFETY_MODE_NORMAL \
                        and self.robot_mode == ROBOT_MODE_RUNNING:
                    self.urp_playing = True
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
            if line == "quit":
                return "Disconnected"
            return f"could not understand: '{line}'"


def _refusal(kind: int, why: str) -> bytes:
    """The answer to a request the controller could not decode: "not accepted" for the requests
    that have a yes/no answer, recipe 0 for a set-up, a text message (level exception) otherwise."""
    if kind in (wire.RTDE_REQUEST_PROTOCOL_VERSION, wire.RTDE_CONTROL_PACKAGE_START, wire.RTDE_CONTROL_PACKAGE_PAUSE):
        return wire.encode_accepted(kind, False)
    if kind in (wire.RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS, wire.RTDE_CONTROL_PACKAGE_SETUP_INPUTS):
        return wire.encode_setup_reply(kind, 0, [])
    return wire.encode_text_message(f"malformed package {kind}: {why}", level=0)


class ScriptReader:
    """Programs out of a script-port byte stream, line by line in bounded memory.

    A program runs from a line `def name():` (or `sec`) to a line `end` at column 0; lines
    outside one are one-line programs (counted in ignored_lines: the emulator runs none). A
    program, or a line, longer than limit_bytes is dropped (dropped_bytes) and reading goes on at
    the next line.
    """

    def __init__(self, limit_bytes: int) -> None:
        self.limit = limit_bytes
        self.ignored_lines = 0
        self.dropped_bytes = 0
        self._line = bytearray()
        self._program: list[str] | None = None
        self._size = 0
        self._skip_line = False  # dropping the rest of an overlong line

    @property
    def buffered_bytes(self) -> int:
        return len(self._line) + self._size

    def feed(self, data: bytes) -> list[str]:
        out: list[str] = []
        pos = 0
        while pos < len(data):
            nl = data.find(b"\n", pos)
            end = len(data) if nl < 0 else nl
            chunk, pos = data[pos:end], end + 1
            if self._skip_line:
                self.dropped_bytes += len(chunk)
                self._skip_line = nl < 0
                continue
            if self.buffered_bytes + len(chunk) > self.limit:
                self.dropped_bytes += self.buffered_bytes + len(chunk)
                self._line.clear()
                self._program, self._size = None, 0
                self._skip_line = nl < 0
                continue
            self._line += chunk
            if nl < 0:
                break
            out.extend(self._take_line())
        if self._program is not None and self._line.rstrip() == b"end":
            out.extend(self._take_line())  # the last line of an upload may come without a newline
        return out

    def _take_line(self) -> list[str]:
        raw = bytes(self._line)
        self._line.clear()
        text = raw.decode("utf-8", errors="replace").rstrip("\r")
        if self._program is None:
            if text.startswith(("def ", "sec ")):
                self._program, self._size = [text], len(raw) + 1
            elif text.strip():
                self.ignored_lines += 1
            return []
        self._program.append(text)
        self._size += len(raw) + 1
        if text.rstrip() == "end":
            program = "\n".join(self._program)
            self._program, self._size = None, 0
            return [program]
        return []


# ---- process entry: python -m hardware.ur5e.controller FD OPTIONS_JSON ------------------------
def _info(ctl: URController) -> dict:
    script = ctl.script
    return {"scripts_received": len(ctl.scripts_received), "dashboard_requests": list(ctl.dashboard_requests),
            "commands": list(script.commands) if script else [],
            "unsupported": list(script.unsupported) if script else [],
            "runtime_state": ctl.runtime_state, "safety_mode": ctl.safety_mode, "robot_mode": ctl.robot_mode,
            "tcp_offset": list(script.tool.tcp_offset) if script else None,
            "payload_kg": script.tool.payload_kg if script else None,
            "payload_cog_m": list(script.tool.payload_cog_m) if script else None,
            "connections": len(ctl._conns), "output_paused": ctl.output_paused}


class ControllerProcess:
    """The controller process's side of the pipe (`hardware.emulation.serve_device` runs it):
    the parent's twin state in, fault injection and settings applied, read-outs out. The parent
    sends through a DeviceProcess (its own sender thread), so it always comes back to reading
    what this side sends; this side's sends (read-outs here, moves from the controller thread)
    share BridgedArm's lock."""

    def __init__(self, conn, *, host: str, t0_s: float, limits: dict | None = None) -> None:
        self.conn = conn
        self.arm = BridgedArm(conn, limits)
        self.ctl = URController(self.arm, host=host, t0_s=t0_s)

    def run(self) -> None:
        logging.basicConfig(level=logging.WARNING, format="ur5e-controller %(levelname)s %(message)s")
        while (msg := self.conn.recv())[0] != "state":  # the twin's pose before any client sees one
            if msg[0] == "quit":
                return
        self.arm.on_state(*msg[1:])
        try:
            where = self.ctl.start()
        except OSError as exc:  # its address is taken: the parent raises this
            self.arm.post(("error", str(exc)))
            return
        self.arm.post(("ready", where))
        last_info = None
        try:
            while True:
                msg = self.conn.recv()
                kind = msg[0]
                if kind == "state":
                    self.arm.on_state(*msg[1:])
                elif kind == "fault":
                    getattr(self.ctl, msg[1])(*msg[2:])
                elif kind == "set":
                    setattr(self.ctl, msg[1], msg[2])
                elif kind == "quit":
                    break
                info = _info(self.ctl)
                if info != last_info:
                    self.arm._send(("info", info, None))  # (no acknowledgement: see wait_info)
                    last_info = info
        finally:
            self.ctl.stop()


def main(argv: list[str]) -> int:
    from hardware.emulation import serve_device

    return serve_device(ControllerProcess, argv, (EOFError, OSError))  # OSError: the parent went away


if __name__ == "__main__":
    import sys

    sys.exit(main(sys.argv[1:]))
