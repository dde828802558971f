"""Wire protocol of the skin readout board: one fixed-size, CRC-checked frame per scan of both layers.

Pure code shared by the driver and the emulator (layout and rationale in README.md):

    offset  size  field
    0       4     sync  A5 5A 53 4B ("\\xa5\\x5aSK")
    4       1     version (1)
    5       1     flags (reserved, sent as 0, ignored by version-1 receivers)
    6       2     seq, u16 LE, +1 per frame, wraps 65535 -> 0
    8       4     device_t_us, u32 LE, board clock in µs, wraps every ~71.6 min
    12      768   superficial then deep, row-major, 512 values of 12 bits packed in pairs:
                  3 bytes = the 24-bit LE word v[2k] | v[2k+1] << 12
    780     4     CRC-32 (zlib/ISO-HDLC) of bytes 0..779, u32 LE

A frame is accepted only where the sync, the version and the CRC all match at one offset, so a
misaligned frame is never yielded. There is no length field: a corrupted length cannot make the
parser wait for, or swallow, more than one frame.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from layerskin_exp.rig import ADC_BITS, ADC_MAX, N_TAXELS

SYNC = b"\xa5\x5aSK"
VERSION = 1
N_VALUES = 2 * N_TAXELS * N_TAXELS  # both layers
HEADER = struct.Struct("<4sBBHI")  # sync, version, flags, seq, device_t_us
HEADER_LEN = HEADER.size  # 12
PAYLOAD_LEN = N_VALUES * 3 // 2  # 768
CRC_OFFSET = HEADER_LEN + PAYLOAD_LEN  # 780
FRAME_LEN = CRC_OFFSET + 4  # 784
SEQ_MOD = 1 << 16
TIME_MOD = 1 << 32

_CRC = struct.Struct("<I")
_FIELDS = struct.Struct("<BHI")  # flags, seq, device_t_us at offset 5


@dataclass(frozen=True, slots=True)
class WireFrame:
    """One frame as it travels: wire sequence number and board time still wrapped.

    superficial, deep: (16, 16) uint16 ADC counts 0..4095, [row, column].
    """

    seq: int  # 0..65535
    device_t_us: int  # 0..2**32 - 1
    superficial: np.ndarray
    deep: np.ndarray
    flags: int = 0


def pack_counts(superficial: np.ndarray, deep: np.ndarray) -> bytes:
    """The 768-byte payload: both (16, 16) layers of 12-bit counts, packed in pairs."""
    vals = np.concatenate([np.asarray(superficial).reshape(-1), np.asarray(deep).reshape(-1)])
    if vals.shape != (N_VALUES,):
        raise ValueError(f"superficial and deep must be ({N_TAXELS}, {N_TAXELS}) each; got "
                         f"{np.shape(superficial)} and {np.shape(deep)}")
    if vals.min() < 0 or vals.max() > ADC_MAX:
        raise ValueError(f"counts must be 0..{ADC_MAX} ({ADC_BITS}-bit ADC); got {vals.min()}..{vals.max()}")
    v = vals.astype(np.uint32)
    word = v[0::2] | (v[1::2] << 12)
    return np.stack([word & 0xFF, (word >> 8) & 0xFF, word >> 16], axis=1).astype(np.uint8).tobytes()


def unpack_counts(payloads: bytes | bytearray | memoryview, n: int) -> np.ndarray:
    """(n, 2, 16, 16) uint16 counts from n concatenated payloads (vectorised over all of them)."""
    raw = np.frombuffer(payloads, np.uint8, count=n * PAYLOAD_LEN).reshape(n, N_VALUES // 2, 3)
    lo, mid, hi = (raw[..., i].astype(np.uint16) for i in range(3))
    out = np.empty((n, N_VALUES // 2, 2), np.uint16)
    out[..., 0] = lo | ((mid & 0x0F) << 8)
    out[..., 1] = (mid >> 4) | (hi << 4)
    return out.reshape(n, 2, N_TAXELS, N_TAXELS)


def encode_frame(seq: int, device_t_us: int, superficial: np.ndarray, deep: np.ndarray, flags: int = 0) -> bytes:
    """The 784 bytes of one frame. seq and device_t_us are taken modulo their wire width."""
    head = HEADER.pack(SYNC, VERSION, flags & 0xFF, seq % SEQ_MOD, device_t_us % TIME_MOD)
    body = head + pack_counts(superficial, deep)
    return body + _CRC.pack(zlib.crc32(body))


class FrameParser:
    """Incremental parser: feed() whatever bytes arrived, get the complete valid frames back.

    Counters (cumulative):
      frames          frames accepted
      skipped_bytes   bytes discarded (not part of an accepted frame)
      crc_failures    candidates (sync + version at an offset) whose CRC did not match
      bad_version     candidates with the sync but another protocol version
      resyncs         times a frame was found again after alignment was lost
      corrupt         corruption events: each rejected candidate, plus each run of stray bytes
                      that starts where the stream had been aligned (one bit flip in a frame
                      counts once, not once per skipped byte). Bytes before the first good
                      frame (joining a stream mid-frame) are skipped but not counted as corrupt.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.frames = 0
        self.skipped_bytes = 0
        self.crc_failures = 0
        self.bad_version = 0
        self.resyncs = 0
        self.corrupt = 0
        self._synced = False  # a good frame has been seen
        self._lost = False  # alignment lost since the last good frame

    def reset(self) -> None:
        """Forget buffered bytes and the alignment (counters are kept), e.g. after reopening the port."""
        self._buf.clear()
        self._synced = False
        self._lost = False

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a frame (or of a sync word)."""
        return len(self._buf)

    def _skip(self, n: int) -> None:
        self.skipped_bytes += n
        if self._synced and not self._lost:
            self.corrupt += 1
        self._lost = True

    def _reject(self) -> None:
        self.skipped_bytes += 1  # the candidate's first byte; the search goes on after it
        if self._synced:
            self.corrupt += 1
        self._lost = True

    def feed(self, data: bytes | bytearray | memoryview) -> list[WireFrame]:
        """Frames completed by these bytes, oldest first."""
        buf = self._buf
        buf += data
        n = len(buf)
        view = memoryview(buf)
        starts: list[int] = []
        pos = 0
        try:
            while True:
                i = buf.find(SYNC, pos)
                if i < 0:
                    keep = max(pos, n - (len(SYNC) - 1))  # a sync word may be split across reads
                    if keep > pos:
                        self._skip(keep - pos)
                    pos = keep
                    break
                if i > pos:
                    self._skip(i - pos)
                    pos = i
                if n - i < FRAME_LEN:
                    break
                if buf[i + 4] != VERSION:
                    self.bad_version += 1
                    self._reject()
                    pos = i + 1
                    continue
                if zlib.crc32(view[i:i + CRC_OFFSET]) != _CRC.unpack_from(buf, i + CRC_OFFSET)[0]:
                    self.crc_failures += 1
                    self._reject()
                    pos = i + 1
                    continue
                if self._lost and self._synced:
                    self.resyncs += 1
                self._synced = True
                self._lost = False
                starts.append(i)
                pos = i + FRAME_LEN
            if not starts:
                return []
            fields = [_FIELDS.unpack_from(buf, s + 5) for s in starts]
            counts = unpack_counts(b"".join([view[s + HEADER_LEN:s + CRC_OFFSET] for s in starts]), len(starts))
        finally:
            view.release()
            del buf[:pos]
        self.frames += len(starts)
        return [WireFrame(seq, t_us, c[0], c[1], flags) for (flags, seq, t_us), c in zip(fields, counts, strict=True)]


class Unwrapper:
    """Turns the wrapping wire counters into monotonic ones, using the board time to count wraps.

    Board time (u32 µs) is unwrapped by the signed shortest step (valid while frames arrive
    within 35 min of each other). The sequence number (u16) is unwrapped to the value nearest
    to the one the elapsed board time predicts, so even a gap of more than 65 536 frames
    (154 s at 424 frame pairs/s) is counted right, and a repeated or older frame comes out as
    a duplicate or a step back rather than as 65 535 lost frames.
    """

    def __init__(self, frame_period_us: float) -> None:
        if not frame_period_us > 0:
            raise ValueError(f"frame_period_us={frame_period_us!r}: must be > 0")
        self.frame_period_us = float(frame_period_us)
        self.reset()

    def reset(self) -> None:
        self._raw: tuple[int, int] | None = None
        self.seq = 0
        self.t_us = 0

    def __call__(self, seq: int, device_t_us: int) -> tuple[int, int]:
        """(unwrapped seq, unwrapped device time in µs) of the next frame."""
        if self._raw is None:
            self.seq, self.t_us = seq, device_t_us
        else:
            last_seq, last_t = self._raw
            dt = (device_t_us - last_t + TIME_MOD // 2) % TIME_MOD - TIME_MOD // 2
            ds = (seq - last_seq) % SEQ_MOD
            wraps = round((dt / self.frame_period_us - ds) / SEQ_MOD)
            self.seq += ds + SEQ_MOD * wraps
            self.t_us += dt
        self._raw = (seq, device_t_us)
        return self.seq, self.t_us
