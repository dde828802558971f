"""load_session: a session file -> numpy arrays per stream on one host timeline."""

from __future__ import annotations

import json
import warnings as _warnings
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from layerskin_exp.log.container.scan import ChannelMessages, Lost, McapScan, scan
from layerskin_exp.log.errors import SessionFileError
from layerskin_exp.log.session import messages as M
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.session.metacheck import check_records
from layerskin_exp.sync import ClockMap, estimate_clock_map
from layerskin_exp.types import SKIN_SHAPE


class SessionWarning(UserWarning):
    """A session file was damaged or incomplete; what could be read was read."""


@dataclass(frozen=True)
class LostRange:
    """Data a damaged file did not give back.

    start_ns / end_ns: host time span the lost messages lie in, the timeline of every stream's
        "host_t_ns" (log time - Session.epoch_offset_ns; None where nothing in the file bounds it);
    messages: messages lost per stream ("skin" counts both layers' messages), None if unknown;
    reason: what was damaged and where (byte offset).
    """

    start_ns: int | None
    end_ns: int | None
    messages: dict[str, int] | None
    reason: str

    def describe(self) -> str:
        span = (
            f"{self.start_ns} .. {self.end_ns} ns ({(self.end_ns - self.start_ns) / 1e6:.1f} ms)"
            if self.start_ns is not None and self.end_ns is not None
            else f"{self.start_ns if self.start_ns is not None else '?'} .. "
            f"{self.end_ns if self.end_ns is not None else '?'} ns"
        )
        msgs = "unknown messages" if self.messages is None else f"messages {self.messages}"
        return f"{span}, {msgs}: {self.reason}"


@dataclass
class Session:
    """One trial read back.

    streams: {name: {field: array}}; every stream has "t_ns" (N,) int64 on the common host
    timeline, "host_t_ns" and (except events) "device_t_ns" and "seq". See layerskin_exp.log.
    complete: the writer finished the file, recorded outcome "complete" (or "complete (<note>)",
        e.g. a safety stop the trial finished after), and nothing in the
        file is damaged (a damaged trial is never complete, whatever its outcome says).
    clock_sync: {stream: ClockMap} used for t_ns (from the file, or estimated on reading).
    lost: the data a damaged file did not give back (skipped chunks, records), see LostRange;
        everything else was read.
    damaged: any damage found, including damage that lost no messages (metadata, indexes).
    chunks_skipped: chunks that could not be read.
    repeats: exact repeats of a message dropped on reading (a chunk present twice), per stream;
        a file `recover` wrote says in its "recovered" record what it dropped.
    damaged_fields: metadata that failed its check or is missing, as "record.field" (a field) or
        "record" (a whole record missing); left out of metadata, labels, outcome and clock_sync.
    unchecked: metadata records stored without a check (files written before it existed): read
        as they are, neither vouched for nor damaged.
    epoch_offset_ns: MCAP log_time - host_t_ns, the session's place on the Unix epoch (0 for a
        file written before log times were Unix times, or whose "log_time" record is lost).
    stream_health: what each device's driver counted over the trial, {device: {"received",
        "lost", "duplicate", "out_of_order", "corrupt", "reconnects"[, "dropped"]: int}} (a device
        whose field fails its check is left out and named in damaged_fields); None for a file
        written before the counters were stored (or by a writer that did not close it).
    """

    path: Path
    metadata: dict
    labels: dict
    outcome: str | None
    complete: bool
    clock_sync: dict[str, ClockMap]
    streams: dict[str, dict]
    warnings: list[str] = field(default_factory=list)
    lost: list[LostRange] = field(default_factory=list)
    damaged: bool = False
    chunks_skipped: int = 0
    repeats: dict[str, int] = field(default_factory=dict)
    damaged_fields: list[str] = field(default_factory=list)
    unchecked: list[str] = field(default_factory=list)
    epoch_offset_ns: int = 0
    stream_health: dict[str, dict[str, int]] | None = None

    def unix_ns(self, host_t_ns):
        """Unix ns (the file's log time) of host times (int or array)."""
        return host_t_ns + self.epoch_offset_ns


def _decode_meta(values: dict) -> dict:
    out = {}
    for k, v in values.items():
        try:
            out[k] = json.loads(v)
        except ValueError:
            out[k] = v  # a plain string from another writer
    return out


def load_session(path, *, streams=None, warn: bool = True) -> Session:
    """Read a session file. Never raises on a damaged or truncated tail: reads up to the damage,
    reports it in Session.warnings (and as a SessionWarning unless warn=False).

    streams: names of the streams to decode (e.g. {"skin", "wrench"}); None decodes all. Streams
    not asked for are left out of Session.streams (names absent from the file are too).

    A damaged file is read around the damage: skipped chunks and records are listed in
    Session.lost with their time ranges, and the session is not complete.

    Raises SessionFileError (naming the file and the problem) for a missing, empty or non-MCAP
    file, an MCAP file that is not a layerskin session, or one with nothing readable in it.
    """
    path = Path(path)
    sc = scan(path)
    kept, damaged_fields, unchecked = check_records(sc.metadata, sc.has_footer)
    records = {name: _decode_meta(values) for name, values in kept}
    session_meta = records.get(S.META_SESSION, {})
    ours = any(c.metadata.get("stream") for c in sc.channels.values())
    if session_meta.get("format") != S.FORMAT and not sc.has_footer and not sc.channels:
        raise SessionFileError(
            f"{path}: cut off or damaged ({path.stat().st_size} bytes) before any session metadata or "
            f"data; there is nothing to read"
        )
    if session_meta.get("format") != S.FORMAT and not (ours and (sc.damaged or damaged_fields)):
        topics = sorted({c.topic for c in sc.channels.values()})[:6]
        raise SessionFileError(
            f"{path}: an MCAP file but not a layerskin session (no '{S.META_SESSION}' metadata with "
            f"format={S.FORMAT!r}; topics {topics}). Open it with Foxglove or the mcap library instead."
        )
    msgs = list(sc.warnings)
    if session_meta.get("format") != S.FORMAT:
        msgs.append("the session metadata record is damaged; its channels are read without it")
    metadata = {k: v for k, v in session_meta.items() if k not in ("format", "format_version")}
    for name, values in records.items():
        if name not in (S.META_SESSION, S.META_LABELS, S.META_OUTCOME, S.META_CLOCK_SYNC, S.META_LAYOUT,
                        S.META_LAYOUT_APP, S.META_LOG_TIME, S.META_STREAM_HEALTH):
            metadata[name] = values
    epoch = records.get(S.META_LOG_TIME, {}).get("offset_ns", 0)
    if any(f in (S.META_LOG_TIME, f"{S.META_LOG_TIME}.offset_ns") for f in damaged_fields):
        msgs.append("the log_time offset is damaged: every stream's host_t_ns is its log time (Unix ns), "
                    "not the host clock the clock maps use")
    if not isinstance(epoch, int) or isinstance(epoch, bool) or epoch < 0:
        msgs.append(f"log_time record holds offset {epoch!r}; log times read as host times")
        epoch = 0
    outcome = records.get(S.META_OUTCOME, {}).get("outcome")
    if outcome is not None and not isinstance(outcome, str):
        msgs.append(f"outcome record holds {outcome!r}, not a string; treated as absent")
        outcome = None
    labels = records.get(S.META_LABELS, {})
    stream_health = _stream_health(records.get(S.META_STREAM_HEALTH), msgs)
    wanted = None if streams is None else ({streams} if isinstance(streams, str) else set(streams))
    lost = [_lost_range(x, sc, epoch) for x in sc.lost]
    streams = _decode_streams(sc, msgs, wanted, lost, epoch)
    stored = records.get(S.META_CLOCK_SYNC, {})
    clock_sync = {}
    for name, arrays in streams.items():
        if name in ("events", "transforms"):  # host-side records: no device clock
            arrays["t_ns"] = arrays["host_t_ns"].copy()
            continue
        cmap = None
        if name in stored and isinstance(stored[name], dict):
            try:
                cmap = ClockMap.from_dict(stored[name])
            except (KeyError, TypeError, ValueError) as exc:
                msgs.append(f"stored clock map of {name} unreadable ({exc}); estimated from the data")
        if cmap is None and arrays["host_t_ns"].size:
            cmap = estimate_clock_map(arrays["device_t_ns"], arrays["host_t_ns"])
        if cmap is None:
            arrays["t_ns"] = arrays["host_t_ns"].copy()
            continue
        clock_sync[name] = cmap
        arrays["t_ns"] = cmap.to_host(arrays["device_t_ns"])
    damaged = sc.damaged or bool(lost) or bool(damaged_fields)
    if damaged_fields:
        msgs.append(f"metadata failing its check or missing, left out: {damaged_fields}")
    repeats = {}
    for cid, k in sc.repeats.items():
        repeats[_stream_of(sc, cid)] = repeats.get(_stream_of(sc, cid), 0) + k
    recovered = metadata.get(S.META_RECOVERED)
    recovered = recovered if isinstance(recovered, dict) else {}
    if recovered.get("repeats"):
        msgs.append(f"recovered from a damaged file; repeated messages dropped then: {recovered['repeats']}")
    if recovered.get("damaged_metadata"):
        msgs.append(f"recovered from a damaged file; metadata left out then: {recovered['damaged_metadata']}")
    finished = outcome is not None and (outcome == "complete" or outcome.startswith("complete ("))
    complete = sc.has_footer and finished and not damaged
    if outcome is None:
        msgs.append("no outcome recorded: the writer did not close this session (crash or kill?)")
    if damaged:
        msgs.append(
            f"damaged: {len(lost)} lost range(s), {sc.chunks_skipped} chunk(s) skipped; everything else "
            f"was read" + (" (the file says complete; this copy is not)" if finished else "")
        )
    if msgs and warn:
        _warnings.warn(f"{path}: " + "; ".join(msgs), SessionWarning, stacklevel=2)
    return Session(
        path=path,
        metadata=metadata,
        labels=labels if isinstance(labels, dict) else {},
        outcome=outcome,
        complete=complete,
        clock_sync=clock_sync,
        streams=streams,
        warnings=msgs,
        lost=lost,
        damaged=damaged,
        chunks_skipped=sc.chunks_skipped,
        repeats=repeats,
        damaged_fields=damaged_fields,
        unchecked=unchecked,
        epoch_offset_ns=epoch,
        stream_health=stream_health,
    )


def _stream_health(record: dict | None, msgs: list[str]) -> dict[str, dict[str, int]] | None:
    """The stream_health record's devices whose counters are whole numbers; others are named."""
    if record is None:
        return None
    out = {}
    for device, counters in record.items():
        if isinstance(counters, dict) and all(isinstance(v, int) and not isinstance(v, bool) and v >= 0
                                              for v in counters.values()):
            out[device] = counters
        else:
            msgs.append(f"stream_health of {device} holds {counters!r}, not counters; left out")
    return out


def _stream_of(sc: McapScan, cid: int) -> str:
    c = sc.channels.get(cid)
    if c is None:
        return f"channel {cid}"
    return c.metadata.get("stream") or c.topic


def _lost_range(x: Lost, sc: McapScan, epoch: int) -> LostRange:
    per = None
    if x.messages is not None:
        per = {}
        for cid, k in x.messages.items():
            name = _stream_of(sc, cid)
            per[name] = per.get(name, 0) + int(k)
    start = None if x.start_ns is None else x.start_ns - epoch
    end = None if x.end_ns is None else x.end_ns - epoch
    return LostRange(start, end, per, x.reason)


# ------------------------------------------------------------------------------ per-stream decoding


def _times(m: ChannelMessages, epoch: int) -> dict:
    h = m.header
    return {
        "host_t_ns": h["log_time"].astype(np.int64) - epoch,
        "device_t_ns": h["publish_time"].astype(np.int64),
        "seq": h["sequence"].astype(np.int64),
    }


def _decode_streams(sc: McapScan, msgs: list[str], wanted: set[str] | None, lost: list[LostRange],
                    epoch: int) -> dict:
    groups: dict[str, list[ChannelMessages]] = {}
    for _cid, m in sc.messages.items():
        stream = m.channel.metadata.get("stream")
        if stream is None and m.channel.metadata.get("view"):
            continue  # a Foxglove view of data that a stream holds (Log, image annotations)
        if stream is None:
            msgs.append(f"topic {m.channel.topic} is not a layerskin stream; skipped")
            continue
        if wanted is None or stream in wanted:
            groups.setdefault(stream, []).append(m)
    streams = {}
    for stream, chans in groups.items():
        try:
            streams[stream] = _decode_stream(sc, stream, chans, msgs, epoch)
        except Exception as exc:  # noqa: BLE001 - a damaged payload can fail any decoder; keep the rest
            t = np.concatenate([m.header["log_time"] for m in chans]).astype(np.int64) - epoch
            lost.append(LostRange(int(t.min()) if t.size else None, int(t.max()) if t.size else None,
                                  {stream: int(t.size)}, f"stream {stream!r} cannot be decoded "
                                  f"({type(exc).__name__}: {exc})"))
            msgs.append(f"stream {stream!r} left out: its messages cannot be decoded ({type(exc).__name__}: {exc})")
    return streams


def _decode_stream(sc: McapScan, stream: str, chans: list[ChannelMessages], msgs: list[str], epoch: int) -> dict:
    if stream == "skin":
        return _decode_skin(sc, chans, msgs, epoch)
    if stream == "markers":
        return _decode_markers(sc, chans, epoch)
    if stream == "camera":
        return _decode_camera(sc, chans[0], epoch)
    if stream == "transforms":
        return _decode_transforms(sc, chans[0], epoch)
    m = chans[0]
    if m.channel.message_encoding == "json":  # format_version 1
        return _decode_json(sc, m, stream, epoch)
    if m.schema is not None and m.schema.name in M.CLASSES:
        return _decode_messages(sc, m, stream, epoch)
    return _decode_poses(sc, m, epoch)


def _gather_rows(data: np.ndarray, start: np.ndarray, nbytes: int) -> np.ndarray:
    """(N, nbytes) uint8: data[start[i] : start[i] + nbytes] for each i, copied as 8-byte words.

    Rows start at arbitrary byte offsets. Grouped by offset mod 8, each group is a fancy index
    into a sliding window over the data viewed as <u8 (a copy of 8-byte items, several times
    faster than gathering single bytes). nbytes must be a multiple of 8.
    """
    words = nbytes // 8
    out = np.empty((start.size, words), "<u8")
    phase = start % 8
    for k in range(8):
        sel = np.flatnonzero(phase == k)
        if sel.size:
            aligned = data[k : k + (data.size - k) // 8 * 8].view("<u8")
            out[sel] = sliding_window_view(aligned, words)[(start[sel] - k) // 8]
    return out.view(np.uint8)


def _skin_pixels(sc: McapScan, m: ChannelMessages, msgs: list[str]) -> np.ndarray:
    """(N, 16, 16) uint16 from the last 512 bytes of each RawImage payload, checked vectorised;
    messages that do not have that layout are decoded with protobuf."""
    n = m.count
    nbytes = S.SKIN_DATA_BYTES
    end = m.payload_end
    tail = S.SKIN_TAIL
    lead = len(tail)
    start = m.payload_start
    fits = (end - start) >= nbytes + lead
    if n and fits.all():
        prefix = sliding_window_view(sc.data, lead)[end - nbytes - lead]
        fits = np.all(prefix == np.frombuffer(tail, np.uint8), axis=1)
    if n and fits.all():
        pix = _gather_rows(sc.data, end - nbytes, nbytes)
    else:
        pix = np.empty((n, nbytes), np.uint8)
        if fits.any():
            pix[fits] = _gather_rows(sc.data, (end - nbytes)[fits], nbytes)
    bad = np.flatnonzero(~fits)
    if bad.size:
        from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

        for i in bad.tolist():
            img = RawImage.FromString(sc.data[start[i] : end[i]].tobytes())
            if (img.width, img.height, img.encoding, len(img.data)) != (
                SKIN_SHAPE[1],
                SKIN_SHAPE[0],
                "mono16",
                nbytes,
            ):
                raise SessionFileError(
                    f"{m.channel.topic}: message {i} is a {img.width}x{img.height} {img.encoding!r} image, "
                    f"not the 16x16 mono16 skin layer"
                )
            pix[i] = np.frombuffer(img.data, np.uint8)
    return pix.view("<u2").reshape(n, *SKIN_SHAPE)


def _decode_skin(sc: McapScan, chans: list[ChannelMessages], msgs: list[str], epoch: int) -> dict:
    layers = {m.channel.metadata.get("layer"): m for m in chans}
    sup, deep = layers.get("superficial"), layers.get("deep")
    if sup is None or deep is None:
        raise SessionFileError(f"skin stream needs both layers' channels, found {sorted(map(str, layers))}")
    times_s, times_d = _times(sup, epoch), _times(deep, epoch)
    pix_s, pix_d = _skin_pixels(sc, sup, msgs), _skin_pixels(sc, deep, msgs)
    if sup.count == deep.count and np.array_equal(times_s["seq"], times_d["seq"]):
        keep_s = keep_d = slice(None)
    else:
        # A frame pair split by a crash, or dropped messages: keep frames present in both layers.
        _, keep_s, keep_d = np.intersect1d(times_s["seq"], times_d["seq"], return_indices=True)
        msgs.append(f"skin layers hold {sup.count} and {deep.count} frames; kept the {keep_s.size} in both")
    out = {k: v[keep_s] for k, v in times_s.items()}
    out["superficial"] = pix_s[keep_s]
    out["deep"] = pix_d[keep_d]
    return out


def _json_rows(sc: McapScan, m: ChannelMessages) -> list[dict]:
    if m.count == 0:
        return []
    return json.loads(b"[" + b",".join(sc.payloads(m)) + b"]")


def _float_array(rows, key, width=None) -> np.ndarray:
    vals = [r[key] for r in rows]
    a = np.array(vals, dtype=np.float64) if vals else np.zeros((0,) if width is None else (0, width))
    return a


def _decode_json(sc: McapScan, m: ChannelMessages, stream: str, epoch: int) -> dict:
    rows = _json_rows(sc, m)
    out = _times(m, epoch)
    if stream == "events":
        out.pop("seq")
        out["kind"] = [r["kind"] for r in rows]
        out["message"] = [r["message"] for r in rows]
        out["detail"] = [r["detail"] for r in rows]
        return out
    sample = rows[0] if rows else {}
    for key, value in sample.items():
        if key in ("host_t_ns", "device_t_ns", "seq"):
            continue
        if isinstance(value, bool):
            out[key] = np.array([r[key] for r in rows], dtype=bool)
        elif isinstance(value, int):
            out[key] = np.array([r[key] for r in rows], dtype=np.int64)
        else:
            out[key] = _float_array(rows, key)
    return out


_TIME_FIELDS = ("timestamp", "host_t_ns", "device_t_ns", "seq")


def _decode_messages(sc: McapScan, m: ChannelMessages, stream: str, epoch: int) -> dict:
    """One of the session's own protobuf streams -> the arrays _decode_json gives for its JSON form."""
    cls = M.CLASSES[m.schema.name]
    rows = [cls.FromString(p) for p in sc.payloads(m)]
    out = _times(m, epoch)
    if stream == "events":
        out.pop("seq")
        out["kind"] = [r.kind for r in rows]
        out["message"] = [r.message for r in rows]
        out["detail"] = [json.loads(r.detail_json) if r.detail_json else {} for r in rows]
        return out
    for name, kind in M.DEFINITIONS[m.schema.name.removeprefix(M.PACKAGE + ".")]:
        if name in _TIME_FIELDS:
            continue
        values = [getattr(r, name) for r in rows]
        if kind == "bool":
            out[name] = np.array(values, dtype=bool)
        elif kind == "int64":
            out[name] = np.array(values, dtype=np.int64)
        elif kind == "repeated double":
            out[name] = np.array([list(v) for v in values], dtype=np.float64)
        elif kind == "double":
            out[name] = np.array(values, dtype=np.float64)
        # other fields (marker corners) are read by the stream's own decoder
    return out


def _detection_corners(sc: McapScan, m: ChannelMessages) -> list:
    """Each marker detection's corners, [[x, y] * 4], from its protobuf or (version 1) JSON form."""
    if m.channel.message_encoding == "json":
        return [r["corners_px"] for r in _json_rows(sc, m)]
    cls = M.CLASSES["layerskin.MarkerDetection"]
    return [[(p.x, p.y) for p in cls.FromString(payload).corners_px] for payload in sc.payloads(m)]


def _decode_poses(sc: McapScan, m: ChannelMessages, epoch: int) -> dict:
    from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame

    n = m.count
    vals = np.empty((n, 7), np.float64)
    frame_ids = []
    for i, payload in enumerate(sc.payloads(m)):
        msg = PoseInFrame.FromString(payload)
        p, q = msg.pose.position, msg.pose.orientation
        vals[i] = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
        frame_ids.append(msg.frame_id)
    out = _times(m, epoch)
    out["position_m"] = vals[:, :3].copy()
    out["orientation_xyzw"] = vals[:, 3:].copy()
    out["frame_id"] = frame_ids
    return out


def _decode_markers(sc: McapScan, chans: list[ChannelMessages], epoch: int) -> dict:
    poses = [m for m in chans if m.channel.metadata.get("part") == "pose"]
    dets = {
        m.channel.metadata.get("marker_id"): m for m in chans if m.channel.metadata.get("part") == "detection"
    }
    parts = []
    for pm in poses:
        mid = pm.channel.metadata.get("marker_id")
        p = _decode_poses(sc, pm, epoch)
        corners = _detection_corners(sc, dets[mid]) if mid in dets else []
        n = min(len(corners), pm.count)
        p = {k: v[:n] for k, v in p.items()}
        p["marker_id"] = np.full(n, int(mid), np.int64)
        p["corners_px"] = np.array(corners[:n], np.float64).reshape(n, 4, 2)
        parts.append(p)
    keys = parts[0].keys()
    out = {}
    for k in keys:
        if isinstance(parts[0][k], list):
            out[k] = [x for p in parts for x in p[k]]
        else:
            out[k] = np.concatenate([p[k] for p in parts])
    order = np.lexsort((out["seq"], out["host_t_ns"]))
    out = {k: (v[order] if isinstance(v, np.ndarray) else [v[i] for i in order]) for k, v in out.items()}
    out["frame_seq"] = out["seq"].copy()
    return out


def _decode_camera(sc: McapScan, m: ChannelMessages, epoch: int) -> dict:
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    images = []
    for payload in sc.payloads(m):
        msg = CompressedImage.FromString(payload)
        images.append(cv2.imdecode(np.frombuffer(msg.data, np.uint8), cv2.IMREAD_UNCHANGED))
    out = _times(m, epoch)
    if images and all(im.shape == images[0].shape for im in images):
        out["image"] = np.stack(images)
    else:
        out["image"] = images
    return out


def _decode_transforms(sc: McapScan, m: ChannelMessages, epoch: int) -> dict:
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform

    n = m.count
    vals = np.empty((n, 7), np.float64)
    parents, children = [], []
    for i, payload in enumerate(sc.payloads(m)):
        msg = FrameTransform.FromString(payload)
        t, q = msg.translation, msg.rotation
        vals[i] = (t.x, t.y, t.z, q.x, q.y, q.z, q.w)
        parents.append(msg.parent_frame_id)
        children.append(msg.child_frame_id)
    out = _times(m, epoch)
    out["parent_frame_id"] = parents
    out["child_frame_id"] = children
    out["translation_m"] = vals[:, :3].copy()
    out["rotation_xyzw"] = vals[:, 3:].copy()
    return out
