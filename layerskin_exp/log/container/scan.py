"""Tolerant, vectorised access to the records of an MCAP file, complete, cut short or damaged.

The mcap library reads a record at a time into Python objects, and its readers stop with an
exception on a truncated or damaged file. Here the top-level records are walked once (a few per
chunk, never per message), all chunks are decompressed in one batch call, and the chunks'
MessageIndex records (packed u64 (log_time, offset) pairs) become numpy arrays of absolute
message offsets in one buffer holding every chunk's records. Message fields are then gathered
with numpy.

Damage is read around, never stopped at: a chunk that fails to decompress or its CRC is skipped
and the rest kept; a damaged record is stepped over to the next well-formed one (framing.resync,
helped by the summary's chunk index when the summary is intact). What was lost is listed in
McapScan.lost with its log-time range, taken from the summary's chunk index (CRC-checked) where
there is one, else from the chunk header or the neighbouring good chunks. A file cut off
mid-record is read up to the last whole chunk.

A message present twice (a chunk written or copied twice: same channel, sequence number, times
and payload) is kept once; McapScan.repeats counts what was dropped.
"""

from __future__ import annotations

import errno
import mmap
import os
import stat
import struct
import zlib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import lz4.frame
import numpy as np
import zstandard
from mcap.opcode import Opcode
from mcap.records import Channel, Metadata, Schema
from numpy.lib.stride_tricks import sliding_window_view

from layerskin_exp.log.container.framing import (
    MAGIC,
    ChunkHead,
    Summary,
    check_record,
    parse_chunk_head,
    parse_record,
    read_footer,
    read_summary,
    resync,
)
from layerskin_exp.log.errors import SessionFileError

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
_LZ4_MAX_RATIO = 256  # lz4 cannot expand data more than ~255x: bounds a size the frame omits


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
class Lost:
    """Data a damaged file did not give back. Times are MCAP log time (host receive ns).

    start_ns / end_ns: the span the lost messages lie in (None where nothing bounds it);
    messages: how many were lost, by channel id where the file's indexes still say (None:
    unknown); reason: what was damaged, with its byte offset.
    """

    start_ns: int | None
    end_ns: int | None
    messages: dict[int, int] | None
    reason: str


@dataclass
class McapScan:
    """What a scan found. data: every good chunk's decompressed records, concatenated (uint8).

    has_footer: the file ends with an MCAP footer (the writer finished it).
    lost: data that could not be read (skipped chunks, damaged records), see Lost.
    damaged: any damage at all, including records that held no messages (metadata, indexes)
        and a data section failing its CRC; a damaged file is never complete.
    repeats: exact repeats of a message dropped (the first copy kept), by channel id.
    """

    data: np.ndarray
    channels: dict[int, Channel]
    schemas: dict[int, Schema]
    metadata: list[tuple[str, dict]]
    messages: dict[int, ChannelMessages]
    has_footer: bool
    warnings: list[str] = field(default_factory=list)
    n_chunks: int = 0
    lost: list[Lost] = field(default_factory=list)
    damaged: bool = False
    chunks_skipped: int = 0
    repeats: dict[int, int] = field(default_factory=dict)

    def payloads(self, msgs: ChannelMessages) -> list[bytes]:
        raw = memoryview(self.data)
        starts, ends = msgs.payload_start.tolist(), msgs.payload_end.tolist()
        return [raw[s:e].tobytes() for s, e in zip(starts, ends, strict=True)]


_SPECIAL = ((stat.S_ISFIFO, "FIFO (named pipe)"), (stat.S_ISSOCK, "socket"), (stat.S_ISCHR, "character device"),
            (stat.S_ISBLK, "block device"))


def special_file_kind(path) -> str | None:
    """What a special file at `path` is ("FIFO (named pipe)", "socket", "character device",
    "block device"), following links; None for a regular file, a folder, or nothing readable there.
    Told by type, without opening it: opening a FIFO blocks until something writes to it."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return next((what for test, what in _SPECIAL if test(mode)), None)


def link_loop_error(path) -> SessionFileError:
    """The one line for a path whose symbolic links lead back to themselves."""
    return SessionFileError(f"{path}: a symbolic link loop (the link leads back to itself); point at the file itself")


def scan(path) -> McapScan:
    """Scan an MCAP file. Raises SessionFileError if it cannot be opened, is empty, is a special
    file (never opened), or is not MCAP at all; damage inside is read around and reported, never
    raised."""
    kind = special_file_kind(path)
    if kind is not None:
        raise SessionFileError(f"{path}: a {kind}, not a session file; skipped without opening it")
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            if not size:
                return _scan(path, b"")
            # Mapped, not read: chunks decompress straight from the page cache into McapScan.data.
            # Everything kept is copied out of the map, which is closed before returning.
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
                return _scan(path, buf)
    except IsADirectoryError:
        raise SessionFileError(f"{path}: is a directory, not a session file") from None
    except FileNotFoundError:
        raise SessionFileError(f"{path}: no such session file") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise link_loop_error(path) from None
        raise SessionFileError(f"{path}: cannot be read ({exc.strerror or exc})") from None


@dataclass
class _Walk:
    """The data section's top-level records, in order, with what was damaged."""

    chunks: list[ChunkHead] = field(default_factory=list)
    index: list[tuple[int, int, int, int]] = field(default_factory=list)  # chunk, channel, start, length
    channels: dict[int, Channel] = field(default_factory=dict)
    schemas: dict[int, Schema] = field(default_factory=dict)
    metadata: list[tuple[str, dict]] = field(default_factory=list)
    bad: list[tuple[int, int | None]] = field(default_factory=list)  # damaged byte ranges
    data_end: tuple[int, int] | None = None  # (position, data-section crc)
    cut_off: bool = False


def _trusted_record(buf, pos: int, limit: int):
    """Record at pos in a data section whose CRC matched: framing as written, parse what is used."""
    if pos + 9 > limit:
        return None
    op, length = struct.unpack_from("<BQ", buf, pos)
    if op == Opcode.CHUNK:
        parsed = parse_chunk_head(buf, pos, length)
    elif op in (Opcode.METADATA, Opcode.CHANNEL, Opcode.SCHEMA):
        parsed = parse_record({Opcode.METADATA: Metadata, Opcode.CHANNEL: Channel, Opcode.SCHEMA: Schema}[op],
                              buf, pos + 9, length)
    else:
        parsed = True
    return None if parsed is None else (op, length, parsed)


def _walk(buf, limit: int, hints, warnings: list[str], trusted: bool = False) -> _Walk:
    w = _Walk()
    pos = 8
    CHUNK, MINDEX, META = Opcode.CHUNK, Opcode.MESSAGE_INDEX, Opcode.METADATA
    check = _trusted_record if trusted else check_record
    while pos < limit:
        rec = check(buf, pos, limit)
        if rec is None:
            nxt = resync(buf, pos + 1, limit, hints())
            w.bad.append((pos, nxt))
            if nxt is None:
                head = struct.unpack_from("<BQ", buf, pos) if pos + 9 <= limit else None
                if head is None or (head[0] == CHUNK and pos + 9 + head[1] > limit):
                    w.cut_off = True
                    warnings.append(f"file cut off inside the record at byte {pos} of {limit}")
                else:
                    warnings.append(f"damaged record at byte {pos}: nothing readable after it")
                break
            warnings.append(f"damaged bytes {pos}..{nxt} skipped")
            pos = nxt
            continue
        op, length, parsed = rec
        if op == MINDEX:
            cid, rlen = struct.unpack_from("<HI", buf, pos + 9)
            if rlen and w.chunks:
                w.index.append((len(w.chunks) - 1, cid, pos + 15, rlen))
        elif op == CHUNK:
            w.chunks.append(parsed)
        elif op == META:
            w.metadata.append((parsed.name, parsed.metadata))
        elif op == Opcode.CHANNEL:
            w.channels.setdefault(parsed.id, parsed)
        elif op == Opcode.SCHEMA:
            w.schemas.setdefault(parsed.id, parsed)
        elif op == Opcode.DATA_END:
            (crc,) = struct.unpack_from("<I", buf, pos + 9)
            w.data_end = (pos, crc)
            break
        elif op == Opcode.FOOTER:
            break
        elif op == Opcode.MESSAGE:
            warnings.append(f"message outside any chunk at byte {pos} ignored (unchunked writer?)")
        pos += 9 + length
    return w


def _scan(path, buf) -> McapScan:
    if not buf:
        raise SessionFileError(f"{path}: the file is empty (0 bytes); no session was recorded in it")
    if len(buf) < 8 and MAGIC.startswith(bytes(buf)):
        raise SessionFileError(f"{path}: cut off after {len(buf)} bytes, before any MCAP record")
    if bytes(buf[:8]) != MAGIC:
        raise SessionFileError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")
    warnings: list[str] = []
    n = len(buf)
    footer = read_footer(buf)
    summary = read_summary(buf, footer, warnings)
    damaged = footer is not None and footer[1] != 0 and summary is None
    limit = summary.start if summary else n
    # A data section whose CRC matches is exactly as written: its records need no checking.
    intact = bool(summary and summary.data_end is not None and summary.data_crc
                  and zlib.crc32(buf[: summary.data_end]) == summary.data_crc)

    def hints():
        return sorted(ci.chunk_start_offset for ci in summary.chunk_indexes) if summary else []

    w = _walk(buf, limit, hints, warnings, trusted=intact)
    damaged |= bool(w.bad) and not (w.cut_off and footer is None)
    if footer is None and not w.cut_off:
        warnings.append("file ends without the MCAP footer (writer did not finish)")
    if not intact and w.data_end is not None and w.data_end[1] and zlib.crc32(buf[: w.data_end[0]]) != w.data_end[1]:
        damaged = True
        warnings.append("the data section fails its CRC: a record outside the chunks (metadata or "
                        "message indexes) is damaged")
    channels, schemas = dict(w.channels), dict(w.schemas)
    if summary:
        for cid, c in summary.channels.items():
            channels.setdefault(cid, c)
        for sid, s in summary.schemas.items():
            schemas.setdefault(sid, s)

    # Chunk parameters: the summary's chunk index where it has the chunk (CRC-checked), else
    # the chunk header. A chunk the index lists but the walk never reached is lost.
    lost: list[Lost] = []
    found = {c.offset for c in w.chunks}
    by_offset = {ci.chunk_start_offset: ci for ci in summary.chunk_indexes} if summary and not intact else {}
    for ci in by_offset.values():
        if ci.chunk_start_offset not in found:
            lost.append(Lost(ci.message_start_time, ci.message_end_time, None,
                             f"chunk at byte {ci.chunk_start_offset} lies in damaged bytes"))
    for c in w.chunks:
        ci = by_offset.get(c.offset)
        if ci is not None and (ci.compression, ci.uncompressed_size) != (c.compression, c.uncompressed_size):
            warnings.append(f"chunk at byte {c.offset}: header disagrees with the chunk index; index used")
            c.compression, c.uncompressed_size = ci.compression, ci.uncompressed_size
            damaged = True

    data, base, good, why = _decompress_all(buf, w.chunks)
    if intact and not good.all():  # chunk data damaged inside an intact section: cannot be, but say so
        by_offset = {ci.chunk_start_offset: ci for ci in summary.chunk_indexes}
    index_counts = _index_counts(w.index)
    for i in np.flatnonzero(~good).tolist():
        c = w.chunks[i]
        ci = by_offset.get(c.offset)
        start, end = (ci.message_start_time, ci.message_end_time) if ci else _bracket(w.chunks, good, i)
        lost.append(Lost(start, end, index_counts.get(i), f"chunk at byte {c.offset}: {why[i]}"))
        warnings.append(f"chunk at byte {c.offset} skipped: {why[i]}")
    if not summary:
        for lo, hi in w.bad:
            if not (w.cut_off and hi is None and footer is None):
                lost.append(_unindexed_loss(w.chunks, good, lo, hi))

    _channels_in_chunks(data, base, good, channels, schemas)
    messages, short = _message_tables(data, base, good, w.index, buf, channels, schemas, warnings)
    for i in short:
        lost.append(Lost(*_bracket(w.chunks, good, i), None, f"chunk at byte {w.chunks[i].offset} ends inside a record"))
    for cid in [cid for cid, m in messages.items() if m.channel is None]:
        m = messages.pop(cid)
        t = m.header["log_time"]
        lost.append(Lost(int(t.min()), int(t.max()), {cid: m.count},
                         f"channel {cid} has no channel record; its {m.count} messages cannot be decoded"))
    repeats = _drop_repeats(data, messages)
    if repeats:
        damaged = True
        warnings.append(f"{sum(repeats.values())} repeated message(s) dropped (a chunk present twice?), "
                        f"by channel {repeats}")
    if summary and summary.statistics is not None:
        _check_counts(summary.statistics.channel_message_counts, messages, lost, warnings)
    if summary:
        lost_meta = _lost_metadata(summary, w.bad)
        if lost_meta:
            warnings.append(f"metadata records lost in damaged bytes: {lost_meta}")
    damaged |= bool(lost)
    return McapScan(
        data=data,
        channels=channels,
        schemas=schemas,
        metadata=w.metadata,
        messages=messages,
        has_footer=footer is not None,
        warnings=warnings,
        n_chunks=int(good.sum()),
        lost=lost,
        damaged=damaged,
        chunks_skipped=int((~good).sum()) + sum(1 for x in lost if x.reason.endswith("lies in damaged bytes")),
        repeats=repeats,
    )


def _drop_repeats(data: np.ndarray, messages: dict[int, ChannelMessages]) -> dict[int, int]:
    """Drop, in place, every message that repeats an earlier one of its channel exactly (sequence,
    log and publish times, payload); returns how many were dropped per channel id."""
    dropped = {}
    raw = memoryview(data)
    for cid, m in messages.items():
        key = m.header[["sequence", "log_time", "publish_time"]]
        _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        if (counts == 1).all():
            continue
        inverse = inverse.ravel()
        keep = np.ones(m.count, bool)
        start, end = m.payload_start, m.payload_end
        seen: dict[int, set[bytes]] = {}  # payloads met so far, per repeated key
        for i in np.flatnonzero(counts[inverse] > 1).tolist():
            payload = raw[start[i]:end[i]].tobytes()
            group = seen.setdefault(int(inverse[i]), set())
            keep[i] = payload not in group
            group.add(payload)
        if not keep.all():
            dropped[cid] = int((~keep).sum())
            m.offset, m.header = m.offset[keep], m.header[keep]
    return dropped


def _bracket(chunks: list[ChunkHead], good: np.ndarray, i: int) -> tuple[int | None, int | None]:
    """Log-time span of chunk i: its header's, if the good chunks around it do not contradict it,
    else the gap between those neighbours (a damaged header may hold any times)."""
    before = [chunks[j].end_ns for j in range(i) if good[j]]
    after = [chunks[j].start_ns for j in range(i + 1, len(chunks)) if good[j]]
    lo, hi = (max(before) if before else None), (min(after) if after else None)
    c = chunks[i] if i < len(chunks) else None
    if c is not None and c.start_ns <= c.end_ns and (lo is None or c.start_ns >= lo) and (hi is None or c.end_ns <= hi):
        return c.start_ns, c.end_ns
    return lo, hi


def _unindexed_loss(chunks: list[ChunkHead], good: np.ndarray, lo: int, hi: int | None) -> Lost:
    """Damaged bytes with no chunk index to say what they held: the gap between the good chunks
    on either side."""
    before = [c.end_ns for c, g in zip(chunks, good, strict=True) if g and c.offset < lo]
    after = [c.start_ns for c, g in zip(chunks, good, strict=True) if g and (hi is not None and c.offset >= hi)]
    span = "the end of the file" if hi is None else f"byte {hi}"
    return Lost(max(before) if before else None, min(after) if after else None, None,
                f"damaged bytes from {lo} to {span} (no intact chunk index says what they held)")


def _index_counts(index) -> dict[int, dict[int, int]]:
    out: dict[int, dict[int, int]] = {}
    for chunk, cid, _start, length in index:
        out.setdefault(chunk, {})[cid] = out.get(chunk, {}).get(cid, 0) + length // 16
    return out


def _check_counts(expected: dict[int, int], messages, lost: list[Lost], warnings) -> None:
    """The summary's per-channel message counts against what was read: any shortfall no lost
    chunk accounts for is listed too, so nothing is ever missing silently."""
    accounted: dict[int, int] = {}
    unknown = False
    for x in lost:
        if x.messages is None:
            unknown = True
        else:
            for cid, k in x.messages.items():
                accounted[cid] = accounted.get(cid, 0) + k
    missing = {}
    for cid, k in expected.items():
        got = messages[cid].count if cid in messages else 0
        short = k - got - accounted.get(cid, 0)
        if short > 0:
            missing[cid] = short
    if missing and not unknown:
        lost.append(Lost(None, None, missing, f"the file's statistics count {sum(missing.values())} more "
                                              f"messages than were read"))
        warnings.append(f"messages missing per channel (statistics vs read): {missing}")
    elif missing:
        for x in lost:  # fill in the counts the index could not give
            if x.messages is None:
                x.messages = missing
                break


def _lost_metadata(summary: Summary, bad) -> list[str]:
    names = []
    for mi in summary.metadata_indexes:
        for lo, hi in bad:
            if lo <= mi.offset < (hi if hi is not None else summary.start):
                names.append(mi.name)
    return names


def _decompress_all(buf, chunks: list[ChunkHead]):
    """Decompress every chunk straight into its slice of one preallocated buffer, chunk ranges
    split over a few threads (zstd, lz4 and zlib.crc32 release the GIL).

    Sizes are checked against the compressed frames before anything is allocated. Returns
    (data uint8, base offsets (n+1,), good (n,) bool, why: {chunk: reason it was skipped}).
    A bad chunk's slice is left as garbage; nothing indexes into it.
    """
    why: dict[int, str] = {}
    src = memoryview(buf)
    sizes = np.zeros(len(chunks), dtype=np.int64)
    for i, c in enumerate(chunks):
        problem = _size_problem(c, src[c.data_start : c.data_start + c.data_length])
        if problem:
            why[i] = problem
        else:
            sizes[i] = c.uncompressed_size
    base = np.zeros(len(chunks) + 1, dtype=np.int64)
    np.cumsum(sizes, out=base[1:])
    data = np.empty(int(base[-1]), np.uint8)
    good = np.ones(len(chunks), bool)
    for i in why:
        good[i] = False
    if not chunks:
        return data, base, good, why
    dst = memoryview(data)
    bounds = base.tolist()

    def work(first: int, stop: int) -> dict[int, str]:
        zstd = zstandard.ZstdDecompressor()
        bad = {}
        for i in range(first, stop):
            if i in why:
                continue
            c = chunks[i]
            out = dst[bounds[i] : bounds[i + 1]]
            try:
                _decompress_into(c.compression, src[c.data_start : c.data_start + c.data_length], out, zstd)
            except Exception as exc:  # noqa: BLE001 - a damaged frame can fail in many ways
                bad[i] = f"cannot be decompressed ({type(exc).__name__}: {exc})"
                continue
            if c.crc and zlib.crc32(out) != c.crc:
                bad[i] = "fails its CRC check"
        return bad

    n_threads = min(_THREADS, len(chunks), max(1, int(base[-1]) // _BYTES_PER_THREAD))
    edges = np.linspace(0, len(chunks), n_threads + 1).astype(int).tolist()
    if n_threads == 1:
        results = [work(0, len(chunks))]
    else:
        with ThreadPoolExecutor(n_threads) as pool:
            results = list(pool.map(work, edges[:-1], edges[1:]))
    for bad in results:
        for i, reason in bad.items():
            why[i] = reason
            good[i] = False
    return data, base, good, why


def _size_problem(c: ChunkHead, blob: memoryview) -> str:
    """Why chunk c's uncompressed size cannot be trusted ('' if it can): it must match what the
    compressed frame declares, so a damaged size never becomes a huge allocation."""
    usize = c.uncompressed_size
    if c.compression == "":
        return "" if usize == len(blob) else f"uncompressed chunk holds {len(blob)} bytes, header says {usize}"
    if c.compression == "zstd":
        try:
            declared = zstandard.frame_content_size(blob)
        except zstandard.ZstdError as exc:
            return f"zstd frame header is damaged ({exc})"
        if declared == -1:  # size not stored: decompress to learn it
            try:
                declared = len(zstandard.ZstdDecompressor().decompressobj().decompress(blob))
            except zstandard.ZstdError as exc:
                return f"cannot be decompressed ({exc})"
    elif c.compression == "lz4":
        try:
            declared = lz4.frame.get_frame_info(blob)["content_size"]
        except Exception as exc:  # noqa: BLE001 - lz4 raises RuntimeError/ValueError on bad headers
            return f"lz4 frame header is damaged ({exc})"
        if not declared:
            declared = usize if usize <= _LZ4_MAX_RATIO * len(blob) + 64 else -1
    else:
        return f"compression {c.compression!r} is not supported (zstd, lz4 or none)"
    return "" if declared == usize else f"frame holds {declared} bytes, chunk header says {usize}"


def _decompress_into(compression: str, blob: memoryview, out: memoryview, zstd) -> None:
    """Decompress one chunk's records into `out`, which must be exactly their size."""
    if compression == "zstd":
        # one-shot into bytes, then copied: stream_reader(...).readinto(out) from several threads
        # at once crashed the interpreter once in the suite (SIGSEGV inside zstandard's C code)
        raw = zstd.decompress(blob, max_output_size=len(out))
        if len(raw) != len(out):
            raise ValueError(f"zstd frame gave {len(raw)} bytes, chunk header says {len(out)}")
        out[:] = raw
    elif compression == "lz4":
        raw = lz4.frame.decompress(blob)
        if len(raw) != len(out):
            raise ValueError(f"lz4 frame gave {len(raw)} bytes, chunk header says {len(out)}")
        out[:] = raw
    else:
        out[:] = blob


def _walk_chunk(data: np.ndarray, start: int, stop: int, channels=None, schemas=None):
    """Walk one chunk's records in Python. Returns ([(channel id, offset in data)], whole):
    whole is False when the chunk ends inside a record."""
    raw = data[start:stop].tobytes()
    out = []
    p = 0
    while p + 9 <= len(raw):
        op, length = struct.unpack_from("<BQ", raw, p)
        if p + 9 + length > len(raw):
            return out, False
        if op == Opcode.MESSAGE and length >= HEADER_BYTES - 9:
            (cid,) = struct.unpack_from("<H", raw, p + 9)
            out.append((cid, start + p))
        elif op == Opcode.CHANNEL and channels is not None:
            c = parse_record(Channel, raw, p + 9, length)
            if c is not None:
                channels.setdefault(c.id, c)
        elif op == Opcode.SCHEMA and schemas is not None:
            s = parse_record(Schema, raw, p + 9, length)
            if s is not None:
                schemas.setdefault(s.id, s)
        p += 9 + length
    return out, p == len(raw)


def _channels_in_chunks(data: np.ndarray, base: np.ndarray, good: np.ndarray, channels, schemas) -> None:
    """Read the Schema/Channel records that open chunks (where our writer puts them)."""
    if data.size == 0:
        return
    for i in np.flatnonzero(good).tolist():
        p, stop = int(base[i]), int(base[i + 1])
        while p + 9 <= stop:
            op = int(data[p])
            if op not in (Opcode.SCHEMA, Opcode.CHANNEL):
                break
            length = int(data[p + 1 : p + 9].view("<u8")[0])
            if p + 9 + length > stop:
                break
            cls = Schema if op == Opcode.SCHEMA else Channel
            rec = parse_record(cls, data, p + 9, length)
            if rec is None:
                break
            (schemas if op == Opcode.SCHEMA else channels).setdefault(rec.id, rec)
            p += 9 + length


def _leading_records_end(data: np.ndarray, start: int, stop: int) -> int:
    """Offset of the first record of a chunk that is not a Schema or Channel record."""
    p = start
    while p + 9 <= stop and int(data[p]) in (Opcode.SCHEMA, Opcode.CHANNEL):
        p += 9 + int(data[p + 1 : p + 9].view("<u8")[0])
    return p


def _message_tables(data, base, good, index, buf, channels, schemas, warnings):
    """Per-channel message offsets and headers, from the MessageIndex records where they exactly
    tile each chunk's messages (checked vectorised), else by walking that chunk's records.

    Returns ({channel id: ChannelMessages}, [chunks that end inside a record]).
    """
    n = len(good)
    mv = memoryview(buf)
    entries = [(c, k, s, ln) for c, k, s, ln in index if good[c]]
    pairs = np.frombuffer(b"".join([mv[s : s + ln] for _, _, s, ln in entries]), "<u8").reshape(-1, 2)
    counts = np.array([ln // 16 for *_, ln in entries], np.int64)
    off = np.repeat(base[np.array([c for c, *_ in entries], np.int64)], counts) + pairs[:, 1].astype(np.int64)
    cid = np.repeat(np.array([k for _, k, *_ in entries], np.int64), counts)
    # Offsets are read from the file: anything outside the good chunks' data is damage.
    chunk_of = np.searchsorted(base, off, side="right") - 1
    inside = (off >= 0) & (chunk_of >= 0) & (chunk_of < n)
    inside[inside] &= good[chunk_of[inside]] & (off[inside] + HEADER_BYTES <= base[chunk_of[inside] + 1])
    ok_chunk = good.copy()
    ok_chunk[np.unique(chunk_of[~inside & (chunk_of >= 0) & (chunk_of < n)])] = False
    off, cid, chunk_of = off[inside], cid[inside], chunk_of[inside]
    order = np.argsort(off, kind="stable")
    off, cid, chunk_of = off[order], cid[order], chunk_of[order]
    header = _headers(data, off)
    end = off + 9 + header["length"].astype(np.int64)
    fine = (header["opcode"] == Opcode.MESSAGE) & (header["channel"] == cid)
    nxt_same = np.zeros(off.size, bool)
    nxt_same[:-1] = chunk_of[1:] == chunk_of[:-1]
    chained = np.ones(off.size, bool)
    chained[:-1] = np.where(nxt_same[:-1], off[1:] == end[:-1], True)
    last = ~nxt_same
    chained &= np.where(last, end == base[np.minimum(chunk_of + 1, n)], True)
    ok_chunk[np.unique(chunk_of[~(fine & chained)])] = False
    has = np.zeros(n, bool)
    has[chunk_of] = True
    first = np.full(n, np.iinfo(np.int64).max, np.int64)
    np.minimum.at(first, chunk_of, off)
    for c in np.flatnonzero(ok_chunk & has).tolist():
        if first[c] != _leading_records_end(data, int(base[c]), int(base[c + 1])):
            ok_chunk[c] = False
    ok_chunk &= has
    keep = ok_chunk[chunk_of]
    off, cid = off[keep], cid[keep]
    walked, short = [], []
    redo = np.flatnonzero(good & ~ok_chunk).tolist()
    if any(has[c] for c in redo):
        warnings.append(f"{len(redo)} chunk(s) with missing or damaged message indexes read by walking their records")
    for c in redo:
        found, whole = _walk_chunk(data, int(base[c]), int(base[c + 1]), channels, schemas)
        walked += found
        if not whole:
            short.append(c)
    if walked:
        off = np.concatenate([off, np.array([o for _, o in walked], np.int64)])
        cid = np.concatenate([cid, np.array([k for k, _ in walked], np.int64)])
        order = np.argsort(off, kind="stable")
        off, cid = off[order], cid[order]
    header = _headers(data, off)
    fits = (header["opcode"] == Opcode.MESSAGE) & (off + 9 + header["length"].astype(np.int64) <= data.size)
    off, cid, header = off[fits], cid[fits], header[fits]
    out = {}
    for k in np.unique(cid).tolist():
        sel = cid == k
        channel = channels.get(k)
        out[k] = ChannelMessages(
            channel=channel,
            schema=schemas.get(channel.schema_id) if channel else None,
            offset=off[sel],
            header=header[sel],
        )
    return out, short


def _headers(data: np.ndarray, off: np.ndarray) -> np.ndarray:
    if not off.size:
        return np.zeros(0, MESSAGE_HEADER)
    windows = sliding_window_view(data, HEADER_BYTES)
    return windows[off].copy().view(MESSAGE_HEADER)[:, 0]


__all__ = ["MESSAGE_HEADER", "ChannelMessages", "Lost", "McapScan", "SessionFileError", "scan"]
