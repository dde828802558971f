"""Robotiq Hand-E gripper through the Robotiq URCap's socket service (TCP 63352).

HandEGripper: the driver (hardware.interfaces.Gripper); HandEConfig: its settings;
hardware.hande.emulator.HandEEmulator: the URCap socket on loopback backed by the simulated gripper.
"""

from hardware.hande.config import HandEConfig
from hardware.hande.driver import HandEGripper

__all__ = ["HandEConfig", "HandEGripper"]
