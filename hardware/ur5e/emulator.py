"""Loopback UR5e: a controller process serving the ur_rtde client, moving the simulated arm.

    with UR5eEmulator(rt, host="127.0.0.2") as emu:      # rt: a started "gripper" RealtimeWorld
        arm = UR5eArm(UR5eConfig(host="127.0.0.2")); arm.connect()
        emu.protective_stop()                            # fault injection

The ur_rtde client reaches fixed ports (dashboard 29999, RTDE 30004, script 30003), so
instances are told apart by host: give each its own loopback address (127.0.0.2, 127.0.0.3, ...;
all of 127/8 is loopback on Linux). The controller itself runs in a child process
(`hardware.ur5e.controller`, which says why); this object starts it and runs the bridge thread
that, every 2 ms, hands it the twin's TCP pose (taken under `rt.lock`) and applies the moves and
stops the control script commands to `rt.rig.arm`. The pipe to that process is a
`hardware.emulation.DeviceProcess`: what this side sends is queued for its own sender thread, so
the bridge, which also reads what the controller sends back, never blocks in a send.
"""

from __future__ import annotations

import logging
import time

import numpy as np
from scipy.spatial.transform import Rotation

from hardware.emulation import DeviceProcess, Emulator
from hardware.interfaces import DeviceError
from hardware.ur5e import wire
from hardware.ur5e.control_script import ARM_LIMITS

log = logging.getLogger(__name__)

EMULATOR_SETUP = "gripper"

PERIOD_S = 0.002
START_TIMEOUT_S = 20.0


class UR5eEmulator(Emulator):
    """A UR5e controller on `host`, backed by `rt` (a started "gripper" RealtimeWorld).

    port: 0 or 30004 (the client knows no other RTDE port). Keyword options go to the controller
    (controller_version, polyscope_version, serial_number, remote_control).
    Faults (hardware.emulation's vocabulary): stall() / resume() (links stay open, no data flows),
    disconnect(refuse_s) (every client connection closes; see drop_connections); the arm's own:
    protective_stop(), emergency_stop(), unlock_protective_stop().
    """

    DEVICE = "ur5e"
    TWINS = ()  # the bridge reads the arm's pose directly
    FAULTS = ("stall", "disconnect")

    def __init__(self, rt, host: str = "127.0.0.2", port: int = 0, *, stall_after_s: float | None = None,
                 disconnect_after_s: float | None = None, **controller_options) -> None:
        if port not in (0, wire.PORT_RTDE):
            raise ValueError(f"port={port}: the ur_rtde client only reaches RTDE on {wire.PORT_RTDE}; "
                             "give each emulator its own loopback host instead")
        if controller_options:
            raise ValueError(f"unknown options {sorted(controller_options)}")
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        self.host = host
        self.info: dict = {}  # the controller's latest read-out (commands seen, runtime state, ...)
        self._controller: DeviceProcess | None = None
        self._applied_id = 0
        self._error: str | None = None

    # ---- life cycle ----------------------------------------------------------------------------
    def _open(self) -> str:
        """Start the controller process and the bridge; returns "host:30004" once it listens."""
        cfg = self.rt.rig.arm.cfg  # its workspace box stands for the controller's safety planes
        limits = {k: getattr(cfg, k) for k in ARM_LIMITS}
        opts = {"host": self.host, "t0_s": float(self.rt.world_time_s()), "limits": limits}
        self._controller = DeviceProcess("hardware.ur5e.controller", opts, self.DEVICE, log)
        try:
            return self._serve_device(self._controller, START_TIMEOUT_S)
        except DeviceError as exc:
            raise DeviceError(f"{exc} on {self.host}") from exc

    def _close(self) -> None:
        if self._controller is not None:
            self._controller.close()
            self._controller = None

    # ---- fault injection -------------------------------------------------------------------------
    def protective_stop(self) -> None:
        """The arm stops, safety mode PROTECTIVE_STOP, the control program pauses."""
        self._send(("fault", "protective_stop"))

    def emergency_stop(self) -> None:
        self._send(("fault", "emergency_stop"))

    def unlock_protective_stop(self) -> None:
        """Safety back to normal (what the pendant's unlock does); the program stays paused."""
        self._send(("fault", "unlock_protective_stop"))

    def _on_stall(self, stalled: bool) -> None:
        """Pause or resume the controller's data and wait until the controller process has taken
        it: a client that connects after stall() returns must find the output paused (a test that
        raced this left the ur_rtde control client looping for ever, holding the interpreter lock)."""
        self._send(("set", "output_paused", bool(stalled)))
        self.wait_info(lambda info: info.get("output_paused") == bool(stalled))

    def disconnect(self, refuse_s: float = 0.0) -> None:
        """Close every client connection (see drop_connections)."""
        self._require("disconnect")
        self.fault_counts["disconnect"] += 1
        self.drop_connections(refuse_s)

    def drop_connections(self, refuse_s: float = 0.0) -> None:
        """Close every client connection (a cable pulled); for refuse_s the ports also refuse new
        connections. The program keeps running. With refuse_s = 0 the ur_rtde 1.6.5 control
        client's own reconnect succeeds at once and then loops (see driver._try_reconnect)."""
        self._send(("fault", "drop_connections", float(refuse_s)))

    def pause_output(self, paused: bool) -> None:
        """stall() / resume() under the name tests/hardware/ur5e uses."""
        self.stall() if paused else self.resume()

    def wait_info(self, predicate, timeout_s: float = 5.0) -> dict:
        """Wait until predicate(info) holds (info: the controller's read-out); returns it."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            info = self.info
            if info and predicate(info):
                return info
            time.sleep(0.005)
        raise TimeoutError(f"ur5e emulator: condition not reached in {timeout_s} s; last read-out {self.info}")

    # ---- bridge ----------------------------------------------------------------------------------
    def _send(self, msg: tuple) -> None:
        """Queue msg for the controller process (never waits on the pipe)."""
        if self._controller is None:
            raise DeviceError("ur5e emulator: not started")
        self._controller.send(msg)

    def _bridge(self) -> None:
        controller = self._controller
        k, origin = 0, time.monotonic()
        try:
            while not self._stop.is_set():
                controller.poll(0.0, self._handle)
                if controller.error is None:  # (the controller listens once it has the first state)
                    with self.rt.lock:
                        arm = self.rt.rig.arm
                        pose = np.asarray(arm.tcp_pose6(), float).tolist()
                        speed = np.asarray(arm.tcp_speed6(), float).tolist()
                        moving = bool(arm.is_moving())
                        t_s = float(self.rt.world.t_s)
                    error, self._error = self._error, None
                    controller.send(("state", t_s, pose, moving, self._applied_id, error, speed))
                k += 1
                delay = origin + k * PERIOD_S - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                elif delay < -0.1:
                    k = int((time.monotonic() - origin) / PERIOD_S)
        except (EOFError, OSError) as exc:
            if not self._stop.is_set():
                log.warning("ur5e emulator: controller process went away (%s)", exc)
                controller.went_away(exc)

    def _handle(self, msg: tuple) -> None:
        """A message from the controller process (DeviceProcess.poll keeps "ready", "error" and
        "log" itself): a move or stop to apply, or its read-out."""
        kind, msg_id = msg[0], msg[1]
        if kind == "move":
            pose, v, a, w, stop_at_workspace = msg[2:]
            try:
                with self.rt.lock:
                    arm = self.rt.rig.arm
                    if stop_at_workspace:
                        pose = _stop_at_box(arm.tcp_pose6(), np.asarray(pose, float),
                                            arm.cfg.workspace_min_m, arm.cfg.workspace_max_m)
                    arm.move_linear(np.asarray(pose), v, a, w)
            except DeviceError as exc:
                self._error = str(exc)
                log.warning("ur5e emulator: %s", exc)
        elif kind == "stop":
            with self.rt.lock:
                self.rt.rig.arm.stop()
        elif kind == "info":
            self.info = msg[2]
        self._applied_id = max(self._applied_id, msg_id)


def _stop_at_box(here6: np.ndarray, target6: np.ndarray, lo, hi) -> np.ndarray:
    """target6 pulled back along the straight move from here6 to where that move leaves the box
    [lo, hi] (m), the turn shortened in proportion: where a speedl meets the workspace boundary,
    the arm stops on it, as at a UR safety plane."""
    p0, d = here6[:3], target6[:3] - here6[:3]
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    s = 1.0
    for i in range(3):
        if d[i] > 0:
            s = min(s, (hi[i] - p0[i]) / d[i])
        elif d[i] < 0:
            s = min(s, (lo[i] - p0[i]) / d[i])
    s = max(s, 0.0)
    if s >= 1.0:
        return target6
    log.info("ur5e emulator: speedl stops at the workspace boundary %s..%s m", lo.tolist(), hi.tolist())
    r0 = Rotation.from_rotvec(here6[3:])
    turn = (Rotation.from_rotvec(target6[3:]) * r0.inv()).as_rotvec()
    rot = Rotation.from_rotvec(s * turn) * r0
    return np.concatenate((np.clip(p0 + s * d, lo, hi), rot.as_rotvec()))
