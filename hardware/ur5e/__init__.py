"""UR5e arm: driver over ur_rtde (RTDE + dashboard + control script) and a loopback emulator."""

from hardware.ur5e.config import UR5eConfig
from hardware.ur5e.driver import UR5eArm

__all__ = ["UR5eArm", "UR5eConfig"]
