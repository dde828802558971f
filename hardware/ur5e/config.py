"""Configuration of the UR5e driver (ur_rtde over the robot's network interface)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from layerskin_exp.config import require


@dataclass
class UR5eConfig:
    """Where the controller is and how the driver talks to it.

    host: the controller's address (PolyScope: Settings > System > Network); the ur_rtde client
    reaches the fixed ports 29999 (dashboard), 30004 (RTDE) and 30003 (script) there. The
    loopback emulator serves on its own 127.x.y.z address.
    """

    host: str = "192.168.1.10"
    rtde_frequency_hz: float = 500.0  # e-Series controllers stream at up to 500 Hz
    poll_period_s: float = 0.001  # how often the receive thread reads the client's latest state
    connect_timeout_s: float = 10.0  # dashboard + RTDE set-up + control script upload and start
    stall_timeout_s: float = 0.05
    reconnect_interval_s: float = 0.5
    stop_decel_m_s2: float = 2.0  # stop(): stopl / speed stop deceleration (m/s^2; rad/s^2 for rotation)
    max_speed_m_s: float = 0.25
    max_accel_m_s2: float = 1.5
    max_angular_speed_rad_s: float = 0.5
    start_timeout_s: float = 0.5  # an asynchronous move must show up in the status register within this
    # The Robotiq Hand-E on its I/O coupling, set by the driver on every control-script start
    # (set_tcp / set_payload) so poses, moves and the payload compensation refer to the gripper.
    # Source: robotiq_hande_description (URDF after Robotiq's drawings): coupling 11.0 mm,
    # gripper body 99.0 mm, fingertips 46.5 mm beyond the body; masses 0.119 kg (coupling with
    # bolts), 0.86387 kg (body, centred at half its height), 2 x 0.03804 kg (fingers at the body's top).
    tcp_offset_m_rad: tuple[float, float, float, float, float, float] = (0.0, 0.0, 0.1565, 0.0, 0.0, 0.0)
    payload_kg: float = 1.059
    payload_cog_m: tuple[float, float, float] = (0.0, 0.0, 0.058)

    def __post_init__(self) -> None:
        k = "hardware.ur5e"
        require(bool(self.host), f"{k}.host", self.host, "must name the controller's address")
        require(0 < self.rtde_frequency_hz <= 500, f"{k}.rtde_frequency_hz", self.rtde_frequency_hz,
                "RTDE streams at 1..500 Hz")
        require(0 < self.poll_period_s <= 0.01, f"{k}.poll_period_s", self.poll_period_s, "must be in (0, 0.01] s")
        require(self.connect_timeout_s > 0, f"{k}.connect_timeout_s", self.connect_timeout_s, "must be > 0 s")
        require(0 < self.stall_timeout_s <= 0.05, f"{k}.stall_timeout_s", self.stall_timeout_s,
                "must be in (0, 0.05] s")
        require(self.reconnect_interval_s > 0, f"{k}.reconnect_interval_s", self.reconnect_interval_s,
                "must be > 0 s")
        require(0 < self.stop_decel_m_s2 <= 15, f"{k}.stop_decel_m_s2", self.stop_decel_m_s2, "must be in (0, 15]")
        require(0 < self.max_speed_m_s <= 1.0, f"{k}.max_speed_m_s", self.max_speed_m_s, "must be in (0, 1] m/s")
        require(0 < self.max_accel_m_s2 <= 15, f"{k}.max_accel_m_s2", self.max_accel_m_s2, "must be in (0, 15]")
        require(0 < self.max_angular_speed_rad_s <= 3.14, f"{k}.max_angular_speed_rad_s",
                self.max_angular_speed_rad_s, "must be in (0, 3.14] rad/s")
        require(self.start_timeout_s > 0, f"{k}.start_timeout_s", self.start_timeout_s, "must be > 0 s")
        t = tuple(self.tcp_offset_m_rad)
        require(len(t) == 6 and all(math.isfinite(x) for x in t) and math.hypot(*t[:3]) <= 0.5
                and math.hypot(*t[3:]) <= math.pi, f"{k}.tcp_offset_m_rad", self.tcp_offset_m_rad,
                "six finite values [x, y, z (m), rx, ry, rz (rad)], within 0.5 m of the flange, turn <= pi")
        require(math.isfinite(self.payload_kg) and 0 <= self.payload_kg <= 5.0, f"{k}.payload_kg", self.payload_kg,
                "must be in [0, 5] kg (the UR5e's rated payload)")
        c = tuple(self.payload_cog_m)
        require(len(c) == 3 and all(math.isfinite(x) and abs(x) <= 0.5 for x in c), f"{k}.payload_cog_m",
                self.payload_cog_m, "three finite values, each within 0.5 m of the flange")
