"""The skin readout board: serial frame protocol, driver, and a pty emulator backed by the simulated world."""

from hardware.skin_board.config import SkinBoardConfig
from hardware.skin_board.driver import SkinBoardReader
from hardware.skin_board.emulator import EMULATOR_SETUP, SkinBoardEmulator
from hardware.skin_board.wire import FrameParser, WireFrame, encode_frame

__all__ = ["EMULATOR_SETUP", "FrameParser", "SkinBoardConfig", "SkinBoardEmulator", "SkinBoardReader", "WireFrame",
           "encode_frame"]
