"""A tiny closed-form rig for protocol tests: linear springs, a virtual clock, exact sample rates.

Independent of the simulated world, so the protocol logic (stop reasons, the per-sample force
guard, resume) is checked against numbers computable by hand: Fz = k_n * indentation,
shear = min(k_t * in-plane travel since contact, mu * Fz).
"""

from __future__ import annotations

import numpy as np

from hardware.interfaces import (
    Arm,
    Clock,
    DeviceError,
    ForceTorqueSensor,
    Gripper,
    Platform,
    SkinReader,
)
from hardware.rig import Rig
from layerskin_exp.types import GripperState, Pose, StagePosition, TwoLayerFrame, Wrench


class FakeClock(Clock):
    def __init__(self, world: FakeWorld) -> None:
        self.world = world

    def now_ns(self) -> int:
        return self.world.t_ns

    def sleep(self, dt_s: float) -> None:
        self.world.advance(dt_s)

    @property
    def is_virtual(self) -> bool:
        return True


class _Stream:
    def __init__(self) -> None:
        self.buffer: list = []

    def read_available(self) -> list:
        self._require_connected()
        out, self.buffer = self.buffer, []
        return out

    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass


class FakeSkin(_Stream, SkinReader):
    """Reports a stall like a real driver: nothing received for longer than stall_timeout_ns."""

    stall_timeout_ns = 40_000_000

    def __init__(self) -> None:
        SkinReader.__init__(self)
        _Stream.__init__(self)
        self.last_rx_ns: int | None = None

    def fault(self, now_ns: int) -> str | None:
        if self.last_rx_ns is not None and now_ns - self.last_rx_ns > self.stall_timeout_ns:
            return f"skin stalled: no frame for {(now_ns - self.last_rx_ns) / 1e6:.0f} ms"
        return None

    def calibration(self) -> dict:
        return {"fake": True}


class FakeFT(_Stream, ForceTorqueSensor):
    def __init__(self) -> None:
        ForceTorqueSensor.__init__(self)
        _Stream.__init__(self)

    def tare(self) -> None:
        pass


class FakePlatform(_Stream, Platform):
    def __init__(self) -> None:
        Platform.__init__(self)
        _Stream.__init__(self)
        self.pos_mm = np.array([0.0, 0.0, 1.0])
        self.target_mm = self.pos_mm.copy()
        self.speed_mm_s = 0.0
        self.stopped_at_ns: list[int] = []  # fake time of every stop() call
        self.clock_ns = lambda: 0
        # A stop takes effect this long after stop() (the bench's path: host, link, controller)
        self.stop_latency_ns = 0
        self._stop_due_ns: int | None = None

    def move_to(self, target_mm, speed_mm_s) -> None:
        self._require_connected()
        self.target_mm, self.speed_mm_s = np.asarray(target_mm, float).copy(), float(speed_mm_s)

    def stop(self) -> None:
        now = self.clock_ns()
        self.stopped_at_ns.append(now)
        if self.stop_latency_ns:
            if self._stop_due_ns is None:
                self._stop_due_ns = now + self.stop_latency_ns
            return
        self.target_mm = self.pos_mm.copy()

    def is_moving(self) -> bool:
        return bool(np.linalg.norm(self.target_mm - self.pos_mm) > 1e-9)

    def step(self, dt_s: float) -> None:
        if self._stop_due_ns is not None and self.clock_ns() >= self._stop_due_ns:
            self.target_mm, self._stop_due_ns = self.pos_mm.copy(), None
        d = self.target_mm - self.pos_mm
        n = np.linalg.norm(d)
        step = self.speed_mm_s * dt_s
        self.pos_mm = self.target_mm.copy() if n <= step else self.pos_mm + d / n * step


class FakeGripper(_Stream, Gripper):
    def __init__(self) -> None:
        Gripper.__init__(self)
        _Stream.__init__(self)
        self.opening_mm, self.target_mm, self.speed_mm_s = 50.0, 50.0, 0.0

    def move(self, opening_mm, speed_mm_s, force_pct) -> None:
        self.target_mm, self.speed_mm_s = float(opening_mm), float(speed_mm_s)

    def stop(self) -> None:
        self.target_mm = self.opening_mm

    def is_moving(self) -> bool:
        return abs(self.target_mm - self.opening_mm) > 1e-9

    def step(self, dt_s: float) -> None:
        d = self.target_mm - self.opening_mm
        self.opening_mm = self.target_mm if abs(d) <= self.speed_mm_s * dt_s else \
            self.opening_mm + np.sign(d) * self.speed_mm_s * dt_s


class FakeArm(_Stream, Arm):
    def __init__(self) -> None:
        Arm.__init__(self)
        _Stream.__init__(self)
        self.pose6 = np.array([0.4, 0.0, 0.3, 0.0, 0.0, 0.0])
        self.target6, self.t_left_s = self.pose6.copy(), 0.0
        self.from6 = self.pose6.copy()
        self.duration_s = 0.0

    def move_linear(self, pose6, speed_m_s, accel_m_s2, angular_speed_rad_s=None) -> None:
        pose6 = np.asarray(pose6, float)
        lin = np.linalg.norm(pose6[:3] - self.pose6[:3]) / speed_m_s
        ang = 0.0 if angular_speed_rad_s is None else np.linalg.norm(pose6[3:] - self.pose6[3:]) / angular_speed_rad_s
        self.from6, self.target6 = self.pose6.copy(), pose6
        self.duration_s = self.t_left_s = max(lin, ang)

    def stop(self) -> None:
        self.target6, self.t_left_s = self.pose6.copy(), 0.0

    def is_moving(self) -> bool:
        return self.t_left_s > 0

    def tcp_pose6(self) -> np.ndarray:
        return self.pose6.copy()

    def step(self, dt_s: float) -> None:
        if self.t_left_s > 0:
            self.t_left_s = max(0.0, self.t_left_s - dt_s)
            frac = 1 - self.t_left_s / self.duration_s if self.duration_s > 0 else 1.0
            self.pose6 = self.from6 + frac * (self.target6 - self.from6)


class FakeWorld:
    """Steps at the F/T rate; skin at skin_hz; stage/gripper/arm at 100 Hz."""

    def __init__(self, k_n_per_mm: float = 4.0, k_t_per_mm: float = 2.0, mu: float = 0.8,
                 ft_hz: float = 1000.0, skin_hz: float = 424.0, rod_contact_mm: float = 20.0,
                 fail_after_s: float | None = None, skin_stalls_after_s: float | None = None) -> None:
        self.k_n, self.k_t, self.mu = k_n_per_mm, k_t_per_mm, mu
        self.ft_dt_ns = int(1e9 / ft_hz)
        self.skin_dt_ns = int(1e9 / skin_hz)
        self.rod_contact_mm = rod_contact_mm
        self.fail_after_ns = None if fail_after_s is None else int(fail_after_s * 1e9)
        self.skin_stall_ns = None if skin_stalls_after_s is None else int(skin_stalls_after_s * 1e9)
        self.t_ns = 0
        self.rig: Rig | None = None
        self.contact_xy: np.ndarray | None = None
        self._next = {"ft": 0, "skin": 0, "slow": 0}
        self._seq = {"ft": 0, "skin": 0, "slow": 0}

    def force_n(self, pos_mm: np.ndarray) -> np.ndarray:
        depth = max(0.0, -pos_mm[2])
        if depth == 0:
            self.contact_xy = None
            return np.zeros(3)
        if self.contact_xy is None:
            self.contact_xy = pos_mm[:2].copy()
        fz = self.k_n * depth
        shear = self.k_t * (pos_mm[:2] - self.contact_xy)
        mag = np.linalg.norm(shear)
        if mag > self.mu * fz:  # slipping: the contact point follows
            shear *= self.mu * fz / mag
            self.contact_xy = pos_mm[:2] - shear / self.k_t
        return np.array([shear[0], shear[1], fz])

    def advance(self, dt_s: float) -> None:
        rig = self.rig
        end_ns = self.t_ns + int(round(dt_s * 1e9))
        while True:
            t_next = min(self._next.values())
            if t_next > end_ns:
                break
            step_s = (t_next - self.t_ns) / 1e9
            self.t_ns = t_next
            for dev in (rig.platform, rig.gripper, rig.arm):
                if dev is not None:
                    dev.step(step_s)
            if self.fail_after_ns is not None and self.t_ns > self.fail_after_ns:
                raise DeviceError("fake: device stopped answering")
            for kind in [k for k, v in self._next.items() if v == t_next]:
                self._emit(kind)
        self.t_ns = end_ns

    def _emit(self, kind: str) -> None:
        rig, t = self.rig, self.t_ns
        seq = self._seq[kind]
        self._seq[kind] += 1
        if kind == "ft":
            self._next[kind] += self.ft_dt_ns
            if rig.ft is not None:
                w = Wrench(self.force_n(rig.platform.pos_mm), np.zeros(3), seq, t, t)
                rig.ft.buffer.append(w)
                rig.check_guards(w)  # the backend's duty: every sample, as acquired
        elif kind == "skin":
            self._next[kind] += self.skin_dt_ns
            if rig.platform is not None:
                level = self.force_n(rig.platform.pos_mm)[2] * 10
            else:
                level = max(0.0, self.rod_contact_mm - rig.gripper.opening_mm) * 40
            layer = np.full((16, 16), min(4095, int(level)), np.uint16)
            if self.skin_stall_ns is not None and t > self.skin_stall_ns:
                return  # the board stopped sending
            frame = TwoLayerFrame(layer, layer.copy(), seq, t, t)
            rig.skin.buffer.append(frame)
            rig.skin.last_rx_ns = t
            rig.check_guards(frame, "skin")
        else:
            self._next[kind] += 10_000_000
            if rig.platform is not None:
                rig.platform.buffer.append(StagePosition(rig.platform.pos_mm.copy(), seq, t, t))
            if rig.gripper is not None:
                g = rig.gripper
                rig.gripper.buffer.append(GripperState(g.opening_mm, g.target_mm, 0, 0, False, 0, t, t, seq))
            if rig.arm is not None:
                rig.arm.buffer.append(Pose(rig.arm.pose6[:3].copy(), np.array([0, 0, 0, 1.0]), "tcp", t, t, seq))


def platform_rig(stop_latency_s: float = 0.0, **kw) -> Rig:
    world = FakeWorld(**kw)
    rig = Rig(backend="fake", clock=FakeClock(world), skin=FakeSkin(), ft=FakeFT(), platform=FakePlatform())
    rig.platform.clock_ns = lambda: world.t_ns
    rig.platform.stop_latency_ns = int(round(stop_latency_s * 1e9))
    world.rig = rig
    return rig


def gripper_rig(**kw) -> Rig:
    world = FakeWorld(**kw)
    rig = Rig(backend="fake", clock=FakeClock(world), skin=FakeSkin(), arm=FakeArm(), gripper=FakeGripper())
    world.rig = rig
    return rig
