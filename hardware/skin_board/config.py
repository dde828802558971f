"""Configuration of the skin readout board driver (the lab/loopback hardware node `skin_board`)."""

from __future__ import annotations

from dataclasses import dataclass

from layerskin_exp.config import require

KEY = "hardware.skin_board"


@dataclass
class SkinBoardConfig:
    """Where the readout board is and how the driver reads it.

    port: serial device path (the board enumerates as USB CDC, e.g. /dev/ttyACM0; on loopback the
    emulator's pty slave path). baud: ignored by native USB CDC, used if a UART bridge sits in
    between (it then has to carry ~3.4 Mbaud, see README.md). read_timeout_s: how long the receive
    thread blocks for the first byte of a read; bounds how fast disconnect() returns.
    ring_frames: frames kept for read_available() (oldest dropped, counted and logged, if the
    consumer falls that far behind: 8192 frames is ~19 s at 424 frame pairs/s).
    """

    port: str = "/dev/ttyACM0"
    baud: int = 2_000_000
    board_id: str = "fsr2x16-rev1"
    connect_timeout_s: float = 2.0
    stall_timeout_s: float = 0.05
    read_timeout_s: float = 0.01
    read_chunk_bytes: int = 65536
    ring_frames: int = 8192

    def __post_init__(self) -> None:
        require(isinstance(self.port, str) and self.port.strip() != "", f"{KEY}.port", self.port,
                "must name a serial device, e.g. /dev/ttyACM0")
        require(self.baud > 0, f"{KEY}.baud", self.baud, "must be > 0 baud")
        require(self.board_id.strip() != "", f"{KEY}.board_id", self.board_id, "must not be empty")
        require(self.connect_timeout_s > 0, f"{KEY}.connect_timeout_s", self.connect_timeout_s, "must be > 0 s")
        require(0 < self.stall_timeout_s <= 0.05, f"{KEY}.stall_timeout_s", self.stall_timeout_s,
                "must be > 0 and <= 0.05 s (a streaming device is stalled after 50 ms at most)")
        require(0 < self.read_timeout_s <= 0.1, f"{KEY}.read_timeout_s", self.read_timeout_s, "must be in (0, 0.1] s")
        require(self.read_chunk_bytes >= 1024, f"{KEY}.read_chunk_bytes", self.read_chunk_bytes,
                "must be >= 1024 bytes (more than one frame)")
        require(self.ring_frames >= 64, f"{KEY}.ring_frames", self.ring_frames, "must be >= 64 frames")
