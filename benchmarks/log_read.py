"""Session-log read speed: skin frame pairs per second into numpy via load_session.

The file: 10 min of two-layer frames at 424 Hz (254,400 pairs) written by SessionWriter with
the default chunk compression (also timed: the other compressions, best of 2).
Baseline, same file and run: the plain mcap reader loop, make_reader(...).iter_messages() with
a foxglove RawImage protobuf decode of every message into numpy (timed on a prefix of the
file, extrapolated per frame pair).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.reader import make_reader

from benchmarks.log_write import N_FRAMES, skin_frames, write_session
from layerskin_exp.log import load_session
from layerskin_exp.log.session.writer import DEFAULT_COMPRESSION


def _naive(path: Path, max_pairs: int) -> tuple[float, int]:
    t0 = time.perf_counter()
    layers = {"/skin/superficial": [], "/skin/deep": []}
    with open(path, "rb") as fh:
        for _, channel, msg in make_reader(fh).iter_messages(topics=list(layers)):
            img = RawImage.FromString(msg.data)
            layers[channel.topic].append(np.frombuffer(img.data, "<u2").reshape(img.height, img.width))
            if len(layers["/skin/deep"]) >= max_pairs:
                break
    n = min(len(v) for v in layers.values())
    np.stack(layers["/skin/superficial"][:n]), np.stack(layers["/skin/deep"][:n])
    return time.perf_counter() - t0, n


def _best_load(path: Path, repeats: int) -> tuple[float, int]:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        s = load_session(path)
        best = min(best, time.perf_counter() - t0)
    n = len(s.streams["skin"]["seq"])
    assert s.complete
    return best, n


def run(n_frames: int = N_FRAMES, n_naive: int = 40_000, repeats: int = 3) -> dict:
    frames = skin_frames(n_frames)
    others = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "session.mcap"
        write_session(path, frames)
        best, n = _best_load(path, repeats)
        assert n == n_frames
        naive_s, naive_n = _naive(path, n_naive)
        for comp in ("zstd", "lz4", "none"):
            if comp != DEFAULT_COMPRESSION:
                other = Path(tmp) / f"{comp}.mcap"
                write_session(other, frames, comp)
                t, _ = _best_load(other, 2)
                others[f"with_{comp}_pairs_per_s"] = round(n / t)
                other.unlink()
    fast = n / best
    naive = naive_n / naive_s
    return {
        "frame_pairs": n,
        "compression": DEFAULT_COMPRESSION,
        "load_s": round(best, 3),
        "frame_pairs_per_s": round(fast),
        "baseline_frame_pairs_per_s": round(naive),
        "speedup_vs_baseline": round(fast / naive, 1),
        "target_frame_pairs_per_s": 1_000_000,
        **others,
        "note": f"baseline: mcap make_reader().iter_messages() + RawImage decode (timed on {naive_n} pairs)",
    }


if __name__ == "__main__":
    print(run())
