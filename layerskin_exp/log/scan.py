"""Tolerant, vectorised access to the records of an MCAP file, complete or cut short.

The mcap library reads a record at a time into Python objects, and its readers stop with an
exception on a truncated file. Here the top-level records are walked once (a few per chunk,
never per message), all chunks are decompressed in one batch call, and the chunks' MessageIndex
records (packed u64 (log_time, offset) pairs) become numpy arrays of absolute message offsets
in one buffer holding every chunk's records. Message fields are then gathered with numpy.
A file cut off mid-record is read up to the last whole chunk, with a warning, never an error.
"""

from __future__ import annotations

import mmap
import os
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from io import BytesIO

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Metadata, Schema
from numpy.lib.stride_tricks import sliding_window_view

from layerskin_exp.log.errors import SessionFileError

MAGIC = b"\x89MCAP0\r\n"

# Message record layout inside a chunk: opcode u8, length u64, channel u16, sequence u32,
# log_time u64, publish_time u64, then the payload (31 bytes of header in all).
MESSAGE_HEADER = np.dtype(
    [
        ("opcode", "u1"),
        ("length", "<u8"),
        ("channel", "<u2"),
        ("sequence", "<u4"),
        ("log_time", "<u8"),
        ("publish_time", "<u8"),
    ]
)
HEADER_BYTES = MESSAGE_HEADER.itemsize  # 31
_THREADS = max(1, min(4, os.cpu_count() or 1))  # for chunk decompression
_BYTES_PER_THREAD = 4 << 20  # smaller files decompress in the calling thread


@dataclass
class ChannelMessages:
    """All messages of one channel, in file order. Arrays are (N,)."""

    channel: Channel
    schema: Schema | None
    offset: np.ndarray  # int64, record start in McapScan.data
    header: np.ndarray  # MESSAGE_HEADER records

    @property
    def count(self) -> int:
        return int(self.offset.size)

    @property
    def payload_start(self) -> np.ndarray:
        return self.offset + HEADER_BYTES

    @property
    def payload_end(self) -> np.ndarray:
        return self.offset + 9 + self.header["length"].astype(np.int64)


@dataclass
class McapScan:
    """What a scan found. data: every chunk's decompressed records, concatenated (uint8)."""

    data: np.ndarray
    channels: dict[int, Channel]
    schemas: dict[int, Schema]
    metadata: list[tuple[str, dict]]
    messages: dict[int, ChannelMessages]
    has_footer: bool
    warnings: list[str] = field(default_factory=list)
    n_chunks: int = 0

    def payloads(self, msgs: ChannelMessages) -> list[bytes]:
        raw = memoryview(self.data)
        starts, ends = msgs.payload_start.tolist(), msgs.payload_end.tolist()
        return [raw[s:e].tobytes() for s, e in zip(starts, ends, strict=True)]


def _read_record(cls, body: bytes):
    return cls.read(ReadDataStream(BytesIO(body)))


def _parse_chunk_header(buf: bytes, body: int):
    start_t, end_t, usize, crc, clen = struct.unpack_from("<QQQII", buf, body)
    p = body + 32
    compression = buf[p : p + clen].decode()
    p += clen
    (rlen,) = struct.unpack_from("<Q", buf, p)
    return compression, usize, crc, p + 8, rlen


def scan(path) -> McapScan:
    """Scan an MCAP file. Raises SessionFileError if it is empty or not MCAP at all."""
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if not size:
            return _scan(path, b"")
        # Mapped, not read: chunks decompress straight from the page cache into McapScan.data.
        # Everything kept is copied out of the map, which is closed before returning.
        with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
            return _scan(path, buf)


def _scan(path, buf) -> McapScan:
    if not buf:
        raise SessionFileError(f"{path}: the file is empty (0 bytes); no session was recorded in it")
    if len(buf) < 8 and MAGIC.startswith(buf):
        raise SessionFileError(f"{path}: cut off after {len(buf)} bytes, before any MCAP record")
    if buf[:8] != MAGIC:
        raise SessionFileError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")
    warnings: list[str] = []
    n = len(buf)
    chunks: list[tuple[str, int, int, int, int]] = []  # compression, usize, crc, data start, length
    index: list[tuple[int, int, int, int]] = []  # chunk, channel id, byte start, byte length
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    metadata: list[tuple[str, dict]] = []
    has_footer = False
    pos = 8
    unpack = struct.Struct("<BQ").unpack_from
    CHUNK, MINDEX, META = Opcode.CHUNK, Opcode.MESSAGE_INDEX, Opcode.METADATA
    while pos < n:
        if pos + 9 > n:
            warnings.append(f"file ends inside a record header at byte {pos} of {n}")
            break
        op, length = unpack(buf, pos)
        body = pos + 9
        end = body + length
        if end > n:
            warnings.append(
                f"record (opcode 0x{op:02x}) at byte {pos} needs {length} bytes but the file ends "
                f"after {n - body}: cut off"
            )
            break
        if op == MINDEX:
            cid, rlen = struct.unpack_from("<HI", buf, body)
            if rlen:
                index.append((len(chunks) - 1, cid, body + 6, rlen))
        elif op == CHUNK:
            chunks.append(_parse_chunk_header(buf, body))
        elif op == META:
            m = _read_record(Metadata, buf[body:end])
            metadata.append((m.name, m.metadata))
        elif op == Opcode.CHANNEL:
            c = _read_record(Channel, buf[body:end])
            channels[c.id] = c
        elif op == Opcode.SCHEMA:
            s = _read_record(Schema, buf[body:end])
            schemas[s.id] = s
        elif op == Opcode.FOOTER:
            has_footer = buf[end : end + 8] == MAGIC
            if not has_footer:
                warnings.append("footer found but the closing magic bytes are missing")
            break
        elif op == Opcode.MESSAGE:
            warnings.append(f"message outside any chunk at byte {pos} ignored (unchunked writer?)")
        elif op == 0:
            warnings.append(f"invalid record (opcode 0x00) at byte {pos}: file damaged from here on")
            break
        pos = end
    else:
        if not has_footer:
            warnings.append("file ends without the MCAP footer (writer did not finish)")

    # Without a footer the last chunk's message indexes may be missing or partial: rebuild them.
    reindex_last = bool(chunks) and not has_footer
    if reindex_last:
        last = len(chunks) - 1
        index = [entry for entry in index if entry[0] != last]

    data, base, chunks_ok = _decompress_all(buf, chunks, warnings)
    if chunks_ok < len(chunks):
        index = [entry for entry in index if entry[0] < chunks_ok]
        reindex_last = False
    extra = []
    if reindex_last:
        extra = _walk_chunk(data, int(base[-2]), int(base[-1]), len(chunks) - 1, warnings)

    _channels_in_chunks(data, base[:-1], channels, schemas)
    messages = _message_tables(buf, data, base, index, extra, channels, schemas, warnings)
    if any(cid not in channels for cid in messages):
        # Channel records not at chunk starts (another writer): walk every chunk once.
        for c in range(len(base) - 1):
            _walk_chunk(data, int(base[c]), int(base[c + 1]), c, [], channels, schemas)
        messages = _message_tables(buf, data, base, index, extra, channels, schemas, warnings)
    return McapScan(
        data=data,
        channels=channels,
        schemas=schemas,
        metadata=metadata,
        messages=messages,
        has_footer=has_footer,
        warnings=warnings,
        n_chunks=chunks_ok,
    )


def _decompress_all(buf, chunks, warnings) -> tuple[np.ndarray, np.ndarray, int]:
    """Decompress every chunk straight into its slice of one preallocated buffer, chunk ranges
    split over a few threads (zstd, lz4 and zlib.crc32 release the GIL).

    Returns (data uint8, base offsets (good+1,), number of good chunks). Reading stops before the
    first chunk that fails to decompress or fails its size/CRC check.
    """
    sizes = np.array([c[1] for c in chunks], dtype=np.int64)
    base = np.zeros(len(chunks) + 1, dtype=np.int64)
    np.cumsum(sizes, out=base[1:])
    data = np.empty(int(base[-1]), np.uint8)
    if not chunks:
        return data, base, 0
    src, dst = memoryview(buf), memoryview(data)
    bounds = base.tolist()

    def work(first: int, stop: int) -> tuple[int, str]:
        """Decompress chunks first..stop-1; returns (index of the first bad chunk or stop, why)."""
        zstd = zstandard.ZstdDecompressor()
        for i in range(first, stop):
            compression, usize, crc, start, length = chunks[i]
            out = dst[bounds[i] : bounds[i + 1]]
            try:
                _decompress_into(compression, src[start : start + length], out, zstd)
            except (zstandard.ZstdError, RuntimeError, ValueError) as exc:
                return i, f"chunk {i} cannot be decompressed ({exc}); reading stops before it"
            if crc and zlib.crc32(out) != crc:
                return i, f"chunk {i} fails its CRC check; reading stops before it"
        return stop, ""

    n_threads = min(_THREADS, len(chunks), max(1, int(base[-1]) // _BYTES_PER_THREAD))
    edges = np.linspace(0, len(chunks), n_threads + 1).astype(int).tolist()
    if n_threads == 1:
        results = [work(0, len(chunks))]
    else:
        with ThreadPoolExecutor(n_threads) as pool:
            results = list(pool.map(work, edges[:-1], edges[1:]))
    good, why = len(chunks), ""
    for (stop, msg), end in zip(results, edges[1:], strict=True):
        if stop < end:
            good, why = stop, msg
            break
    if why:
        warnings.append(why)
    return data[: bounds[good]], base[: good + 1], good


def _decompress_into(compression: str, blob: memoryview, out: memoryview, zstd) -> None:
    """Decompress one chunk's records into `out`, which must be exactly their size."""
    if compression == "zstd":
        declared = zstandard.frame_content_size(blob)
        if declared not in (-1, len(out)):
            raise ValueError(f"zstd frame holds {declared} bytes, chunk header says {len(out)}")
        got = zstd.stream_reader(blob).readinto(out)
        if got != len(out):
            raise ValueError(f"zstd frame gave {got} bytes, chunk header says {len(out)}")
    elif compression == "lz4":
        raw = lz4.frame.decompress(blob)
        if len(raw) != len(out):
            raise ValueError(f"lz4 frame gave {len(raw)} bytes, chunk header says {len(out)}")
        out[:] = raw
    elif compression == "":
        out[:] = blob
    else:
        raise SessionFileError(f"chunk compression {compression!r} is not supported (zstd, lz4 or none)")


def _walk_chunk(data: np.ndarray, start: int, stop: int, chunk: int, warnings, channels=None, schemas=None):
    """Walk one chunk's records in Python. Returns [(chunk, channel id, offset in chunk)]."""
    raw = data[start:stop].tobytes()
    out = []
    p = 0
    while p + 9 <= len(raw):
        op, length = struct.unpack_from("<BQ", raw, p)
        if p + 9 + length > len(raw):
            warnings.append(f"chunk {chunk} ends inside a record")
            break
        if op == Opcode.MESSAGE:
            (cid,) = struct.unpack_from("<H", raw, p + 9)
            out.append((chunk, cid, p))
        elif op == Opcode.CHANNEL and channels is not None:
            c = _read_record(Channel, raw[p + 9 : p + 9 + length])
            channels.setdefault(c.id, c)
        elif op == Opcode.SCHEMA and schemas is not None:
            s = _read_record(Schema, raw[p + 9 : p + 9 + length])
            schemas.setdefault(s.id, s)
        p += 9 + length
    return out


def _channels_in_chunks(data: np.ndarray, starts: np.ndarray, channels, schemas) -> None:
    """Read the Schema/Channel records that open chunks (where our writer puts them)."""
    if data.size == 0:
        return
    ops = data[starts]
    for s in starts[(ops == Opcode.SCHEMA) | (ops == Opcode.CHANNEL)].tolist():
        p = s
        while p + 9 <= data.size:
            op = int(data[p])
            length = int(data[p + 1 : p + 9].view("<u8")[0])
            body = data[p + 9 : p + 9 + length].tobytes()
            if op == Opcode.SCHEMA:
                rec = _read_record(Schema, body)
                schemas.setdefault(rec.id, rec)
            elif op == Opcode.CHANNEL:
                rec = _read_record(Channel, body)
                channels.setdefault(rec.id, rec)
            else:
                break
            p += 9 + length


def _message_tables(buf, data, base, index, extra, channels, schemas, warnings) -> dict[int, ChannelMessages]:
    by_channel: dict[int, list] = {}
    for chunk, cid, start, length in index:
        by_channel.setdefault(cid, []).append((chunk, start, length))
    for chunk, cid, off in extra:
        by_channel.setdefault(cid, []).append((chunk, None, off))
    windows = sliding_window_view(data, HEADER_BYTES) if data.size >= HEADER_BYTES else None
    mv = memoryview(buf)
    out = {}
    for cid, entries in by_channel.items():
        idx_parts = [mv[s : s + ln] for _, s, ln in entries if s is not None]
        pairs = np.frombuffer(b"".join(idx_parts), "<u8").reshape(-1, 2)
        counts = np.array([ln // 16 for _, s, ln in entries if s is not None], dtype=np.int64)
        chunk_ids = np.array([c for c, s, _ in entries if s is not None], dtype=np.int64)
        offsets = base[np.repeat(chunk_ids, counts)] + pairs[:, 1].astype(np.int64)
        tail = [base[c] + off for c, s, off in entries if s is None]
        if tail:
            offsets = np.concatenate([offsets, np.array(tail, dtype=np.int64)])
        if offsets.size > 1 and np.any(np.diff(offsets) <= 0):
            offsets = np.unique(offsets)
        ok = (offsets >= 0) & (offsets + HEADER_BYTES <= data.size)
        if not ok.all():
            warnings.append(
                f"channel {cid}: {int((~ok).sum())} index entries point outside the data; skipped"
            )
            offsets = offsets[ok]
        header = (
            windows[offsets].copy().view(MESSAGE_HEADER)[:, 0]
            if offsets.size
            else np.zeros(0, MESSAGE_HEADER)
        )
        good = (header["opcode"] == Opcode.MESSAGE) & (header["channel"] == cid)
        good &= offsets + 9 + header["length"].astype(np.int64) <= data.size
        if not good.all():
            warnings.append(
                f"channel {cid}: {int((~good).sum())} index entries do not point at its messages; skipped"
            )
            offsets, header = offsets[good], header[good]
        channel = channels.get(cid)
        out[cid] = ChannelMessages(
            channel=channel,  # None until the channel record is found; the caller re-scans
            schema=schemas.get(channel.schema_id) if channel else None,
            offset=offsets,
            header=header,
        )
    return out


__all__ = ["MESSAGE_HEADER", "McapScan", "ChannelMessages", "SessionFileError", "scan"]
