"""SessionWriter: one MCAP file per trial, written crash-safely as data arrives."""

from __future__ import annotations

import math
import os
import struct
from pathlib import Path

import cv2
import numpy as np
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform as FrameTransformMsg
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import CompressionType, Writer

import layerskin_exp
from layerskin_exp.log.container.lock import WriterLock
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.session.epoch import session_offset_ns
from layerskin_exp.log.session.metacheck import with_check
from layerskin_exp.log.view import frame_tree as F

# Imported with the writer, not where the layout is written: foxglove.layouts takes ~35 ms to
# import with the interpreter lock held, and at the first trial's close that starved the loopback
# emulators (in this process) past their 50 ms stream deadlines.
from layerskin_exp.log.view.layout import app_layout, session_layout
from layerskin_exp.sync import estimate_clock_map
from layerskin_exp.types import (
    SKIN_SHAPE,
    FrameTransform,
    GripperState,
    MarkerDetection,
    Pose,
    ProtocolEvent,
    SkinEstimate,
    StagePosition,
    TwoLayerFrame,
    Wrench,
)

# Chunk compression default, from benchmarks/log_write.py and log_read.py (10 min of noisy 12-bit
# frames at 424 Hz, 2-core machine): lz4 writes ~290x real time, reads ~540 k pairs/s, 266 MB;
# zstd (the mcap Writer's fixed level 3) ~200x, ~400 k/s, 191 MB; none ~400x, ~680 k/s, 304 MB.
# Noise leaves the frames hard to compress, and zstd-3 alone costs ~1.5 s of the 3 s budget for
# 200x real time. lz4 keeps writing and reading fast at +39 % size over zstd (~27 MB per minute
# of skin data; a 900-trial campaign of 30 s trials ~12 GB): the trade taken. Pass
# compression="zstd" where disk matters more than speed; the reader handles all three.
DEFAULT_COMPRESSION = "lz4"
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
_U32_MAX = 2**32 - 1
_U64_MAX = 2**64 - 1
_LE_U16 = np.dtype("<u2")
_SKIN_PAIR_BYTES = 2 * (len(S.skin_head(0)) + S.SKIN_DATA_BYTES + 12 + 31)
# An MCAP Message record: opcode, record length, channel id, sequence, log time, publish time,
# then the payload (MCAP spec, "Message (op=0x05)"); 31 bytes before the payload.
_MESSAGE = struct.Struct("<BQHIQQ")
_MESSAGE_OP = int(Opcode.MESSAGE)
_MESSAGE_FIXED = _MESSAGE.size - 9  # record length = 22 + payload length


class _PackedMessageIndex(MessageIndex):
    """mcap.records.MessageIndex whose records are an (N, 2) uint64 array (log_time, offset),
    written with one bytes call instead of two per message. Same bytes as MessageIndex.write."""

    def write(self, stream) -> None:
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(self.records) * 16)
        stream.write(np.ascontiguousarray(self.records, dtype="<u8").tobytes())
        stream.finish_record()


class _OpenChunk:
    """Bulk access to the chunk an mcap Writer has open, so a whole chunk's messages go in with
    a few calls instead of one Writer.add_message (~5 us of Python) per message.

    mcap 1.x keeps the open chunk (a ChunkBuilder) and the file statistics in private
    attributes of Writer. They are used here only to do what Writer.add_message does, for many
    messages at once: append the serialized Message records to the chunk, its message indexes,
    its time range and message count, and the file statistics. Compression, CRCs, chunk and
    summary records stay the library's (Writer.flush / finish). tests/log/test_mcap_bulk.py
    checks that a file written this way is byte-identical to one written with add_message;
    if a library release changes these internals, attach() returns None and the writer falls
    back to Writer.add_message (same file, slower).
    """

    def __init__(self, builder, stats) -> None:
        self.builder = builder
        self.stats = stats

    @classmethod
    def attach(cls, writer: Writer) -> _OpenChunk | None:
        builder = getattr(writer, "_Writer__chunk_builder", None)
        stats = getattr(writer, "_Writer__statistics", None)
        needed_b = (
            "record_writer",
            "message_indices",
            "num_messages",
            "message_start_time",
            "message_end_time",
        )
        needed_s = ("message_count", "channel_message_counts", "message_start_time", "message_end_time")
        if builder is None or stats is None:
            return None
        if not all(hasattr(builder, a) for a in needed_b) or not all(hasattr(stats, a) for a in needed_s):
            return None
        if not hasattr(builder.record_writer, "count") or not hasattr(builder.record_writer, "write"):
            return None
        return cls(builder, stats)

    def add(self, records: list[bytes], channels: list[int], log_times: list[int]) -> None:
        """Append serialized Message records (in order) to the open chunk."""
        b, st = self.builder, self.stats
        n = len(records)
        lengths = np.fromiter(map(len, records), np.uint64, n)
        offsets = np.empty(n, np.uint64)
        offsets[0] = b.record_writer.count
        np.cumsum(lengths[:-1], out=offsets[1:])
        offsets[1:] += offsets[0]
        b.record_writer.write(b"".join(records))
        t = np.array(log_times, np.uint64)
        ch = np.array(channels, np.uint16)
        lo, hi = min(log_times), max(log_times)
        b.message_start_time = lo if b.num_messages == 0 else min(b.message_start_time, lo)
        b.message_end_time = max(b.message_end_time, hi)
        b.num_messages += n
        st.message_start_time = lo if st.message_count == 0 else min(st.message_start_time, lo)
        st.message_end_time = max(st.message_end_time, hi)
        st.message_count += n
        ids, first = np.unique(ch, return_index=True)
        for cid in ids[np.argsort(first)].tolist():  # first-seen order, as add_message makes it
            sel = ch == cid
            rows = np.stack([t[sel], offsets[sel]], axis=1)
            index = b.message_indices.get(cid)
            if index:
                rows = np.concatenate([np.asarray(index.records, np.uint64).reshape(-1, 2), rows])
            b.message_indices[cid] = _PackedMessageIndex(channel_id=cid, records=rows)
            st.channel_message_counts[cid] += rows.shape[0] - (len(index.records) if index else 0)


class SessionClosedError(RuntimeError):
    """A record was written to a SessionWriter that is already closed."""


class SessionWriter:
    """Write one trial to an MCAP file.

    path: the .mcap file to create (refused if it exists, unless overwrite=True). The writer
        holds an exclusive OS lock on it until close: a second SessionWriter on the same path
        raises SessionInUseError naming the live owner (pid, host, start time), even with
        overwrite=True. overwrite=True replaces only a file no live writer holds (e.g. the
        .partial left by a crashed run).
    metadata: {"config": dict, "backend": str, "calibration": dict, ...}; dict values become
        their own MCAP metadata records, other values go into the "session" record.
    labels: trial labels (position index, direction, grip depth, motion, trial index, ...).
    compression: "lz4" (default, see DEFAULT_COMPRESSION), "zstd" or "none", per chunk.
    chunk_span_ns / chunk_bytes: a chunk is closed and handed to the OS as soon as it spans
        chunk_span_ns of log (host) time or holds chunk_bytes, so a kill loses at most that
        much data. Protocol events are flushed at once.
    epoch_offset_ns: MCAP log_time and Foxglove timestamps are host_t_ns + this (Unix ns);
        None chooses it from the metadata's backend (see layerskin_exp.log.session.epoch).
    epoch_how: how a given epoch_offset_ns was chosen (stored with it in the "log_time" record).

    Use as a context manager: an exception inside closes the file with outcome
    "aborted: <Type: message>" (KeyboardInterrupt -> "aborted: interrupted") and propagates.
    """

    def __init__(
        self,
        path,
        metadata: dict | None = None,
        labels: dict | None = None,
        *,
        compression: str = DEFAULT_COMPRESSION,
        chunk_span_ns: int = 100_000_000,
        chunk_bytes: int = 1 << 20,
        overwrite: bool = False,
        epoch_offset_ns: int | None = None,
        epoch_how: str = "given",
    ) -> None:
        if compression not in _COMPRESSION:
            raise ValueError(f"compression={compression!r}: use one of {sorted(_COMPRESSION)}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # Exclusive: a live writer holds an OS lock on its file; a second one is refused before it
        # can truncate anything (see lock.py). A stale file nobody holds is replaced if overwrite.
        self._lock = WriterLock.acquire(self.path, overwrite=overwrite)
        # The file object owns the locked descriptor: closing it (or losing it) drops the lock.
        self._file = _NamedFile(_open_fd(self._lock.fd), self)
        try:
            self._start(metadata or {}, labels or {}, compression, chunk_span_ns, chunk_bytes, epoch_offset_ns,
                        epoch_how)
        except BaseException:
            # Refused metadata, or a failing disk: give the file and its lock back at once.
            self._lock.forget_owner()
            self._file.close()
            raise
        self._dispatch = {
            TwoLayerFrame: self.write_frame,
            Wrench: self.write_wrench,
            StagePosition: self.write_stage,
            Pose: self.write_pose,
            GripperState: self.write_gripper,
            MarkerDetection: self.write_marker,
            ProtocolEvent: self.write_event,
            FrameTransform: self.write_transform,
            SkinEstimate: self.write_estimate,
        }
        # A live view (layerskin_exp.live.LiveView) sees a decimated copy of what is written.
        self.live = None

    def _start(self, metadata: dict, labels: dict, compression: str, chunk_span_ns: int, chunk_bytes: int,
               epoch_offset_ns: int | None, epoch_how: str) -> None:
        how = epoch_how
        if epoch_offset_ns is None:
            epoch_offset_ns, how = session_offset_ns(metadata)
        if not 0 <= int(epoch_offset_ns) <= _U64_MAX:
            raise ValueError(f"epoch_offset_ns={epoch_offset_ns}: must be Unix ns in 0..{_U64_MAX}")
        # host_t_ns + this = MCAP log_time and Foxglove timestamp (Unix ns); see session/epoch.py
        self.epoch_offset_ns = int(epoch_offset_ns)
        self._epoch_how = how
        self._mcap = Writer(
            self._file,
            chunk_size=1 << 40,  # chunks are closed here, by span and size, not by the library
            compression=_COMPRESSION[compression],
            # The data-section CRC lets the reader tell an intact file from one whose metadata or
            # indexes (outside the CRC-checked chunks) were damaged.
            enable_data_crcs=True,
        )
        self._mcap.start(profile="", library=f"layerskin-exp/{layerskin_exp.__version__}")
        self._chunk_span_ns = int(chunk_span_ns)
        self._chunk_bytes = int(chunk_bytes)
        self._chunk_start_ns: int | None = None
        self._chunk_fill = 0
        # The open chunk's messages, serialized, until the chunk is closed (see flush).
        self._pending: list[bytes] = []
        self._pending_channel: list[int] = []
        self._pending_log: list[int] = []
        self._bulk = _OpenChunk.attach(self._mcap)
        self._closed = False
        self.outcome: str | None = None
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        # Per-stream (device_t, host_t) pairs for the clock map computed at close.
        self._clock_pairs: dict[str, tuple[list[int], list[int]]] = {}
        # Host-side records (events, transforms, views) have no device sequence number: each
        # channel numbers its own, so two writes of one record at one time are two messages, never
        # an exact repeat the reader drops as a chunk present twice.
        self._host_seq: dict[int, int] = {}
        self._write_metadata(metadata, labels)
        skin = {
            layer: self._channel(topic, RawImage, {"stream": "skin", "layer": layer})
            for layer, topic in S.SKIN_TOPICS.items()
        }
        self._skin_sup, self._skin_deep = skin["superficial"], skin["deep"]
        self._skin_dev, self._skin_host = self._clock("skin")

    # ------------------------------------------------------------------ set-up

    def _write_metadata(self, metadata: dict, labels: dict) -> None:
        session = {
            "format": S.FORMAT,
            "format_version": S.FORMAT_VERSION,
            "version": layerskin_exp.__version__,
        }
        records = {}
        for key, value in metadata.items():
            if hasattr(value, "items"):
                records[str(key)] = value
            else:
                session[str(key)] = value
        reserved = {S.META_SESSION, S.META_LABELS, S.META_OUTCOME, S.META_CLOCK_SYNC, S.META_RECOVERED,
                    S.META_LAYOUT, S.META_LOG_TIME, S.META_STREAM_HEALTH}
        clash = reserved & set(records)
        if clash:
            raise ValueError(f"metadata keys {sorted(clash)} are reserved by the session log; rename them")
        self._add_metadata(S.META_SESSION, session)
        self._add_metadata(S.META_LOG_TIME, {"epoch": "unix", "offset_ns": self.epoch_offset_ns,
                                             "chosen": self._epoch_how})
        for name, value in records.items():
            self._add_metadata(name, value)
        self._add_metadata(S.META_LABELS, labels)

    def _add_metadata(self, name: str, values) -> None:
        # MCAP metadata maps str -> str: each value is stored as JSON so types come back.
        items = values.items() if hasattr(values, "items") else values
        self._mcap.add_metadata(name, with_check(name, {str(k): S.dumps(v).decode() for k, v in items}))
        self._file.flush()

    def _schema(self, name: str) -> int:
        sid = self._schemas.get(name)
        if sid is None:
            sid = self._mcap.register_schema(name, "protobuf", S.proto_schema_data(S.proto_class(name)))
            self._schemas[name] = sid
        return sid

    def _channel(self, topic: str, schema, meta: dict) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            # Close the open chunk first, so channel records always start a chunk: the reader
            # finds them without walking every message.
            self.flush()
            name = S.proto_class(schema).DESCRIPTOR.full_name
            cid = self._mcap.register_channel(topic, "protobuf", self._schema(name), meta)
            self._channels[topic] = cid
        return cid

    def _clock(self, stream: str) -> tuple[list[int], list[int]]:
        pairs = self._clock_pairs.get(stream)
        if pairs is None:
            pairs = self._clock_pairs[stream] = ([], [])
        return pairs

    # ------------------------------------------------------------------ low-level add

    def _check_open(self) -> None:
        if self._closed:
            raise SessionClosedError(
                f"session {self.path} is closed (outcome {self.outcome!r}); open a new SessionWriter"
            )

    def _check_times(self, host_t_ns: int, device_t_ns: int, seq: int) -> None:
        if not (0 <= host_t_ns <= _U64_MAX - self.epoch_offset_ns and 0 <= device_t_ns <= _U64_MAX):
            raise ValueError(
                f"times must be non-negative ns (MCAP stores u64): host_t_ns={host_t_ns}, "
                f"device_t_ns={device_t_ns}"
            )
        if not 0 <= seq <= _U32_MAX:
            raise ValueError(f"sequence number {seq} does not fit MCAP's u32 sequence field")

    def _next_seq(self, channel: int) -> int:
        """The next sequence number of a host-side channel (0, 1, 2, ... wrapping at 2**32)."""
        seq = self._host_seq.get(channel, 0)
        self._host_seq[channel] = (seq + 1) & _U32_MAX
        return seq

    def _add(self, channel: int, host_t_ns: int, device_t_ns: int, seq: int, payload: bytes) -> None:
        self._check_times(host_t_ns, device_t_ns, seq)
        log_t = host_t_ns + self.epoch_offset_ns
        self._pending.append(
            _MESSAGE.pack(_MESSAGE_OP, _MESSAGE_FIXED + len(payload), channel, seq, log_t, device_t_ns)
            + payload
        )
        self._pending_channel.append(channel)
        self._pending_log.append(log_t)
        start = self._chunk_start_ns
        if start is None:
            self._chunk_start_ns = start = log_t
        self._chunk_fill += len(payload) + 31
        if log_t - start >= self._chunk_span_ns or self._chunk_fill >= self._chunk_bytes:
            self.flush()

    def unix_ns(self, host_t_ns: int) -> int:
        """The MCAP log_time / Foxglove timestamp of a message received at host_t_ns."""
        return int(host_t_ns) + self.epoch_offset_ns

    def flush(self) -> None:
        """Close the open chunk and hand everything written so far to the OS."""
        if self._pending:
            records, channels, logs = self._pending, self._pending_channel, self._pending_log
            self._pending, self._pending_channel, self._pending_log = [], [], []
            if self._bulk is not None:
                self._bulk.add(records, channels, logs)
            else:
                add = self._mcap.add_message
                for rec in records:
                    _, _, cid, seq, log, pub = _MESSAGE.unpack_from(rec)
                    add(cid, log, rec[_MESSAGE.size :], pub, seq)
        self._mcap.flush()
        self._chunk_start_ns, self._chunk_fill = None, 0

    # ------------------------------------------------------------------ records

    def write(self, record) -> None:
        """Write one record, dispatching on its type (see layerskin_exp.types)."""
        self._check_open()
        method = self._dispatch.get(type(record))
        if method is None:
            raise TypeError(
                f"SessionWriter.write cannot log a {type(record).__name__}; expected one of "
                f"{', '.join(t.__name__ for t in self._dispatch)}"
            )
        method(record)

    def write_frame(self, frame: TwoLayerFrame) -> None:
        """Both layers as foxglove.RawImage mono16 on /skin/superficial and /skin/deep.

        The hot path (424 Hz): payload bytes are assembled directly (see schema.skin_head).
        """
        if self._closed:
            self._check_open()
        sup, deep = frame.superficial, frame.deep
        if not (type(sup) is np.ndarray and sup.dtype == _LE_U16 and sup.shape == SKIN_SHAPE):
            sup = _skin_array(sup, "superficial")
        if not (type(deep) is np.ndarray and deep.dtype == _LE_U16 and deep.shape == SKIN_SHAPE):
            deep = _skin_array(deep, "deep")
        dev, host, seq = int(frame.device_t_ns), int(frame.host_t_ns), int(frame.seq)
        if dev < 0 or host < 0 or not 0 <= seq <= _U32_MAX:
            self._check_times(host, dev, seq)
        t = host + self.epoch_offset_ns  # log time = Foxglove time (see session/epoch.py)
        head = S.skin_head(t)
        size = _MESSAGE_FIXED + len(head) + S.SKIN_DATA_BYTES
        pack = _MESSAGE.pack
        sup_id, deep_id = self._skin_sup, self._skin_deep
        self._pending += (
            pack(_MESSAGE_OP, size, sup_id, seq, t, dev) + head + sup.tobytes(),
            pack(_MESSAGE_OP, size, deep_id, seq, t, dev) + head + deep.tobytes(),
        )
        self._pending_channel += (sup_id, deep_id)
        self._pending_log += (t, t)
        self._skin_dev.append(dev)
        self._skin_host.append(host)
        if self.live is not None:
            self.live.frame(frame, head, t)
        start = self._chunk_start_ns
        if start is None:
            self._chunk_start_ns = start = t
        self._chunk_fill += _SKIN_PAIR_BYTES
        if t - start >= self._chunk_span_ns or self._chunk_fill >= self._chunk_bytes:
            self.flush()

    def _write_message(
        self,
        topic: str,
        schema: str,
        stream: str,
        host: int,
        dev: int,
        seq: int,
        body: dict,
        meta: dict | None = None,
    ) -> None:
        """One of the session's own messages (schema: its name in messages.py), body its fields."""
        channel = self._channel(topic, schema, {"stream": stream, **(meta or {})})
        payload = S.encode(schema, body, host + self.epoch_offset_ns)
        self._add(channel, host, dev, seq, payload)
        if self.live is not None:
            self.live.message(topic, schema, payload, host + self.epoch_offset_ns)
        pairs = self._clock(stream)
        pairs[0].append(dev)
        pairs[1].append(host)

    def write_wrench(self, w: Wrench) -> None:
        self._check_open()
        host, dev, seq = int(w.host_t_ns), int(w.device_t_ns), int(w.seq)
        body = {
            "host_t_ns": host,
            "device_t_ns": dev,
            "seq": seq,
            "status": int(w.status),
            "force_n": _vec(w.force_n, 3, "force_n"),
            "torque_nm": _vec(w.torque_nm, 3, "torque_nm"),
        }
        self._write_message(S.WRENCH_TOPIC, "layerskin.Wrench", "wrench", host, dev, seq, body)

    def write_estimate(self, e: SkinEstimate) -> None:
        """A live estimate: the force on /estimate/force (reader stream "estimate_force"), the slip
        score and flag on /estimate/slip ("estimate_slip") when there is a score; seq = frame."""
        self._check_open()
        host, dev, seq = int(e.host_t_ns), int(e.device_t_ns), int(e.frame)
        times = {"host_t_ns": host, "device_t_ns": dev, "seq": seq}
        body = {**times, "force_n": _vec(e.force_n, 3, "force_n")}
        self._write_message(S.ESTIMATE_FORCE_TOPIC, "layerskin.ForceEstimate", "estimate_force", host, dev, seq, body)
        if e.slip_score is not None:
            body = {**times, "score": float(e.slip_score), "slip": bool(e.slip)}
            self._write_message(S.ESTIMATE_SLIP_TOPIC, "layerskin.SlipEstimate", "estimate_slip", host, dev, seq, body)

    def write_stage(self, p: StagePosition) -> None:
        self._check_open()
        host, dev, seq = int(p.host_t_ns), int(p.device_t_ns), int(p.seq)
        body = {
            "host_t_ns": host,
            "device_t_ns": dev,
            "seq": seq,
            "position_mm": _vec(p.position_mm, 3, "position_mm"),
        }
        self._write_message(S.STAGE_TOPIC, "layerskin.StagePosition", "stage", host, dev, seq, body)
        # The stage carries the indenter, its position given in the skin (= base) frame.
        self._derived_transform(F.BASE, F.TOOL, np.asarray(body["position_mm"], float) * 1e-3, F.IDENTITY, host)

    def write_gripper(self, g: GripperState) -> None:
        self._check_open()
        host, dev, seq = int(g.host_t_ns), int(g.device_t_ns), int(g.seq)
        body = {
            "host_t_ns": host,
            "device_t_ns": dev,
            "seq": seq,
            "position_mm": float(g.position_mm),
            "requested_mm": float(g.requested_mm),
            "speed": int(g.speed),
            "force": int(g.force),
            "object_detected": bool(g.object_detected),
            "fault": int(g.fault),
        }
        self._write_message(S.GRIPPER_TOPIC, "layerskin.GripperState", "gripper", host, dev, seq, body)

    def write_pose(self, pose: Pose, topic: str = S.TCP_TOPIC) -> None:
        """A pose as foxglove.PoseInFrame. Default topic /arm/tcp (reader stream "tcp");
        other topics appear in the reader under their topic name."""
        self._check_open()
        stream = "tcp" if topic == S.TCP_TOPIC else topic
        self._write_pose(pose, topic, stream, {}, int(pose.seq), int(pose.device_t_ns), int(pose.host_t_ns))
        if topic == S.TCP_TOPIC:  # the TCP pose in its frame is where the tool frame is
            self._derived_transform(pose.frame_id, F.TOOL, pose.position_m, pose.orientation_xyzw,
                                    int(pose.host_t_ns))

    def _write_pose(self, pose: Pose, topic: str, stream: str, meta: dict, seq: int, dev: int, host: int):
        channel = self._channel(topic, PoseInFrame, {"stream": stream, **meta})
        payload = S.pose_payload(
            _vec(pose.position_m, 3, "position_m"),
            _vec(pose.orientation_xyzw, 4, "orientation_xyzw"),
            pose.frame_id,
            host + self.epoch_offset_ns,
        )
        self._add(channel, host, dev, seq, payload)
        if self.live is not None:
            self.live.message(topic, PoseInFrame, payload, host + self.epoch_offset_ns)
        pairs = self._clock(stream)
        pairs[0].append(dev)
        pairs[1].append(host)

    def write_marker(self, m: MarkerDetection) -> None:
        """Marker pose as PoseInFrame on /markers/<id> (for Foxglove), and the detection itself
        (image corners, frame sequence) as layerskin.MarkerDetection on /markers/<id>/detection."""
        self._check_open()
        mid, host, dev, seq = int(m.marker_id), int(m.host_t_ns), int(m.device_t_ns), int(m.frame_seq)
        meta = {"marker_id": str(mid)}
        corners = np.asarray(m.corners_px, dtype=np.float64)
        if corners.shape != (4, 2):
            raise ValueError(f"marker {mid}: corners_px has shape {corners.shape}, expected (4, 2)")
        self._write_pose(
            m.pose, S.marker_pose_topic(mid), "markers", {**meta, "part": "pose"}, seq, dev, host
        )
        body = {
            "host_t_ns": host,
            "device_t_ns": dev,
            "marker_id": mid,
            "frame_seq": seq,
            "corners_px": corners.tolist(),
        }
        channel = self._channel(
            S.marker_detection_topic(mid),
            "layerskin.MarkerDetection",
            {"stream": "markers", **meta, "part": "detection"},
        )
        self._add(channel, host, dev, seq, S.encode("layerskin.MarkerDetection", body, host + self.epoch_offset_ns))
        self._derived_transform(m.pose.frame_id, F.marker_frame(mid), m.pose.position_m, m.pose.orientation_xyzw,
                                host)

    def write_transform(self, tf: FrameTransform) -> None:
        """A foxglove.FrameTransform on /tf (reader stream "transforms")."""
        self._check_open()
        self._transform(tf.parent_frame_id, tf.child_frame_id, tf.translation_m, tf.rotation_xyzw, int(tf.host_t_ns))

    def _derived_transform(self, parent: str, child: str, translation_m, rotation_xyzw, host: int) -> None:
        t, q = _vec(translation_m, 3, "translation_m"), _vec(rotation_xyzw, 4, "rotation_xyzw")
        if None in t or None in q:
            return  # a pose with NaN (lost tracking) has its own record; no frame to place
        self._transform(parent, child, t, q, host)

    def _transform(self, parent: str, child: str, translation_m, rotation_xyzw, host: int) -> None:
        channel = self._channel(S.TF_TOPIC, FrameTransformMsg, {"stream": "transforms"})
        t = host + self.epoch_offset_ns
        payload = S.transform_payload(parent, child, _vec(translation_m, 3, "translation_m"),
                                      _vec(rotation_xyzw, 4, "rotation_xyzw"), t)
        self._add(channel, host, host, self._next_seq(channel), payload)
        if self.live is not None:
            self.live.message(S.TF_TOPIC, FrameTransformMsg, payload, t, key=child)

    def write_view(self, topic: str, schema, payload, host_t_ns: int) -> None:
        """A message for Foxglove only, derived from data a stream already holds (image
        annotations, display-rate skin summaries): schema is a Foxglove protobuf class or the name
        of one of the session's own messages (schema.PROTO_CLASSES). payload: bytes, or payload(t_ns) -> bytes for a
        message that carries its own Foxglove timestamp (given the message's Unix log time).
        The reader skips these channels."""
        self._check_open()
        host = int(host_t_ns)
        t = host + self.epoch_offset_ns
        if callable(payload):
            payload = payload(t)
        channel = self._channel(topic, schema, {"view": "foxglove"})
        self._add(channel, host, host, self._next_seq(channel), payload)
        if self.live is not None:
            self.live.message(topic, schema, payload, t)

    def write_event(self, e: ProtocolEvent) -> None:
        """Protocol events are rare and matter most after a crash: flushed at once."""
        self._check_open()
        host, dev = int(e.host_t_ns), int(e.device_t_ns)
        kind, message, detail = str(e.kind), str(e.message), dict(e.detail)
        body = {"host_t_ns": host, "device_t_ns": dev, "kind": kind, "message": message,
                "detail_json": S.dumps(detail).decode()}
        t = host + self.epoch_offset_ns
        channel = self._channel(S.EVENTS_TOPIC, "layerskin.ProtocolEvent", {"stream": "events"})
        self._add(channel, host, dev, self._next_seq(channel), S.encode("layerskin.ProtocolEvent", body, t))
        # The same event for Foxglove's Log panel.
        log_channel = self._channel(S.LOG_TOPIC, Log, {"view": "foxglove"})
        log_payload = S.log_payload(kind, message, detail, t)
        self._add(log_channel, host, host, self._next_seq(log_channel), log_payload)
        if self.live is not None:
            self.live.message(S.LOG_TOPIC, Log, log_payload, t, key=None)
        self.flush()

    def write_image(self, gray_uint8: np.ndarray, device_t_ns: int, host_t_ns: int, seq: int = 0,
                    detections=()) -> None:
        """A camera image (H, W) uint8 (or (H, W, 3) BGR) as a PNG foxglove.CompressedImage.

        detections: the MarkerDetections found in this image; their outlines go on
        /camera/markers as foxglove.ImageAnnotations with the image's timestamp.
        """
        self._check_open()
        img = np.asarray(gray_uint8)
        if img.dtype != np.uint8 or img.ndim not in (2, 3):
            raise ValueError(
                f"write_image needs an (H, W) or (H, W, 3) uint8 image, got {img.dtype} {img.shape}"
            )
        ok, png = cv2.imencode(".png", img)
        if not ok:
            raise ValueError(f"could not PNG-encode an image of shape {img.shape}")
        msg = CompressedImage(format="png", frame_id=S.CAMERA_FRAME, data=png.tobytes())
        msg.timestamp.FromNanoseconds(int(host_t_ns) + self.epoch_offset_ns)
        channel = self._channel(S.CAMERA_TOPIC, CompressedImage, {"stream": "camera"})
        self._add(channel, int(host_t_ns), int(device_t_ns), int(seq), msg.SerializeToString())
        pairs = self._clock("camera")
        pairs[0].append(int(device_t_ns))
        pairs[1].append(int(host_t_ns))
        if detections:
            outlines = [np.asarray(d.corners_px, float) for d in detections]
            self.write_view(S.CAMERA_MARKERS_TOPIC, ImageAnnotations,
                            lambda t: S.outlines_payload(outlines, t), int(host_t_ns))

    # ------------------------------------------------------------------ closing

    @property
    def closed(self) -> bool:
        return self._closed

    def clock_maps(self) -> dict:
        """Per-stream clock maps from the pairs written so far: {stream: ClockMap}."""
        return {
            stream: estimate_clock_map(np.asarray(d, np.int64), np.asarray(h, np.int64))
            for stream, (d, h) in self._clock_pairs.items()
            if d
        }

    def _write_layout(self) -> None:
        """The Foxglove layout of the topics written (see view/layout.py), in the SDK's form and
        in the app's import form; a layout that cannot be built is left out, never the session."""
        try:
            layout = session_layout(self._channels)
        except ValueError:  # nothing written that a panel could show
            return
        self._mcap.add_metadata(S.META_LAYOUT, {"": layout.to_json()})
        self._mcap.add_metadata(S.META_LAYOUT_APP, {"": S.dumps(app_layout(layout)).decode()})

    def close(self, outcome: str = "complete", *, move_to=None, stream_health: dict | None = None) -> None:
        """Record the clock sync, the Foxglove layout of what was written, the stream health and
        the outcome ("complete", "complete (<note>)", e.g. a safety stop the trial finished after,
        "incomplete: <reason>", a trial that ran to its end with data missing, e.g. more lost
        frames than allowed, or "aborted: <reason>"), write the MCAP summary and close the file.
        Closing twice is a no-op.

        move_to: rename the finished file to this path (atomically, fsynced) while the lock is
        still held, so no other writer can claim the old name between closing and renaming.
        stream_health: {device: {counter: int}}, what each device's driver counted over the trial
        (protocols.runner.trial_health); stored as the checked "stream_health" record, one field
        per device.
        """
        if self._closed:
            return
        if not (outcome == "complete" or outcome.startswith(("complete (", "incomplete: ", "aborted"))):
            raise ValueError(f"outcome {outcome!r}: use 'complete', 'complete (<note>)', 'incomplete: <reason>' "
                             "or 'aborted: <reason>'")
        try:
            self.flush()
            try:
                maps = {k: m.to_dict() for k, m in self.clock_maps().items()}
            except Exception as exc:  # never lose the session over a failed fit
                maps = {"error": f"{type(exc).__name__}: {exc}"}
            self._add_metadata(S.META_CLOCK_SYNC, maps)
            if stream_health is not None:
                self._add_metadata(S.META_STREAM_HEALTH, stream_health)
            self._write_layout()
            self._add_metadata(S.META_OUTCOME, {"outcome": outcome})
            self._mcap.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            if move_to is not None:
                self.path = self._lock.move(move_to)
        finally:
            self._lock.forget_owner()
            self._closed = True
            self.outcome = outcome
            self._file.close()  # drops the lock (and raises, naming the file, if the last bytes did not fit)

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            self.close("complete")
        elif issubclass(exc_type, KeyboardInterrupt):
            self.close("aborted: interrupted")
        else:
            self.close(f"aborted: {exc_type.__name__}: {exc}")
        return False


def _open_fd(fd: int):
    """The buffered file over the writer's locked descriptor."""
    return os.fdopen(fd, "wb")


class _NamedFile:
    """The writer's file: a failed write, flush or close (a full disk, a lost mount) raises an
    OSError that names the file being written, whichever record the failure came with."""

    def __init__(self, raw, writer: SessionWriter) -> None:
        self._raw, self._writer = raw, writer

    def _failed(self, exc: OSError) -> OSError:
        return OSError(exc.errno, exc.strerror or str(exc), str(self._writer.path))

    def write(self, data) -> int:
        try:
            return self._raw.write(data)
        except OSError as exc:
            raise self._failed(exc) from None

    def flush(self) -> None:
        try:
            self._raw.flush()
        except OSError as exc:
            raise self._failed(exc) from None

    def close(self) -> None:
        try:
            self._raw.close()
        except OSError as exc:
            raise self._failed(exc) from None

    def __getattr__(self, name: str):  # fileno, tell, closed, ...: the file's own
        return getattr(self._raw, name)


def _skin_array(layer, name: str) -> np.ndarray:
    """Any (16, 16) array of counts -> little-endian uint16; refuses values that would wrap."""
    a = np.asarray(layer)
    if a.shape != SKIN_SHAPE:
        raise ValueError(f"{name} layer has shape {a.shape}, expected {SKIN_SHAPE}")
    if a.dtype.kind not in "uif" or (a.dtype.kind == "f" and not np.all(np.isfinite(a))):
        raise ValueError(f"{name} layer must hold finite ADC counts, got dtype {a.dtype}")
    if a.min() < 0 or a.max() > 65535 or (a.dtype.kind == "f" and np.any(a != np.rint(a))):
        raise ValueError(
            f"{name} layer has values that are not counts in 0..65535 (min {a.min()}, max {a.max()})"
        )
    return a.astype(_LE_U16)


def _vec(values, n: int, name: str) -> list[float]:
    if type(values) in (tuple, list) or (type(values) is np.ndarray and values.ndim == 1):
        out = [float(x) for x in values]  # the hot path (a wrench at 1 kHz): no array round trip
    else:
        out = np.asarray(values, dtype=np.float64).reshape(-1).tolist()
    if len(out) != n:
        raise ValueError(f"{name} has {len(out)} values, expected {n}")
    if not all(map(math.isfinite, out)):
        # None marks NaN (the session's messages store NaN, old JSON files null); the reader gives NaN. Never drop the sample.
        out = [x if math.isfinite(x) else None for x in out]
    return out
