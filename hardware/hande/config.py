"""Configuration of the Robotiq Hand-E driver (URCap socket on the UR controller)."""

from __future__ import annotations

from dataclasses import dataclass

from hardware.hande.wire import Calibration
from layerskin_exp.config import require


@dataclass
class HandEConfig:
    """Robotiq Hand-E through the Robotiq URCap's socket service (TCP 63352 on the UR controller).

    open_count/closed_count: the POS counts at full opening and fully closed (the gripper's
    auto-calibration; nominal 0/255). stall_timeout_s bounds the time without any reply from the
    socket while polling; poll_rate_hz polls POS, OBJ, PRE, STA, FLT and GTO (six round trips each).
    """

    host: str = "192.168.1.10"
    port: int = 63352
    connect_timeout_s: float = 2.0
    reply_timeout_s: float = 0.5  # one request's reply; longer -> link lost
    stall_timeout_s: float = 0.05
    poll_rate_hz: float = 50.0
    activation_timeout_s: float = 5.0  # SET ACT 1 until STA == 3 (a real Hand-E takes a few s)
    stroke_mm: float = 50.0
    open_count: int = 0
    closed_count: int = 255
    min_speed_mm_s: float = 20.0
    max_speed_mm_s: float = 150.0

    def __post_init__(self) -> None:
        k = "hardware.hande"
        require(bool(self.host), f"{k}.host", self.host, "must name the UR controller running the URCap")
        require(0 < self.port < 65536, f"{k}.port", self.port, "must be 1..65535 (the URCap listens on 63352)")
        require(0 < self.connect_timeout_s <= 60, f"{k}.connect_timeout_s", self.connect_timeout_s, "must be 0..60 s")
        require(0 < self.reply_timeout_s <= 10, f"{k}.reply_timeout_s", self.reply_timeout_s, "must be 0..10 s")
        require(0 < self.stall_timeout_s <= 0.05, f"{k}.stall_timeout_s", self.stall_timeout_s,
                "must be > 0 and <= 0.05 s")
        require(1 <= self.poll_rate_hz <= 500 and 1.0 / self.poll_rate_hz < self.stall_timeout_s,
                f"{k}.poll_rate_hz", self.poll_rate_hz,
                "must be 1..500 Hz with a poll period shorter than stall_timeout_s")
        require(0 < self.activation_timeout_s <= 60, f"{k}.activation_timeout_s", self.activation_timeout_s,
                "must be 0..60 s")
        require(self.stroke_mm > 0, f"{k}.stroke_mm", self.stroke_mm, "must be > 0 (Hand-E: 50 mm)")
        require(0 <= self.open_count <= 255 and 0 <= self.closed_count <= 255 and self.open_count < self.closed_count,
                f"{k}.open_count", (self.open_count, self.closed_count),
                "open_count and closed_count must be 0..255 with open_count < closed_count")
        require(0 < self.min_speed_mm_s < self.max_speed_mm_s, f"{k}.min_speed_mm_s",
                (self.min_speed_mm_s, self.max_speed_mm_s), "must satisfy 0 < min_speed_mm_s < max_speed_mm_s")

    @property
    def calibration(self) -> Calibration:
        return Calibration(self.stroke_mm, self.open_count, self.closed_count, self.min_speed_mm_s,
                           self.max_speed_mm_s)
