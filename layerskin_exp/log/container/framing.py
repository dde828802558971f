"""The top-level record structure of an MCAP file, read defensively.

Every length and offset read from the file is checked against the file before it is used, and
every record is parsed by the mcap library's own record classes from a bounded slice, so a
damaged file gives "this record is bad", never an exception or a huge allocation. A record is
accepted only if it parses exactly to its declared length and the record after it starts with a
plausible header: a damaged length field is then caught where it lands, and `resync` finds the
next good record by the same test.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from io import BytesIO

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    ChunkIndex,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from numpy.lib.stride_tricks import sliding_window_view

MAGIC = b"\x89MCAP0\r\n"
RECORD_HEAD = struct.Struct("<BQ")  # opcode, record length
_FOOTER = struct.Struct("<BQQQI")  # opcode, length (20), summary start, summary offset start, crc
FOOTER_BYTES = _FOOTER.size  # 29
_CHUNK_HEAD = struct.Struct("<QQQII")  # start time, end time, uncompressed size, crc, name length

_PARSERS = {
    Opcode.HEADER: Header,
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.METADATA: Metadata,
    Opcode.CHUNK_INDEX: ChunkIndex,
    Opcode.STATISTICS: Statistics,
    Opcode.METADATA_INDEX: MetadataIndex,
    Opcode.SUMMARY_OFFSET: SummaryOffset,
}
KNOWN_OPS = frozenset(int(o) for o in Opcode)
# Where the data section is damaged, the next record is looked for among these: never Message
# records (ours are all inside chunks, where an uncompressed chunk holds valid-looking ones).
_RESYNC_OPS = np.zeros(256, bool)
_RESYNC_OPS[[int(o) for o in Opcode if o not in (Opcode.MESSAGE, Opcode.HEADER)]] = True


@dataclass
class ChunkHead:
    """A Chunk record's header: where its compressed records lie in the file."""

    offset: int  # record start in the file
    start_ns: int
    end_ns: int
    uncompressed_size: int
    crc: int
    compression: str
    data_start: int
    data_length: int


def parse_record(cls, buf, body: int, length: int):
    """The record `cls` from buf[body : body + length], or None unless it parses to exactly that
    length (the mcap library's reader, on a bounded copy)."""
    stream = ReadDataStream(BytesIO(bytes(buf[body : body + length])))
    try:
        rec = cls.read(stream)
    except Exception:  # noqa: BLE001 - any failure to parse untrusted bytes means "not this record"
        return None
    return rec if stream.count == length else None


def parse_chunk_head(buf, pos: int, length: int) -> ChunkHead | None:
    body = pos + 9
    if length < _CHUNK_HEAD.size + 8:
        return None
    start_t, end_t, usize, crc, clen = _CHUNK_HEAD.unpack_from(buf, body)
    p = body + _CHUNK_HEAD.size
    if clen > 16 or p + clen + 8 > body + length:
        return None
    try:
        compression = bytes(buf[p : p + clen]).decode("ascii")
    except UnicodeDecodeError:
        return None
    (rlen,) = struct.unpack_from("<Q", buf, p + clen)
    if rlen != length - _CHUNK_HEAD.size - clen - 8:
        return None
    return ChunkHead(pos, start_t, end_t, usize, crc, compression, p + clen + 8, rlen)


def check_record(buf, pos: int, limit: int, *, resync: bool = False):
    """(opcode, length, parsed) if a well-formed record starts at pos and ends by limit, else None.

    parsed: the library record for metadata-like records, a ChunkHead for chunks, True otherwise.
    The record after it must start with a plausible header (or be the limit, or the footer's
    closing magic), which catches a length field that was damaged but still lands in the file.
    """
    if pos + 9 > limit:
        return None
    op, length = RECORD_HEAD.unpack_from(buf, pos)
    end = pos + 9 + length
    if op not in KNOWN_OPS or end > limit or (resync and not _RESYNC_OPS[op]):
        return None
    if op == Opcode.CHUNK:
        parsed = parse_chunk_head(buf, pos, length)
    elif op == Opcode.MESSAGE_INDEX:
        ok = length >= 6 and struct.unpack_from("<I", buf, pos + 11)[0] == length - 6 and (length - 6) % 16 == 0
        parsed = True if ok else None
    elif op == Opcode.DATA_END:
        parsed = True if length == 4 else None
    elif op == Opcode.FOOTER:
        parsed = True if length == 20 and bytes(buf[end : end + 8]) == MAGIC else None
        return (op, length, parsed) if parsed else None
    elif op in _PARSERS:
        parsed = parse_record(_PARSERS[op], buf, pos + 9, length)
    else:
        parsed = True
    if parsed is None:
        return None
    if end == limit:
        return op, length, parsed
    if end + 9 > limit:
        return None
    nop, nlen = RECORD_HEAD.unpack_from(buf, end)
    allowed = _RESYNC_OPS[nop] if resync else nop in KNOWN_OPS
    if not allowed or end + 9 + nlen > len(buf):
        return None
    return op, length, parsed


def resync(buf, start: int, limit: int, hints=()) -> int | None:
    """The first position >= start where a well-formed record (not a Message) begins, or None.

    hints: positions known to hold records (the summary's chunk index), tried with the rest.
    Candidates are found vectorised: an opcode byte followed by a length that fits the file.
    """
    if start + 9 > limit:
        return None
    arr = np.frombuffer(buf, np.uint8, count=limit)
    seg = arr[start : limit - 8]
    cand = np.flatnonzero(_RESYNC_OPS[seg]) + start
    if cand.size:
        lengths = sliding_window_view(arr, 8)[cand + 1].copy().view("<u8")[:, 0]
        room = (limit - 9 - cand).astype(np.uint64)
        cand = cand[lengths <= room]
    order = sorted(set(cand.tolist()) | {h for h in hints if start <= h < limit})
    for p in order:
        if check_record(buf, p, limit, resync=True) is not None:
            return p
    return None


@dataclass
class Summary:
    """The summary section, trusted only when its CRC (if any) matches and every record parses.

    Chunk indexes (one per chunk, the bulk of the summary) are parsed when first asked for:
    an intact file never needs them.
    """

    start: int
    buf: object = None
    channels: dict[int, Channel] = field(default_factory=dict)
    schemas: dict[int, Schema] = field(default_factory=dict)
    statistics: Statistics | None = None
    metadata_indexes: list[MetadataIndex] = field(default_factory=list)
    data_end: int | None = None  # position of the DataEnd record, just before the summary
    data_crc: int = 0
    _chunk_index_at: list[tuple[int, int]] = field(default_factory=list)
    _chunk_indexes: list[ChunkIndex] | None = None

    @property
    def chunk_indexes(self) -> list[ChunkIndex]:
        if self._chunk_indexes is None:
            parsed = [parse_record(ChunkIndex, self.buf, p + 9, n) for p, n in self._chunk_index_at]
            self._chunk_indexes = [ci for ci in parsed if ci is not None]
        return self._chunk_indexes


def read_footer(buf) -> tuple[int, int, int] | None:
    """(footer position, summary start, summary crc) if the file ends with a footer and magic."""
    n = len(buf)
    pos = n - 8 - FOOTER_BYTES
    if pos < 8 or bytes(buf[n - 8 :]) != MAGIC:
        return None
    op, length, summary_start, _offsets, crc = _FOOTER.unpack_from(buf, pos)
    if op != Opcode.FOOTER or length != 20:
        return None
    return pos, summary_start, crc


def read_summary(buf, footer: tuple[int, int, int] | None, warnings: list[str]) -> Summary | None:
    if footer is None:
        return None
    pos, start, crc = footer
    if start == 0:
        return None  # a finished file written without a summary
    if not 8 < start <= pos:
        warnings.append(f"the footer's summary offset {start} is outside the file: summary ignored")
        return None
    if crc and zlib.crc32(buf[start : pos + 25]) != crc:
        warnings.append("the summary section fails its CRC: summary ignored, the data section read in order")
        return None
    out = Summary(start, buf)
    p = start
    while p < pos:
        if crc:  # CRC-checked: the record framing is as written, chunk indexes can wait
            if p + 9 > pos:
                break
            op, length = RECORD_HEAD.unpack_from(buf, p)
            if p + 9 + length > pos:
                warnings.append(f"summary record at byte {p} overruns the summary: summary ignored")
                return None
            if op == Opcode.CHUNK_INDEX:
                out._chunk_index_at.append((p, length))
                p += 9 + length
                continue
            parsed = parse_record(_PARSERS[op], buf, p + 9, length) if op in _PARSERS else True
        else:
            rec = check_record(buf, p, pos)
            op, length, parsed = rec if rec is not None else (None, 0, None)
        if parsed is None:
            warnings.append(f"summary record at byte {p} is malformed: summary ignored")
            return None
        if op == Opcode.SCHEMA:
            out.schemas[parsed.id] = parsed
        elif op == Opcode.CHANNEL:
            out.channels[parsed.id] = parsed
        elif op == Opcode.CHUNK_INDEX:
            out._chunk_index_at.append((p, length))
        elif op == Opcode.STATISTICS:
            out.statistics = parsed
        elif op == Opcode.METADATA_INDEX:
            out.metadata_indexes.append(parsed)
        p += 9 + length
    d = start - 13  # DataEnd: opcode, length 4, data-section CRC
    if d >= 8 and RECORD_HEAD.unpack_from(buf, d) == (Opcode.DATA_END, 4):
        out.data_end = d
        (out.data_crc,) = struct.unpack_from("<I", buf, d + 9)
    return out


__all__ = [
    "MAGIC",
    "ChunkHead",
    "Summary",
    "check_record",
    "parse_chunk_head",
    "parse_record",
    "read_footer",
    "read_summary",
    "resync",
]
