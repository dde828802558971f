"""Session-log write speed: two-layer frames at 424 Hz for a simulated 10 min trial.

Figure: times faster than real time for SessionWriter.write(TwoLayerFrame) of 254,400 frame
pairs (both layers as foxglove.RawImage on their own channels, 100 ms zstd chunks, clock sync
and summary at close) into a temp file. Baseline, same run: the straightforward way, a
foxglove RawImage protobuf object serialised per layer through mcap_protobuf's Writer
(timed on a slice, extrapolated per frame pair).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap_protobuf.writer import Writer as ProtobufWriter

from layerskin_exp.log import SessionWriter
from layerskin_exp.types import TwoLayerFrame

FRAME_PERIOD_NS = 2_360_000  # one frame pair every 2.36 ms (~424 Hz)
N_FRAMES = 254_400  # 10 min at 424 Hz


def skin_frames(n: int, pool: int = 4096, seed: int = 0) -> list[TwoLayerFrame]:
    """n frames cycling through `pool` distinct realistic scans: per-taxel baselines, read
    noise, and a contact blob moving across the array (deep layer: wider, weaker)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:16, 0:16]
    k = np.arange(pool)
    cx = 7.5 + 5 * np.sin(2 * np.pi * k / pool)[:, None, None]
    cy = 7.5 + 5 * np.cos(2 * np.pi * k / 1024)[:, None, None]
    amp = (2000 * np.clip(np.sin(2 * np.pi * k / 700), 0, None))[:, None, None]
    r2 = (xx - cx) ** 2 + (yy - cy) ** 2
    base = rng.uniform(40, 300, (2, 16, 16))
    sup = base[0] + amp * np.exp(-r2 / 4.0) + rng.normal(0, 4, (pool, 16, 16))
    deep = base[1] + 0.6 * amp * np.exp(-r2 / 9.0) + rng.normal(0, 4, (pool, 16, 16))
    sup = np.clip(np.rint(sup), 0, 4095).astype(np.uint16)
    deep = np.clip(np.rint(deep), 0, 4095).astype(np.uint16)
    jitter = rng.gamma(2.0, 60_000, n).astype(np.int64)
    return [
        TwoLayerFrame(
            sup[i % pool],
            deep[i % pool],
            i,
            1_000_000_000 + i * FRAME_PERIOD_NS,
            7_000_000_000 + i * FRAME_PERIOD_NS + int(jitter[i]),
        )
        for i in range(n)
    ]


def write_session(path: Path, frames: list[TwoLayerFrame]) -> float:
    """Write frames with SessionWriter; returns seconds taken (including close)."""
    t0 = time.perf_counter()
    with SessionWriter(path, metadata={"backend": "benchmark"}, labels={"trial": 0}) as w:
        write = w.write
        for f in frames:
            write(f)
    return time.perf_counter() - t0


def _naive(path: Path, frames: list[TwoLayerFrame]) -> float:
    t0 = time.perf_counter()
    with open(path, "wb") as fh:
        writer = ProtobufWriter(fh)
        for f in frames:
            for topic, layer in (("/skin/superficial", f.superficial), ("/skin/deep", f.deep)):
                msg = RawImage(width=16, height=16, encoding="mono16", step=32, data=layer.tobytes())
                msg.timestamp.FromNanoseconds(f.device_t_ns)
                writer.write_message(
                    topic, msg, log_time=f.host_t_ns, publish_time=f.device_t_ns, sequence=f.seq
                )
        writer.finish()
    return time.perf_counter() - t0


def run(n_frames: int = N_FRAMES, n_naive: int = 30_000) -> dict:
    frames = skin_frames(n_frames)
    real_time_s = n_frames * FRAME_PERIOD_NS / 1e9
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "session.mcap"
        elapsed = write_session(path, frames)
        size = path.stat().st_size
        naive = _naive(Path(tmp) / "naive.mcap", frames[:n_naive])
    naive_per_frame = naive / n_naive
    return {
        "frame_pairs": n_frames,
        "real_time_s": round(real_time_s, 1),
        "write_s": round(elapsed, 2),
        "x_real_time": round(real_time_s / elapsed, 1),
        "baseline_x_real_time": round(FRAME_PERIOD_NS / 1e9 / naive_per_frame, 1),
        "speedup_vs_baseline": round(naive_per_frame * n_frames / elapsed, 2),
        "target_x_real_time": 200,
        "file_mb": round(size / 1e6, 1),
        "note": "baseline: foxglove RawImage protobuf object per layer via mcap_protobuf Writer "
        f"(timed on {n_naive} frame pairs)",
    }


if __name__ == "__main__":
    print(run())
