"""Skin board stream parsing throughput (frame pairs per second, one core).

`FrameParser` (hardware/skin_board/wire.py): sync search with bytes.find, CRC-32 by zlib, and
the 12-bit unpacking vectorised over every frame a read completed. Baseline: a byte-at-a-time
state machine, as one would first write it, with the same CRC function and a Python loop over
the packed values. Both parse the same stream of a few thousand frames with ~1 % of frames
bit-flipped and stray bytes between ~1 % of them, fed in USB-sized reads. The real board sends
424 frame pairs/s; the target is >= 50 000 (over 100 times that).
"""

from __future__ import annotations

import time
import zlib

import numpy as np

from hardware.skin_board.wire import (
    CRC_OFFSET,
    FRAME_LEN,
    HEADER_LEN,
    SYNC,
    VERSION,
    FrameParser,
    encode_frame,
)

REAL_RATE = 424


def make_stream(n_frames: int, seed: int = 0) -> tuple[bytes, int]:
    """A stream of n_frames encoded frames, ~1 % corrupted and ~1 % preceded by garbage; and how
    many frames are intact."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 4096, (n_frames, 2, 16, 16), dtype=np.uint16)
    out, intact = [], 0
    for k in range(n_frames):
        frame = bytearray(encode_frame(k, 2360 * k, counts[k, 0], counts[k, 1]))
        if rng.random() < 0.01:
            bit = int(rng.integers(FRAME_LEN * 8))
            frame[bit // 8] ^= 1 << (bit % 8)
        else:
            intact += 1
        if rng.random() < 0.01:
            out.append(rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8).tobytes())
        out.append(bytes(frame))
    return b"".join(out), intact


class NaiveParser:
    """Byte-at-a-time framing: match the sync, collect FRAME_LEN bytes, check, unpack value by value."""

    def __init__(self) -> None:
        self.frame = bytearray()
        self.out: list = []

    def feed(self, data: bytes) -> list:
        for b in data:
            self._byte(b)
        out, self.out = self.out, []
        return out

    def _byte(self, b: int) -> None:
        frame = self.frame
        if len(frame) < len(SYNC):
            if b == SYNC[len(frame)]:
                frame.append(b)
            else:
                self.frame = bytearray([b]) if b == SYNC[0] else bytearray()
            return
        frame.append(b)
        if len(frame) < FRAME_LEN:
            return
        self.frame = bytearray()
        crc = int.from_bytes(frame[CRC_OFFSET:], "little")
        if frame[4] != VERSION or zlib.crc32(frame[:CRC_OFFSET]) != crc:
            for c in frame[1:]:  # resync: search again from the byte after this sync
                self._byte(c)
            return
        vals = []
        for k in range(HEADER_LEN, CRC_OFFSET, 3):
            lo, mid, hi = frame[k], frame[k + 1], frame[k + 2]
            vals.append(lo | (mid & 0x0F) << 8)
            vals.append(mid >> 4 | hi << 4)
        counts = np.array(vals, np.uint16).reshape(2, 16, 16)
        seq = int.from_bytes(frame[6:8], "little")
        t_us = int.from_bytes(frame[8:12], "little")
        self.out.append((seq, t_us, counts[0], counts[1]))


def _parse(parser, data: bytes, chunk: int) -> list:
    out = []
    for i in range(0, len(data), chunk):
        out += parser.feed(data[i:i + chunk])
    return out


def run(n_frames: int = 5_000, n_naive: int = 500, chunk: int = 4096) -> dict:
    data, intact = make_stream(n_frames)
    naive_data = data[:n_naive * FRAME_LEN]
    # the two parsers agree on what they accept
    ref = _parse(NaiveParser(), naive_data, chunk)
    fast = _parse(FrameParser(), naive_data, chunk)
    assert [(f.seq, f.superficial.tobytes(), f.deep.tobytes()) for f in fast] == \
        [(s, a.tobytes(), b.tobytes()) for s, _, a, b in ref]
    figures = {}
    for label, size in (("", chunk), ("_256B_reads", 256)):
        best = np.inf
        for _ in range(3):
            p = FrameParser()
            t0 = time.perf_counter()
            got = _parse(p, data, size)
            best = min(best, time.perf_counter() - t0)
        assert len(got) == intact, (len(got), intact)
        figures[f"frame_pairs_per_s{label}"] = round(len(got) / best)
    t0 = time.perf_counter()
    got = _parse(NaiveParser(), naive_data, chunk)
    naive = len(got) / (time.perf_counter() - t0)
    fast_rate = figures["frame_pairs_per_s"]
    return {**figures, "naive_byte_loop_frame_pairs_per_s": round(naive), "speedup": round(fast_rate / naive, 1),
            "target_frame_pairs_per_s": 50_000, "x_real_rate": round(fast_rate / REAL_RATE),
            "note": f"{n_frames} frames ({FRAME_LEN} B each) with ~1 % bit-flipped and ~1 % after stray bytes, "
                    f"fed in {chunk}-byte reads; corrupt frames={p.corrupt}, skipped bytes={p.skipped_bytes}"}


if __name__ == "__main__":
    print(run())
