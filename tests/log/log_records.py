"""Deterministic records for the session-log tests."""

from __future__ import annotations

import numpy as np

from layerskin_exp.types import (
    GripperState,
    MarkerDetection,
    Pose,
    ProtocolEvent,
    StagePosition,
    TwoLayerFrame,
    Wrench,
)

PERIOD_NS = 2_360_000
DEVICE0_NS = 5_000_000_000
HOST0_NS = 90_000_000_000


def flip_value(raw: bytes, record: bytes, key: bytes) -> bytes:
    """raw with the first character of `key`'s stored value in metadata record `record` changed
    (a digit stays a digit: the value still parses, only the check can tell)."""
    at = raw.index(key, raw.index(record)) + len(key) + 4  # the value follows its u32 length
    return raw[:at] + bytes([raw[at] ^ 0x01]) + raw[at + 1:]


def frame(i: int) -> TwoLayerFrame:
    """Frame i: both layers a deterministic function of i, including the extremes 0 and 4095."""
    k = np.arange(256, dtype=np.int64).reshape(16, 16)
    sup = ((k * 37 + i * 11) % 4096).astype(np.uint16)
    deep = ((k * 53 + i * 5) % 4096).astype(np.uint16)
    sup[0, 0], sup[15, 15], deep[3, 4], deep[7, 7] = 0, 4095, 4095, 0
    return TwoLayerFrame(
        sup,
        deep,
        seq=i,
        device_t_ns=DEVICE0_NS + i * PERIOD_NS,
        host_t_ns=HOST0_NS + i * PERIOD_NS + (i * 7919) % 50_000,
    )


def records(n_frames: int, seed: int = 0) -> list:
    """A mixed session: skin every frame, other streams at lower rates, events now and then."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n_frames):
        f = frame(i)
        out.append(f)
        dev, host = f.device_t_ns, f.host_t_ns + 1000
        if i % 2 == 0:
            out.append(
                Wrench(rng.normal(0, 2, 3) - 1.0, rng.normal(0, 0.05, 3), i // 2, dev, host, status=i % 3)
            )
        if i % 5 == 0:
            out.append(StagePosition(rng.uniform(-12, 12, 3), i // 5, dev, host))
            out.append(Pose(rng.normal(size=3), rng.normal(size=4), "base", dev, host, seq=i // 5))
            out.append(
                GripperState(rng.uniform(0, 50), 25.0, 255, 100, bool(i % 2), 0, dev, host, seq=i // 5)
            )
        if i % 14 == 0:
            for mid in (0, 1):
                pose = Pose(rng.normal(size=3), rng.normal(size=4), "camera", dev, host, seq=i // 14)
                out.append(MarkerDetection(mid, pose, rng.uniform(0, 640, (4, 2)), i // 14, dev, host))
        if i % 100 == 0:
            out.append(ProtocolEvent("phase", f"step {i}", host, dev, {"i": i, "nested": {"ok": True}}))
    return out
