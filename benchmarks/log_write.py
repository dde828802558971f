"""Session-log write speed: two-layer frames at 424 Hz for a simulated 10 min trial.

Figure: times faster than real time for SessionWriter.write(TwoLayerFrame) of 254,400 frame
pairs (both layers as foxglove.RawImage on their own channels, 100 ms chunks with the default
compression, clock sync and summary at close) into a temp file, and the same for each other
chunk compression (speed and file size). Baseline, same run: the straightforward way, a
foxglove RawImage protobuf object serialised per layer through mcap_protobuf's Writer
(timed on a slice, extrapolated per frame pair). Second reference: the bare mcap
Writer.add_message loop with prebuilt payload bytes and no compression, the ceiling of any
writer that adds messages one at a time through the library's public API. Third reference: the
Foxglove SDK's own MCAP writer (Rust; foxglove.open_mcap + Channel.log per layer, prebuilt
payload bytes, lz4, timed on the first 100,000 frame pairs), the writer the live view's
library would offer for files.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.writer import CompressionType, Writer
from mcap_protobuf.writer import Writer as ProtobufWriter

from layerskin_exp.log import SessionWriter
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.session.writer import DEFAULT_COMPRESSION
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


def write_session(path: Path, frames: list[TwoLayerFrame], compression: str = DEFAULT_COMPRESSION) -> float:
    """Write frames with SessionWriter; returns seconds taken (including close)."""
    t0 = time.perf_counter()
    with SessionWriter(
        path, metadata={"backend": "benchmark"}, labels={"trial": 0}, compression=compression
    ) as w:
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


def _bare_add_message(path: Path, frames: list[TwoLayerFrame]) -> float:
    """The library's per-message floor: Writer.add_message with payloads built beforehand, no
    compression, chunks closed every 100 ms as SessionWriter does."""
    payloads = [
        (
            S.skin_payload(f.device_t_ns, f.superficial.tobytes()),
            S.skin_payload(f.device_t_ns, f.deep.tobytes()),
        )
        for f in frames
    ]
    per_chunk = 100_000_000 // FRAME_PERIOD_NS
    t0 = time.perf_counter()
    with open(path, "wb") as fh:
        w = Writer(fh, chunk_size=1 << 40, compression=CompressionType.NONE)
        w.start(profile="", library="bench")
        sid = w.register_schema("foxglove.RawImage", "protobuf", b"")
        sup, deep = (
            w.register_channel("/skin/superficial", "protobuf", sid),
            w.register_channel("/skin/deep", "protobuf", sid),
        )
        add = w.add_message
        for i, (f, (p_sup, p_deep)) in enumerate(zip(frames, payloads, strict=True)):
            add(sup, f.host_t_ns, p_sup, f.device_t_ns, f.seq)
            add(deep, f.host_t_ns, p_deep, f.device_t_ns, f.seq)
            if i % per_chunk == per_chunk - 1:
                w.flush()
        w.finish()
    return time.perf_counter() - t0


def _foxglove_sdk(path: Path, frames: list[TwoLayerFrame]) -> float:
    """foxglove.open_mcap with two raw protobuf channels, payloads built beforehand (lz4)."""
    import foxglove
    from foxglove.mcap import MCAPCompression, MCAPWriteOptions

    payloads = [(S.skin_payload(f.host_t_ns, f.superficial.tobytes()), S.skin_payload(f.host_t_ns, f.deep.tobytes()))
                for f in frames]
    ctx = foxglove.Context()
    schema = foxglove.Schema(name="foxglove.RawImage", encoding="protobuf", data=S.proto_schema_data(S.RawImage))
    t0 = time.perf_counter()
    with foxglove.open_mcap(path, context=ctx, allow_overwrite=True,
                            writer_options=MCAPWriteOptions(compression=MCAPCompression.Lz4)):
        sup = foxglove.Channel("/skin/superficial", schema=schema, message_encoding="protobuf", context=ctx)
        deep = foxglove.Channel("/skin/deep", schema=schema, message_encoding="protobuf", context=ctx)
        for f, (p_sup, p_deep) in zip(frames, payloads, strict=True):
            sup.log(p_sup, log_time=f.host_t_ns)
            deep.log(p_deep, log_time=f.host_t_ns)
    return time.perf_counter() - t0


def run(n_frames: int = N_FRAMES, n_naive: int = 30_000, n_sdk: int = 100_000) -> dict:
    frames = skin_frames(n_frames)
    real_time_s = n_frames * FRAME_PERIOD_NS / 1e9
    others = [c for c in ("zstd", "lz4", "none") if c != DEFAULT_COMPRESSION]
    by_compression = {}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "session.mcap"
        elapsed = write_session(path, frames)
        size = path.stat().st_size
        naive = _naive(Path(tmp) / "naive.mcap", frames[:n_naive])
        bare = _bare_add_message(Path(tmp) / "bare.mcap", frames)
        sdk = _foxglove_sdk(Path(tmp) / "sdk.mcap", frames[:n_sdk]) / min(n_sdk, n_frames)
        for comp in others:
            other = Path(tmp) / f"{comp}.mcap"
            t = write_session(other, frames, comp)
            by_compression[comp] = f"{real_time_s / t:.0f}x real time, {other.stat().st_size / 1e6:.0f} MB"
            other.unlink()
    naive_per_frame = naive / n_naive
    return {
        "frame_pairs": n_frames,
        "real_time_s": round(real_time_s, 1),
        "compression": DEFAULT_COMPRESSION,
        "write_s": round(elapsed, 2),
        "x_real_time": round(real_time_s / elapsed, 1),
        "baseline_x_real_time": round(FRAME_PERIOD_NS / 1e9 / naive_per_frame, 1),
        "speedup_vs_baseline": round(naive_per_frame * n_frames / elapsed, 2),
        "bare_add_message_x_real_time": round(real_time_s / bare, 1),
        "foxglove_sdk_x_real_time": round(FRAME_PERIOD_NS / 1e9 / sdk, 1),
        "target_x_real_time": 200,
        "file_mb": round(size / 1e6, 1),
        **{f"with_{comp}": text for comp, text in by_compression.items()},
        "note": "baseline: foxglove RawImage protobuf object per layer via mcap_protobuf Writer "
        f"(timed on {n_naive} frame pairs); bare_add_message: mcap Writer.add_message loop, "
        "prebuilt payloads, no compression",
    }


if __name__ == "__main__":
    print(run())
