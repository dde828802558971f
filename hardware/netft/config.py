"""Configuration of the ATI Mini40 behind its Net F/T box (RDT over UDP)."""

from __future__ import annotations

from dataclasses import dataclass

from hardware.netft.wire import FORCE_UNITS_N, RDT_PORT, TORQUE_UNITS_NM
from layerskin_exp.config import require

K = "hardware.netft"


@dataclass
class NetFTConfig:
    """Where the Net F/T box is and how to turn its counts into N and N·m.

    fetch_calibration: read counts per unit and units from the box's http://host:http_port/netftapi2.xml
    at connect (the box knows its active calibration; a mismatched pair in the config would scale
    every force, the safety limit included). Otherwise counts_per_force / counts_per_torque and
    the units below are used (from the calibration sheet or the box's settings page).
    ft_sample_rate_hz: the box's internal sample rate, at which each record's ft_sequence counts;
    device time is estimated from it (see driver.py).
    """

    host: str = "192.168.1.1"
    port: int = RDT_PORT
    http_port: int = 80
    fetch_calibration: bool = True
    counts_per_force: float = 1_000_000.0
    counts_per_torque: float = 1_000_000.0
    force_unit: str = "N"
    torque_unit: str = "N-m"
    ft_sample_rate_hz: float = 7000.0
    connect_timeout_s: float = 2.0
    stall_timeout_s: float = 0.05

    def __post_init__(self) -> None:
        require(isinstance(self.host, str) and self.host.strip() != "", f"{K}.host", self.host,
                "must be the Net F/T box's host name or IP address")
        for k in ("port", "http_port"):
            v = getattr(self, k)
            require(isinstance(v, int) and 1 <= v <= 65535, f"{K}.{k}", v, "must be a UDP/TCP port 1..65535")
        require(self.counts_per_force > 0, f"{K}.counts_per_force", self.counts_per_force,
                "must be > 0 (cfgcpf on the box's calibration page)")
        require(self.counts_per_torque > 0, f"{K}.counts_per_torque", self.counts_per_torque,
                "must be > 0 (cfgcpt on the box's calibration page)")
        require(self.force_unit in FORCE_UNITS_N, f"{K}.force_unit", self.force_unit,
                f"one of {sorted(FORCE_UNITS_N)}")
        require(self.torque_unit in TORQUE_UNITS_NM, f"{K}.torque_unit", self.torque_unit,
                f"one of {sorted(TORQUE_UNITS_NM)}")
        require(0 < self.ft_sample_rate_hz <= 100_000, f"{K}.ft_sample_rate_hz", self.ft_sample_rate_hz,
                "must be 0..100000 Hz (7000 Hz on a Net F/T)")
        require(self.connect_timeout_s > 0, f"{K}.connect_timeout_s", self.connect_timeout_s, "must be > 0 s")
        require(0 < self.stall_timeout_s <= 0.05, f"{K}.stall_timeout_s", self.stall_timeout_s,
                "must be > 0 and <= 0.05 s (the F/T streams at 1 kHz and guards the 6 N limit)")
