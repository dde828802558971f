"""UR5e driver over ur_rtde: RTDEReceiveInterface for state, RTDEControlInterface for motion.

How moves are commanded
- Translations (no angular speed given): `moveL(pose, v, a, asynchronous=True)`; the control
  script runs movel in a thread and reports it in its asynchronous-status register
  (output_int_register_2: running bit 15, operation id bits 24-30), which the receive recipe
  carries, so is_moving() needs no command round trip.
- Rotations with an angular speed (the 1.5 deg/s torsion about the tool axis): `speedL` with the
  twist [dp/T, w * axis] (m/s, rad/s, base frame; T = angle / w), the driver's own profile: it
  watches the TCP orientation and, one braking distance (w^2 / 2 alpha) before the target,
  commands a zero twist (the controller decelerates at alpha), then `speedStop` once at rest.
  Why not moveL: URScript documents movel's v and a in m/s and m/s^2 only; for orientation the
  controller derives its own angular limits from them and plans the orientation on rotation-vector
  components, which is undocumented and misbehaves near |r| = pi, where a tool pointing down
  sits. speedL's rotational part is documented in rad/s about the TCP, so the commanded rate is
  the rate the tool turns. servoL would need setpoints streamed at 500 Hz from Python.
  Angular acceleration alpha: the `accel_m_s2` argument taken as rad/s^2 for such moves (the
  grip protocol's trajectory.accel_mm_s2 documents that use), so Arm.move_linear keeps its
  signature.
- stop(): `stopL(decel, asynchronous=True)` for moveL (returns after the command handshake; the
  controller decelerates on its own), `speedStop(decel)` for a speedL move (it must end the
  script's speed thread; at stop_decel from 1.5 deg/s that takes milliseconds). Any thread may
  call it; all calls on the control client go through one lock (the client is not thread-safe).

State and health
- A receive thread polls the receive client every poll_period_s (its cache holds the latest
  500 Hz package) and turns each new controller timestamp into a Pose (frame "base",
  device_t_ns = controller timestamp, host_t_ns at poll). seq = timestamp / 2 ms, so packages the
  poll did not see count as `lost` (the client keeps only the latest package).
- Tool: on every control-script start (connect, reconnect, restart_program) the driver sets the
  Hand-E's TCP offset and payload from the config (setTcp, setPayload) and reads the TCP back.
- fault(): link lost, emergency stop, protective stop, control program not running, stall. A
  stall is judged by the controller's timestamp (hardware.watchdog.DeviceClock), not by when the
  receive thread last polled: before calling one, fault() asks the receive client's cache (which
  ur_rtde's own thread fills) for the newest timestamp, so a poll thread the host did not run is
  not a silent controller.
  A dropped link is reconnected (reconnect() on both clients, counted in health.reconnects); a
  move in progress is not resumed, and nothing is ever resumed after a protective stop: that
  needs an operator (unlock on the pendant, then restart_program()).
"""

from __future__ import annotations

import ctypes
import logging
import threading
import time
from collections import deque

import numpy as np
from scipy.spatial.transform import Rotation

from hardware.interfaces import Arm, DeviceError
from hardware.ur5e.config import UR5eConfig
from hardware.ur5e.wire import (
    RUNTIME_NAMES,
    RUNTIME_PLAYING,
    SAFETY_BIT_PROTECTIVE_STOPPED,
    SAFETY_EMERGENCY_STOPPED,
    probe_stream,
)
from hardware.watchdog import DeviceClock
from layerskin_exp.types import Pose

log = logging.getLogger(__name__)

CONTROLLER_PERIOD_S = 0.002
PROBE_TIMEOUT_S = 2.0  # for the controller's first RTDE data package (it streams at 125-500 Hz)
ASYNC_RUNNING_BIT = 1 << 15


def async_status(word: int) -> tuple[bool, int]:
    """(running, operation id) of the control script's asynchronous-status register."""
    word &= 0xFFFFFFFF
    return bool(word & ASYNC_RUNNING_BIT), (word >> 24) & 0x7F


# ur_rtde clients left behind when their controller hung (see UR5eArm._close_clients)
_ABANDONED: list = []
_CLOSED: list = []  # disconnected clients, destroyed at exit (see _close_clients)


def _require_streaming(recv) -> None:
    """A controller that takes the RTDE connection but sends no data: the receive client gives up
    (~2.5 s, not connected), while the control client would loop reconnecting for ever inside its
    constructor, holding the interpreter lock (no timeout, no signal could end the process)."""
    if not recv.isConnected():
        raise ConnectionError("the controller accepted the RTDE connection but sends no data (stalled)")

class UR5eArm(Arm):
    """The UR5e through ur_rtde. See the module docstring for how moves are commanded."""

    def __init__(self, cfg: UR5eConfig) -> None:
        super().__init__()
        self.cfg = cfg
        self._ctrl = None  # rtde_control.RTDEControlInterface
        self._recv = None  # rtde_receive.RTDEReceiveInterface
        self._io = threading.RLock()  # every call on the control client
        self._buf: deque[Pose] = deque()
        self._buf_lock = threading.Lock()
        self._stop_evt = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_seq: int | None = None
        self._last_rx_ns: int | None = None
        self._controller_clock = DeviceClock()  # when the controller made its newest package, host clock
        self._pose6 = np.zeros(6)
        self._safety_bits = 1
        self._runtime_state = RUNTIME_PLAYING
        self._link_error: str | None = None
        # Motion bookkeeping.
        self._move_kind: str | None = None  # "movel" | "speedl" | "stopl" | None
        self._op_before = -1  # async operation id before the last moveL/stopL was sent
        self._op_sent_ns = 0
        self._torsion: threading.Thread | None = None
        self._torsion_cancel = threading.Event()

    # ---- connection ----------------------------------------------------------------------------
    def _connect(self) -> None:
        try:
            import rtde_control
            import rtde_receive
        except ImportError as exc:
            raise DeviceError("arm: the ur_rtde package is not installed (pip install ur_rtde)") from exc
        host, cfg = self.cfg.host, self.cfg
        result: dict = {}

        # A controller that accepts RTDE but sends no data would trap ur_rtde's control client
        # in its constructor, reconnecting for ever with the interpreter lock held (no signal
        # could end the run): ask for one data package first, on plain sockets.
        try:
            missing = probe_stream(host, min(cfg.connect_timeout_s, PROBE_TIMEOUT_S), cfg.rtde_frequency_hz)
        except OSError as exc:
            missing = f"RTDE port: {exc}"
        if missing is not None:
            raise DeviceError(f"arm: cannot connect to the UR controller at {host}: it "
                              + ("accepted the RTDE connection but sends no data (stalled"
                                 if missing.startswith("no data") else f"answered no RTDE request ({missing}")
                              + "); check the address (hardware.ur5e.host), that the robot is on and in remote "
                              "control, and that ports 29999/30003/30004 are reachable")

        def open_clients() -> None:
            try:
                result["recv"] = rtde_receive.RTDEReceiveInterface(host, cfg.rtde_frequency_hz)
                _require_streaming(result["recv"])
                result["ctrl"] = rtde_control.RTDEControlInterface(host)
            except Exception as exc:  # noqa: BLE001 - reported below with the address
                result["error"] = exc

        t = threading.Thread(target=open_clients, name="ur5e-connect", daemon=True)
        t.start()
        t.join(cfg.connect_timeout_s)
        if t.is_alive() or "error" in result:
            for key in ("ctrl", "recv"):
                if key in result:
                    _quiet(result[key].disconnect)
            why = "no answer" if t.is_alive() else str(result["error"])
            raise DeviceError(f"arm: cannot connect to the UR controller at {host} within {cfg.connect_timeout_s} s "
                              f"({why}); check the address (hardware.ur5e.host), that the robot is on and in "
                              "remote control, and that ports 29999/30003/30004 are reachable")
        self._recv, self._ctrl = result["recv"], result["ctrl"]
        self._controller_clock.reset()  # a restarted controller starts its clock afresh
        self._link_error = None
        self._last_seq = None
        try:
            self._set_tool()
        except Exception as exc:
            self._close_clients()
            raise DeviceError(f"arm: connected to {host} but {exc}") from exc
        self._last_rx_ns = time.monotonic_ns()  # the receive thread starts now: no stall before it
        try:
            self._read_state()
        except Exception as exc:
            self._close_clients()
            raise DeviceError(f"arm: connected to {host} but cannot read its state ({exc})") from exc
        self._stop_evt.clear()
        self._thread = threading.Thread(target=self._receive_loop, name="ur5e-receive", daemon=True)
        self._thread.start()

    def _disconnect(self) -> None:
        self._cancel_torsion()
        self._stop_evt.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close_clients()

    def _stalled(self) -> bool:
        """The controller stopped sending (connections open): calls that wait for its answer hang."""
        last = self._last_rx_ns
        return last is not None and time.monotonic_ns() - last > self.cfg.stall_timeout_s * 1e9

    def _close_clients(self) -> None:
        stalled = self._stalled()
        locked = self._io.acquire(timeout=2.0)  # a call stuck on a hung controller may hold it
        try:
            ctrl, recv = self._ctrl, self._recv
            self._ctrl = self._recv = None
        finally:
            if locked:
                self._io.release()

        if not stalled:
            with self._io:
                if ctrl is not None:
                    _quiet(ctrl.stopScript)
                # ur_rtde's disconnect ends with a fixed 0.5 s sleep in each client, with the GIL
                # released: both at once. Its destructor disconnects (and sleeps) again, holding the
                # GIL: the clients are kept (_CLOSED) so that happens at the process's exit, not
                # while the run closes its other devices (SIGTERM allows a second in all).
                closing = [threading.Thread(target=_quiet, args=(c.disconnect,), name="ur5e-close", daemon=True)
                           for c in (ctrl, recv) if c is not None]
                for t in closing:
                    t.start()
                for t in closing:
                    t.join(timeout=5.0)
                _CLOSED.extend(c for c in (ctrl, recv) if c is not None)
            return
        # A hung controller: ur_rtde's clients loop reconnecting, and disconnecting or destroying
        # a client whose threads still run calls std::terminate (the process would abort after
        # the session was closed). So they are left as they are and kept alive (never destroyed)
        # for the rest of the process; the operator restarts the controller.
        for c in (ctrl, recv):
            if c is not None:
                _ABANDONED.append(c)
                ctypes.pythonapi.Py_IncRef(ctypes.py_object(c))
        log.warning("ur5e: the controller stopped answering; its client connections were abandoned")

    def restart_program(self) -> None:
        """Upload and start the control script again (after an operator unlocked a protective stop)."""
        self._require_connected()
        with self._io:
            if not self._ctrl.reuploadScript():
                raise DeviceError("arm: the controller did not restart the control script; check the pendant")
            # reuploadScript returns once the program is sent, before the controller runs it.
            deadline = time.monotonic() + self.cfg.connect_timeout_s
            while not self._ctrl.isProgramRunning():
                if time.monotonic() > deadline:
                    raise DeviceError(f"arm: the control script did not start within {self.cfg.connect_timeout_s} s "
                                      "(hardware.ur5e.connect_timeout_s); check the pendant")
                time.sleep(0.005)
            try:
                self._set_tool()
            except DeviceError as exc:
                raise DeviceError(f"arm: {exc}") from exc

    def _set_tool(self) -> None:
        """Set the gripper's TCP offset and payload (hardware.ur5e.tcp_offset_m_rad, payload_*) in the
        control script just started (a program starts from the installation's), and read the TCP
        back: poses and moves refer to that TCP, so a controller that did not take it is an error."""
        cfg = self.cfg
        tcp = [float(x) for x in cfg.tcp_offset_m_rad]
        with self._io:
            if not self._ctrl.setTcp(tcp):
                raise DeviceError("the controller refused the TCP offset (hardware.ur5e.tcp_offset_m_rad)")
            if not self._ctrl.setPayload(float(cfg.payload_kg), [float(x) for x in cfg.payload_cog_m]):
                raise DeviceError("the controller refused the payload (hardware.ur5e.payload_kg, payload_cog_m)")
            got = np.asarray(self._ctrl.getTCPOffset(), float)
        if got.shape != (6,) or not np.allclose(got, tcp, atol=1e-9):
            raise DeviceError(f"the controller reports TCP offset {got.tolist()}, not the one set {tcp} "
                              "(hardware.ur5e.tcp_offset_m_rad)")

    # ---- receive thread ---------------------------------------------------------------------------
    def _read_state(self) -> float:
        r = self._recv
        ts = r.getTimestamp()
        self._controller_clock.observe(int(round(ts * 1e9)), time.monotonic_ns())
        self._pose6 = np.asarray(r.getActualTCPPose(), float)
        self._safety_bits = int(r.getSafetyStatusBits())
        self._runtime_state = int(r.getRuntimeState())
        return ts

    def _async_word(self) -> int:
        """The control script's asynchronous-status register (the receive client refuses to read
        registers 0..11, the control client's cache has it)."""
        with self._io:
            return int(self._ctrl.getAsyncOperationProgressEx().value())

    def _receive_loop(self) -> None:
        last_ts = None
        next_check = 0.0
        while not self._stop_evt.wait(self.cfg.poll_period_s):
            if self._link_error is not None:
                self._try_reconnect()
                continue
            try:
                now = time.monotonic()
                if now >= next_check:  # the clients notice a closed socket in their own threads
                    next_check = now + 0.01
                    if not (self._recv.isConnected() and self._ctrl.isConnected()):
                        raise ConnectionError("the controller closed the connection")
                ts = self._recv.getTimestamp()
                if ts == last_ts:
                    continue
                host_ns = time.monotonic_ns()
                ts = self._read_state()
            except Exception as exc:  # noqa: BLE001 - any client failure is a lost link
                self._link_lost(str(exc) or type(exc).__name__)
                continue
            last_ts = ts
            seq = int(round(ts / CONTROLLER_PERIOD_S))
            if self._last_seq is not None and seq > self._last_seq + 1:
                log.debug("ur5e: %d RTDE packages not seen by the poll", seq - self._last_seq - 1)
            self.health.observe_seq(self._last_seq, seq)
            self._last_seq = seq
            p = self._pose6
            pose = Pose(p[:3].copy(), Rotation.from_rotvec(p[3:]).as_quat(), "base", int(round(ts * 1e9)), host_ns, seq)
            with self._buf_lock:
                self._buf.append(pose)
            self._last_rx_ns = host_ns

    def _link_lost(self, why: str) -> None:
        if self._link_error is None:
            log.warning("ur5e: link to %s lost (%s); reconnecting", self.cfg.host, why)
            self._link_error = why
            self._torsion_cancel.set()
            self._move_kind = None  # a move in progress is not resumed after the link returns
            # The control client reconnects by itself from its receive thread when it can; give it
            # one interval before reconnecting whatever is still down.
            self._next_reconnect = time.monotonic() + self.cfg.reconnect_interval_s

    def _try_reconnect(self) -> None:
        """Replace both clients with new ones. Not RTDEControlInterface.reconnect(): in ur_rtde
        1.6.5 the control client's receive thread, once it has lost the link, keeps reconnecting
        on every loop turn (its should_reconnect flag is never cleared), so the old client is shut
        down (disconnect() ends that thread) and a new one uploads the control script again."""
        if time.monotonic() < self._next_reconnect:
            return
        self._next_reconnect = time.monotonic() + self.cfg.reconnect_interval_s
        import rtde_control
        import rtde_receive

        with self._io:
            old, self._ctrl = self._ctrl, None
            if old is not None:
                _quiet(old.disconnect)
            if self._recv is not None:
                _quiet(self._recv.disconnect)
            try:
                self._recv = rtde_receive.RTDEReceiveInterface(self.cfg.host, self.cfg.rtde_frequency_hz)
                self._controller_clock.reset()
                _require_streaming(self._recv)
                self._ctrl = rtde_control.RTDEControlInterface(self.cfg.host)
                self._read_state()
                self._set_tool()
            except Exception as exc:  # noqa: BLE001 - try again after the interval
                log.info("ur5e: reconnect to %s failed (%s)", self.cfg.host, exc)
                return
        self.health.reconnects += 1
        self._last_rx_ns = time.monotonic_ns()
        self._link_error = None
        log.warning("ur5e: reconnected to %s", self.cfg.host)

    # ---- state ---------------------------------------------------------------------------------------
    def read_available(self) -> list[Pose]:
        with self._buf_lock:
            out = list(self._buf)
            self._buf.clear()
        return out

    def tcp_pose6(self) -> np.ndarray:
        self._require_connected()
        return self._pose6.copy()

    def fault(self, now_ns: int) -> str | None:
        if not self._connected:
            return None
        if self._link_error is not None:
            return f"arm: link lost ({self._link_error}); reconnecting to {self.cfg.host}"
        if self._safety_bits & SAFETY_EMERGENCY_STOPPED:
            return "arm: emergency stop (release the e-stop, then restart the program)"
        if self._safety_bits & SAFETY_BIT_PROTECTIVE_STOPPED:
            return "arm: protective stop; inspect the cause, unlock it on the pendant, then restart_program()"
        if self._runtime_state != RUNTIME_PLAYING:
            name = RUNTIME_NAMES.get(self._runtime_state, str(self._runtime_state))
            return f"arm: control program not running (runtime state {name})"
        bound_ns = self.cfg.stall_timeout_s * 1e9
        if (self._controller_clock.silent_ns(now_ns) or 0) > bound_ns:
            self._ask_timestamp()  # packages the receive thread has not been scheduled to poll yet
            silent_ns = self._controller_clock.silent_ns(now_ns)
            if silent_ns is not None and silent_ns > bound_ns:
                return (f"arm stalled: no RTDE sample for {silent_ns / 1e6:.0f} ms (controller time of the newest "
                        f"package {self._controller_clock.newest_device_ns / 1e9:.3f} s)")
        return None

    def _ask_timestamp(self) -> None:
        """The newest controller timestamp in the receive client's cache (a read of what ur_rtde's
        own receive thread stored; it never waits on the controller)."""
        recv = self._recv
        if recv is None:
            return
        try:
            ts = recv.getTimestamp()
        except Exception:  # noqa: BLE001 - a lost link is the receive thread's to report
            return
        self._controller_clock.observe(int(round(ts * 1e9)), time.monotonic_ns())

    def is_moving(self) -> bool:
        self._require_connected()
        kind = self._move_kind
        if kind is None:
            return False
        if self._safety_bits & (SAFETY_BIT_PROTECTIVE_STOPPED | SAFETY_EMERGENCY_STOPPED) \
                or self._runtime_state != RUNTIME_PLAYING:
            self._move_kind = None  # the safety system stopped the arm; the script's registers froze
            return False
        if kind == "speedl":
            return self._torsion is not None and self._torsion.is_alive()
        running, op = async_status(self._async_word())
        if op == self._op_before:  # the controller has not started the operation yet
            if time.monotonic_ns() - self._op_sent_ns < self.cfg.start_timeout_s * 1e9:
                return True
            log.warning("ur5e: %s never showed up as running; taking the arm as stopped", kind)
            self._move_kind = None
            return False
        if not running:
            self._move_kind = None
        return running

    # ---- motion --------------------------------------------------------------------------------------
    def move_linear(self, pose6: np.ndarray, speed_m_s: float, accel_m_s2: float,
                    angular_speed_rad_s: float | None = None) -> None:
        self._require_connected()
        cfg = self.cfg
        pose6 = np.asarray(pose6, float).reshape(-1)
        if pose6.shape != (6,) or not np.all(np.isfinite(pose6)):
            raise DeviceError(f"arm: pose {pose6.tolist()} must be six finite values [x, y, z, rx, ry, rz]")
        if not 0 < speed_m_s <= cfg.max_speed_m_s:
            raise DeviceError(f"arm: speed {speed_m_s!r} m/s is outside (0, {cfg.max_speed_m_s}] "
                              "(hardware.ur5e.max_speed_m_s)")
        if not 0 < accel_m_s2 <= cfg.max_accel_m_s2:
            raise DeviceError(f"arm: acceleration {accel_m_s2!r} is outside (0, {cfg.max_accel_m_s2}]")
        if angular_speed_rad_s is not None and not 0 < angular_speed_rad_s <= cfg.max_angular_speed_rad_s:
            raise DeviceError(f"arm: angular speed {angular_speed_rad_s!r} rad/s is outside "
                              f"(0, {cfg.max_angular_speed_rad_s}] (hardware.ur5e.max_angular_speed_rad_s)")
        why = self.fault(time.monotonic_ns())
        if why is not None:
            raise DeviceError(f"{why}; not moving")
        self._cancel_torsion()
        here = self._pose6.copy()
        rel = Rotation.from_rotvec(pose6[3:]) * Rotation.from_rotvec(here[3:]).inv()
        angle = float(rel.magnitude())
        if angular_speed_rad_s is None or angle < 1e-6:
            self._send_async("movel", lambda c: c.moveL(pose6.tolist(), speed_m_s, accel_m_s2, True))
            return
        self._start_torsion(here, pose6, rel.as_rotvec() / angle, angle, speed_m_s, accel_m_s2,
                            float(angular_speed_rad_s))

    def _send_async(self, kind: str, call) -> None:
        with self._io:
            self._op_before = async_status(self._async_word())[1]
            self._op_sent_ns = time.monotonic_ns()
            self._move_kind = kind
            ok = call(self._ctrl)
        if not ok:
            self._move_kind = None
            raise DeviceError(f"arm: the controller refused {kind} ({self.fault(time.monotonic_ns()) or 'no reason given'})")

    def _start_torsion(self, here, target, axis, angle, speed_m_s, alpha, omega) -> None:
        d = target[:3] - here[:3]
        duration = max(angle / omega, float(np.linalg.norm(d)) / speed_m_s)
        omega = angle / duration
        twist = np.concatenate((d / duration, axis * omega)).tolist()
        self._torsion_cancel.clear()
        self._move_kind = "speedl"
        t = threading.Thread(target=self._run_torsion, args=(here, axis, angle, twist, omega, alpha),
                             name="ur5e-torsion", daemon=True)
        self._torsion = t
        t.start()

    def _run_torsion(self, start, axis, angle, twist, omega, alpha) -> None:
        """speedL at the twist until one braking distance before the target, then a zero twist
        (decelerate at alpha), then speedStop once the tool is at rest."""
        r0 = Rotation.from_rotvec(start[3:])
        brake = omega * omega / (2.0 * alpha) + 2.0 * omega * self.cfg.poll_period_s
        try:
            with self._io:
                if not self._ctrl.speedL(twist, alpha, 0.0):
                    log.warning("ur5e: the controller refused speedL")
                    return
            while not self._torsion_cancel.wait(self.cfg.poll_period_s):
                turned = float(np.dot((Rotation.from_rotvec(self._pose6[3:]) * r0.inv()).as_rotvec(), axis))
                if angle - turned <= brake:
                    break
            if self._torsion_cancel.is_set():
                return
            with self._io:
                self._ctrl.speedL([0.0] * 6, alpha, 0.0)
            rest_by = time.monotonic() + omega / alpha + 0.2
            last = self._pose6.copy()
            while time.monotonic() < rest_by and not self._torsion_cancel.wait(0.02):
                now = self._pose6.copy()
                if np.abs(now - last).max() < 1e-7:
                    break
                last = now
            with self._io:
                self._ctrl.speedStop(self.cfg.stop_decel_m_s2)
        except Exception as exc:  # noqa: BLE001 - the receive thread reports the link
            log.warning("ur5e: torsion move ended by an error: %s", exc)

    def _cancel_torsion(self) -> None:
        t = self._torsion
        if t is not None:
            self._torsion_cancel.set()
            if t is not threading.current_thread():
                t.join(timeout=1.0)
            self._torsion = None

    def stop(self) -> None:
        """Decelerate now at stop_decel; safe from any thread, returns after the command handshake."""
        self._require_connected()
        kind = self._move_kind
        self._torsion_cancel.set()
        if self._stalled():  # the controller stopped answering: a stop that waits for it would hang
            log.warning("ur5e: stop not sent, the controller stopped answering (its own safety must hold it)")
            return
        try:
            with self._io:
                if self._link_error is not None:
                    return  # nothing can reach the robot until the link is back
                if kind == "speedl":
                    self._ctrl.speedStop(self.cfg.stop_decel_m_s2)
                    self._move_kind = None
                else:
                    self._op_before = async_status(self._async_word())[1]
                    self._op_sent_ns = time.monotonic_ns()
                    self._move_kind = "stopl"  # ur_rtde's stopL returns nothing; is_moving() watches
                    self._ctrl.stopL(self.cfg.stop_decel_m_s2, True)
        except Exception as exc:  # noqa: BLE001 - stop must never raise into a guard's thread
            log.warning("ur5e: stop failed: %s", exc)


def _quiet(call) -> None:
    try:
        call()
    except Exception:  # noqa: BLE001 - best effort on the way out
        pass
