"""What the emulated controller runs in place of the `rtde_control` URScript that ur_rtde uploads.

The ur_rtde client (1.6.5) sends its control script to port 30003 and then drives it through
RTDE registers: a command number in `input_int_register_0`, arguments in
`input_int_register_1..` and `input_double_register_0..`; the script answers in
`output_int_register_0` (1 = ready for a command, 2 = done with it), `output_int_register_1`
(boolean results such as is_steady) and `output_int_register_2` (asynchronous operation status).
`ControlScript.tick()` is one 2 ms cycle of the script's main loop, written after the script the
client sends (captured in the tests):

    cmd = read_input_integer_reg(0)
    if cmd is a realtime command (speedl, servoj, ...): process it; signal_ready()
    elif cmd == 0: executing = False; signal_ready()
    elif not executing: process it (blocking commands finish first); executing = True
                        and signal_done_with_cmd() unless cmd == 255 (stop script)

Commands acted on: moveL (3, synchronous or asynchronous; above the safety limits it runs at them,
speed-scaled, see _limited), moveJ (1, likewise: see _joint_move), stopL (33) / stopJ (34), speedL (10),
servoL (24: the TCP follows the stream of poses, see _command_servo), speedStop (15), servoStop (16), isSteady (47), isPoseWithinSafetyLimits (36: the pose against the
safety planes, here the twin's workspace box; orientation is not limited), triggerProtectiveStop
(31: the controller's protective stop, which pauses the program before the command is done),
getInverseKinematics (30 with qnear, 46 without: the UR5e's closed-form IK, kinematics.py),
setPayload (17), setTcp (29), getTCPOffset (40), stop script (255). The TCP offset and payload belong to the running program (a new upload starts
from the installation's, here none); the controller reports the payload on RTDE. Commands that
only set state the emulator does not model (setWatchdog 35, force-mode damping 20 / gain 21) are
acknowledged like the script would without effect; any other command is acknowledged and
recorded in `unsupported` so a test can see the driver asked for something not emulated.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from hardware.ur5e import kinematics

log = logging.getLogger(__name__)

# Command numbers of the control script (ur_rtde 1.6.5, RTDE::RobotCommand::Type).
CMD_NONE = 0
CMD_MOVEJ = 1
CMD_MOVEL = 3
CMD_SPEEDL = 10
CMD_SPEED_STOP = 15
CMD_SERVO_STOP = 16
CMD_SET_PAYLOAD = 17
CMD_SERVOL = 24
CMD_SET_TCP = 29
CMD_GET_INVERSE_KINEMATICS = 30  # get_inverse_kin(x, qnear, maxPositionError, maxOrientationError)
CMD_PROTECTIVE_STOP = 31
CMD_STOPL = 33
CMD_STOPJ = 34
CMD_SET_WATCHDOG = 35
CMD_IS_POSE_WITHIN_SAFETY_LIMITS = 36
CMD_GET_TCP_OFFSET = 40
CMD_GET_INVERSE_KINEMATICS_DEFAULT = 46  # get_inverse_kin(x): nearest the current joint positions
CMD_IS_STEADY = 47
CMD_STOP_SCRIPT = 255
# Processed every cycle and answered with "ready", never "done" (the script's list).
REALTIME_CMDS = frozenset({24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71})
ACKNOWLEDGED_ONLY = frozenset({CMD_SET_WATCHDOG, 20, 21})

SIGNAL_READY = 1
SIGNAL_DONE = 2

# speedl runs until told otherwise, but the twin only takes targets: a twist becomes a move toward
# where it leads SPEED_HORIZON_S ahead (at most MAX_HORIZON_ANGLE_RAD of turn), renewed every
# quarter of that, so the arm never reaches it. Where the move would leave the workspace, the
# emulator's bridge ends it on the boundary (the controller's safety planes).
SPEED_HORIZON_S = 2.0
MAX_HORIZON_ANGLE_RAD = 1.0
CYCLE_S = 0.002
# What the controller process knows of the twin (sim.rig.arm): the workspace box (the safety
# planes) and the speed limits a servo stream is held to.
ARM_LIMITS = ("workspace_min_m", "workspace_max_m", "max_speed_m_s", "max_accel_m_s2", "max_angular_speed_rad_s")


class ArmAccess(Protocol):
    """The simulated arm as the script reaches it (the emulator takes the world lock);
    limits: the twin's ARM_LIMITS by name, or None."""

    limits: dict | None

    def move_linear(self, pose6: np.ndarray, speed_m_s: float, accel_m_s2: float,
                    angular_speed_rad_s: float | None, stop_at_workspace: bool = False) -> None: ...
    def stop(self) -> None: ...
    def is_moving(self) -> bool: ...
    def tcp_pose6(self) -> np.ndarray: ...
    def within_safety_limits(self, pose6: np.ndarray) -> bool: ...


class Registers:
    """The controller's general-purpose RTDE registers (48 int and 48 double each way)."""

    def __init__(self) -> None:
        self.input_int = [0] * 48
        self.input_double = [0.0] * 48
        self.output_int = [0] * 48
        self.output_double = [0.0] * 48


class ToolSettings:
    """What set_tcp / set_payload set: TCP offset from the flange [x, y, z, rx, ry, rz] (m, rad),
    payload mass (kg) and centre of gravity from the flange (m)."""

    def __init__(self) -> None:
        self.tcp_offset = [0.0] * 6
        self.payload_kg = 0.0
        self.payload_cog_m = [0.0, 0.0, 0.0]


class ControlScript:
    """One running instance of the uploaded control script.

    arm: access to the twin. regs: the shared registers. protective_stop: the controller's
    protective stop (URScript protective_stop()). Call tick() every 2 ms; `running` turns False
    once the script ends (stop-script command).
    """

    def __init__(self, arm: ArmAccess, regs: Registers, protective_stop: Callable[[], None] | None = None) -> None:
        self.arm, self.regs = arm, regs
        self._protective_stop = protective_stop
        self.running = True
        self.executing = False
        self.unsupported: list[int] = []
        self.commands: list[int] = []  # every command started, in order (tests read it)
        self._async_wr_count = 0
        self._async_op_id = 0
        self._move_active = False  # the script's move_thrd / stop_thrd
        self._speeding = False
        self._speed_twist = np.zeros(6)
        self._speed_accel = 0.5
        self._pending: Callable[[], bool] | None = None  # blocking command: done when it returns True
        self._speed_renew_in = 0  # cycles until a running speedl's target is renewed
        self._servo_target: np.ndarray | None = None  # the pose a servoL stream last gave
        self._last_twist: np.ndarray | None = None
        self.tool = ToolSettings()
        self.actual_q = [0.0] * 6  # what RTDE reports as actual_q (no joint space here: zeros)
        self.speed_fraction = 1.0  # the speed slider, set by the controller (applies to moves commanded after)
        # RTDE speed_scaling: how far the trajectory limiter slows the motion under way to keep it
        # within the safety limits (the twin's envelope), 1.0 when it does not; the slider is apart.
        self.speed_scaling = 1.0
        self._reset_async_progress()
        self._signal(SIGNAL_READY)

    # ---- the script's helpers ----------------------------------------------------------------
    def _signal(self, value: int) -> None:
        self.regs.output_int[0] = value

    def _write_async_progress(self, value: int) -> None:
        self._async_wr_count += 1
        if self._async_wr_count > 127:
            self._async_wr_count = 0
        if value == 0:
            self._async_op_id += 1
            if self._async_op_id > 127:
                self._async_op_id = 0
        reg = self._async_wr_count * 65536 + self._async_op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self.regs.output_int[2] = reg

    def _reset_async_progress(self) -> None:
        self._write_async_progress(-1)

    def _stop_async_move(self) -> None:
        if self._move_active:
            self._move_active = False
            self._write_async_progress(-1)

    def _pose_in(self, index: int = 0) -> np.ndarray:
        return np.asarray(self.regs.input_double[index:index + 6], float)

    # ---- main loop -----------------------------------------------------------------------------
    def tick(self) -> None:
        """One cycle of the main loop, plus the progress of what the script's threads run."""
        if not self.running:
            return
        if self._move_active and not self.arm.is_moving():
            self._move_active = False  # move_thread / stop_thread finished
            self._write_async_progress(-1)
        if self.speed_scaling != 1.0 and not self._speeding and not self.arm.is_moving():
            self.speed_scaling = 1.0  # the limited motion is over
        if self._speeding and self._last_twist is not None:
            self._speed_renew_in -= 1
            if self._speed_renew_in <= 0:
                self._command_twist(self._speed_twist, self._speed_accel)
        if self._pending is not None:
            if not self._pending():
                return  # a blocking command is still executing: no signal this cycle
            self._pending = None
            self._signal(SIGNAL_DONE)
            return
        cmd = int(self.regs.input_int[0])
        if cmd in REALTIME_CMDS:
            self._process(cmd)
            self._signal(SIGNAL_READY)
        elif cmd == CMD_NONE:
            self.executing = False
            self._signal(SIGNAL_READY)
        elif not self.executing:
            self.executing = True
            keep_running = self._process(cmd)
            if not keep_running:
                self.running = False
                log.info("ur5e emulator: control script terminated (stop script command)")
            elif self._pending is None:
                self._signal(SIGNAL_DONE)

    def halt(self) -> None:
        """The program was stopped or paused from outside (protective stop, dashboard stop)."""
        self._move_active = False
        self._speeding = False
        self._last_twist = None
        self._servo_target = None
        self._pending = None
        self.speed_scaling = 1.0

    # ---- commands -----------------------------------------------------------------------------
    def _process(self, cmd: int) -> bool:
        """Act on one command; False when the script must end."""
        if cmd != CMD_NONE and (not self.commands or self.commands[-1] != cmd or cmd not in REALTIME_CMDS):
            self.commands.append(cmd)
        r = self.regs
        if cmd in (CMD_MOVEL, CMD_MOVEJ):
            pose, v, a, is_async = self._pose_in(0), r.input_double[6], r.input_double[7], r.input_int[1]
            self._stop_async_move()
            self._servo_target = None
            f = self._slider()
            if cmd == CMD_MOVEL:
                self.arm.move_linear(pose, *self._limited(v * f, a * f * f), None)
            else:  # the registers hold joint angles q, joint speed and acceleration
                self.arm.move_linear(*self._joint_move(pose, v * f, a * f * f))
            if is_async == 1:
                self._move_active = True
                self._write_async_progress(0)
            else:
                self._pending = lambda: not self.arm.is_moving()
        elif cmd in (CMD_STOPL, CMD_STOPJ):
            is_async = r.input_int[1]
            self._stop_async_move()
            self._servo_target = None
            self.arm.stop()
            if is_async == 1:
                self._move_active = True  # stop_thread
                self._write_async_progress(0)
            else:
                self._pending = lambda: not self.arm.is_moving()
        elif cmd == CMD_SPEEDL:
            twist = np.asarray(r.input_double[0:6], float)
            self._speed_accel = float(r.input_double[6])
            if not self._speeding or not np.array_equal(twist, self._speed_twist):
                self._speed_twist = twist
                self._speeding = True
                self._command_twist(twist, self._speed_accel)
        elif cmd == CMD_SERVOL:  # servo_target = get_inverse_kin(pose), then servoj(q, t, lookahead, gain)
            pose = self._pose_in(0)
            if self._servo_target is None or not np.array_equal(pose, self._servo_target):
                self._servo_target = pose
                self._command_servo(pose, float(r.input_double[8]), float(r.input_double[9]))
        elif cmd in (CMD_SPEED_STOP, CMD_SERVO_STOP):
            self._servo_target = None
            self._speeding = False
            self._speed_twist = np.zeros(6)
            self.arm.stop()
            self._pending = lambda: not self.arm.is_moving()
        elif cmd == CMD_IS_STEADY:
            r.output_int[1] = 0 if self.arm.is_moving() else 1
        elif cmd == CMD_IS_POSE_WITHIN_SAFETY_LIMITS:  # is_within_safety_limits(pose)
            r.output_int[1] = 1 if self.arm.within_safety_limits(self._pose_in(0)) else 0
        elif cmd == CMD_SET_TCP:
            self.tool.tcp_offset = [float(x) for x in r.input_double[0:6]]
        elif cmd == CMD_SET_PAYLOAD:
            self.tool.payload_kg = float(r.input_double[0])
            cog = [float(x) for x in r.input_double[1:4]]
            if any(cog):  # all zero: the script keeps the current centre of gravity
                self.tool.payload_cog_m = cog
        elif cmd in (CMD_GET_INVERSE_KINEMATICS, CMD_GET_INVERSE_KINEMATICS_DEFAULT):
            # (the closed form is exact: maxPositionError / maxOrientationError have nothing to bound)
            near = r.input_double[6:12] if cmd == CMD_GET_INVERSE_KINEMATICS else self.actual_q
            r.output_double[0:6] = self._inverse_kinematics(self._pose_in(0), near).tolist()
        elif cmd == CMD_GET_TCP_OFFSET:
            r.output_double[0:6] = list(self.tool.tcp_offset)
        elif cmd == CMD_PROTECTIVE_STOP and self._protective_stop is not None:
            # protective_stop() stops the arm and pauses the program there: the command's done
            # signal comes only if the program is resumed (the client sees the script not running)
            self._protective_stop()
            self._pending = lambda: True
        elif cmd == CMD_STOP_SCRIPT:
            log.info("ur5e emulator: Received stop script!")
            return False
        elif cmd in ACKNOWLEDGED_ONLY:
            pass
        else:
            self.unsupported.append(cmd)
            log.warning("ur5e emulator: control script command %d is not emulated (acknowledged only)", cmd)
        return True

    def _inverse_kinematics(self, tcp_pose6: np.ndarray, q_near) -> np.ndarray:
        """get_inverse_kin for the active TCP: the flange pose is the TCP pose less the TCP
        offset. Unreachable: kinematics.NoSolution, a runtime error that ends the program as
        URControl's "inverse kinematics" error does."""
        flange = (kinematics.pose6_to_matrix(tcp_pose6)
                  @ np.linalg.inv(kinematics.pose6_to_matrix(self.tool.tcp_offset)))
        return kinematics.inverse(kinematics.matrix_to_pose6(flange), q_near)

    def _joint_move(self, q, speed_rad_s: float, accel_rad_s2: float):
        """moveJ(q) for a twin without joints: a straight move of the TCP to where q puts it
        (forward kinematics, active TCP), timed like the joint move (the joint that turns
        furthest at speed_rad_s) within the twin's limits; the path between is straight, not the
        joint-interpolated arc. Returns move_linear's (pose6, speed, accel, angular speed)."""
        q = np.asarray(q, float)
        t_tcp = kinematics.forward(q) @ kinematics.pose6_to_matrix(self.tool.tcp_offset)
        target = kinematics.matrix_to_pose6(t_tcp)
        here = np.asarray(self.arm.tcp_pose6(), float)
        flange_here = kinematics.pose6_to_matrix(here) @ np.linalg.inv(kinematics.pose6_to_matrix(self.tool.tcp_offset))
        try:
            q_here = kinematics.inverse(kinematics.matrix_to_pose6(flange_here), q)
        except kinematics.NoSolution:
            q_here = q  # (a pose the arm cannot be in: time the move by the TCP alone)
        lead = float(np.max(np.abs(q - q_here)))
        dist = float(np.linalg.norm(target[:3] - here[:3]))
        turn = (Rotation.from_rotvec(target[3:]) * Rotation.from_rotvec(here[3:]).inv()).magnitude()
        lim = self.arm.limits or {}
        if lead < 1e-9:
            scale_m, scale_rad = 1.0, 1.0
        else:
            scale_m, scale_rad = dist / lead, turn / lead  # TCP metres / radians per joint radian
        v = min(max(speed_rad_s * scale_m, 1e-4), lim.get("max_speed_m_s", np.inf))
        a = min(max(accel_rad_s2 * scale_m, 1e-3), lim.get("max_accel_m_s2", np.inf))
        w = None if turn < 1e-9 else min(max(speed_rad_s * scale_rad, 1e-4), lim.get("max_angular_speed_rad_s", np.inf))
        return target, v, a, w

    def _limited(self, speed_m_s: float, accel_m_s2: float) -> tuple[float, float]:
        """A move's speed and acceleration within the safety limits (the twin's envelope, ARM_LIMITS),
        as the controller's trajectory limiter runs a move asked above them: held at the limit
        and reported as speed scaling, the program going on (UR user manual: "the speed of the
        robot arm is automatically adjusted in order to not exceed" the limits; e-Series: "the
        robot controller prevents violations by making a robot stop or by reducing the speed").
        A stop (category 0) comes only where the arm itself exceeds a limit, which a planned move
        here never does."""
        lim = self.arm.limits or {}
        v = min(speed_m_s, lim.get("max_speed_m_s", np.inf))
        a = min(accel_m_s2, lim.get("max_accel_m_s2", np.inf))
        self.speed_scaling = v / speed_m_s if speed_m_s > 0 else 1.0
        return v, a

    def _slider(self) -> float:
        # Time scaling by the speed slider: speeds scale by f, accelerations by f^2; kept above
        # what the twin accepts (a slider at 0 holds the arm on the real controller).
        return min(max(float(self.speed_fraction), 1e-3), 1.0)

    def _command_twist(self, twist: np.ndarray, accel: float) -> None:
        """speedl(twist, a): TCP velocity [vx, vy, vz, wx, wy, wz] (m/s, rad/s, base frame).

        The twin takes targets, so a twist becomes a linear move toward where the twist leads
        SPEED_HORIZON_S ahead, renewed before it gets there (see SPEED_HORIZON_S); a zero twist
        decelerates at `accel` to rest, i.e. a move to the point where that deceleration stops the
        current motion.
        """
        here = np.asarray(self.arm.tcp_pose6(), float)
        f = self._slider()
        v, w = twist[:3] * f, twist[3:] * f
        accel = accel * f * f
        speed, ang = float(np.linalg.norm(v)), float(np.linalg.norm(w))
        # The trajectory limiter: a twist above the safety limits runs at them, in its direction.
        lim = self.arm.limits or {}
        v_max, w_max = lim.get("max_speed_m_s", np.inf), lim.get("max_angular_speed_rad_s", np.inf)
        s = min(1.0, v_max / speed if speed > 0 else 1.0, w_max / ang if ang > 0 else 1.0)
        if s < 1.0:
            v, w, speed, ang = v * s, w * s, min(speed * s, v_max), min(ang * s, w_max)
        accel = min(accel, lim.get("max_accel_m_s2", np.inf))
        self.speed_scaling = s
        if speed == 0.0 and ang == 0.0:
            self._decelerate(here, accel)
            return
        horizon_s = SPEED_HORIZON_S if ang == 0.0 else min(SPEED_HORIZON_S, MAX_HORIZON_ANGLE_RAD / ang)
        self._speed_renew_in = max(1, int(horizon_s / 4.0 / CYCLE_S))
        self._last_twist = np.concatenate((v, w))
        target = _advance(here, v, w, horizon_s)
        self.arm.move_linear(target, max(speed, 1e-4), max(accel, 1e-3), ang if ang > 0 else None,
                             stop_at_workspace=True)

    def _command_servo(self, pose6: np.ndarray, t_s: float, lookahead_s: float) -> None:
        """servoj follows its target with a lag of about lookahead_time (its smoothing), each
        target reached over at least t. The twin takes targets: it moves toward each new one at
        the speed that covers the distance in that time, within the arm's limits; a stream that
        leads out of the workspace stops on its boundary (the safety planes), as speedL does."""
        here = np.asarray(self.arm.tcp_pose6(), float)
        horizon_s = max(t_s, lookahead_s, CYCLE_S)
        lim = self.arm.limits or {}
        dist = float(np.linalg.norm(pose6[:3] - here[:3]))
        turn = (Rotation.from_rotvec(pose6[3:]) * Rotation.from_rotvec(here[3:]).inv()).magnitude()
        v = min(max(dist / horizon_s, 1e-4), lim.get("max_speed_m_s", np.inf))
        w = None if turn < 1e-9 else min(max(turn / horizon_s, 1e-4), lim.get("max_angular_speed_rad_s", np.inf))
        self.arm.move_linear(pose6, v, lim.get("max_accel_m_s2", 1.5), w, stop_at_workspace=True)

    def _decelerate(self, here: np.ndarray, accel: float) -> None:
        last = self._last_twist
        self._last_twist = None
        if last is None or accel <= 0:
            self.arm.stop()
            return
        v, w = last[:3], last[3:]
        speed, ang = float(np.linalg.norm(v)), float(np.linalg.norm(w))
        # Time to stop at `accel` from the larger of the two (speedl's aRot defaults to a).
        t_stop = max(speed, ang) / accel
        target = _advance(here, v, w, t_stop / 2.0)  # distance of a linear ramp to zero
        self.arm.move_linear(target, max(speed, 1e-4), max(accel, 1e-3), ang if ang > 0 else None,
                             stop_at_workspace=True)


def _advance(pose6: np.ndarray, v: np.ndarray, w: np.ndarray, dt_s: float) -> np.ndarray:
    """The pose reached from pose6 moving at twist (v, w) for dt_s (w in the base frame)."""
    rot = Rotation.from_rotvec(w * dt_s) * Rotation.from_rotvec(pose6[3:])
    return np.concatenate((pose6[:3] + v * dt_s, rot.as_rotvec()))
