"""Configuration of the UR5e driver (ur_rtde over the robot's network interface)."""

from __future__ import annotations

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
