"""ATI Mini40 behind a Net F/T box: RDT over UDP (driver), its loopback emulator, the wire format."""

from hardware.netft.config import NetFTConfig
from hardware.netft.driver import NetFTSensor
from hardware.netft.emulator import EMULATOR_SETUP, NetFTEmulator
from hardware.netft.wire import Calibration

__all__ = ["EMULATOR_SETUP", "Calibration", "NetFTConfig", "NetFTEmulator", "NetFTSensor"]
