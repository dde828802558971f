"""What goes on which channel, and how each payload is encoded.

Skin layers and poses use Foxglove's well-known protobuf schemas so a session opens in
Foxglove Studio as it is; streams with no fitting Foxglove schema use the session's own protobuf
messages (messages.py). Every channel is protobuf with its FileDescriptorSet as the schema, so
generic viewers decode each to named fields. Files of format_version 1 (layerskin-exp 0.2 and
earlier) hold those streams as JSON with JSON schemas; the reader reads both.
Every channel carries metadata {"stream": <reader stream name>, ...} so the reader groups
channels by what they hold, not by topic spelling.

Times (one timeline for Foxglove): MCAP log_time = host receive time on the Unix epoch (ns),
host_t_ns + the session's constant offset (metadata record "log_time", see epoch.py); the
`timestamp` of every Foxglove message is that same time, so plots by receive time or by message
time agree across devices. The host's monotonic receive time is log_time - offset; the device's
own clock stays in the MCAP publish_time (and sequence = device sequence number); the session's
own messages repeat host_t_ns / device_t_ns / seq. The reader maps device time onto the host timeline with
the stored clock maps (t_ns).

Frames: every Foxglove message names its frame (skin images "skin", poses the frame they are
expressed in, the camera image "camera"); FrameTransform messages on /tf relate them (see
layerskin_exp.log.view.frame_tree).

Channels whose metadata has no "stream" key (/log, image annotations) are views for Foxglove of
data that is already in a stream; the reader skips them.
"""

from __future__ import annotations

import json

import numpy as np
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.PointsAnnotation_pb2 import PointsAnnotation
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap_protobuf.schema import build_file_descriptor_set

from layerskin_exp.log.session import messages as M
from layerskin_exp.types import SKIN_SHAPE

FORMAT = "layerskin-session"
FORMAT_VERSION = "2"  # 2: the session's own streams are protobuf (1: JSON)

SKIN_TOPICS = {"superficial": "/skin/superficial", "deep": "/skin/deep"}
WRENCH_TOPIC = "/ft/wrench"
STAGE_TOPIC = "/stage/position"
TCP_TOPIC = "/arm/tcp"
GRIPPER_TOPIC = "/gripper/state"
EVENTS_TOPIC = "/events"
CAMERA_TOPIC = "/camera/image"
SKIN_SUMMARY_TOPIC = "/skin/summary"  # per-layer totals and CoP at display rate (a view)
CAMERA_MARKERS_TOPIC = "/camera/markers"  # ImageAnnotations: detected marker outlines on the image
TF_TOPIC = "/tf"
LOG_TOPIC = "/log"  # protocol events again, as foxglove.Log for the Log panel

SKIN_FRAME = "skin"
CAMERA_FRAME = "camera"


def cop_topic(layer: str) -> str:
    """ImageAnnotations with the centre of pressure of one layer, drawn on its image."""
    return f"{SKIN_TOPICS[layer]}/cop"
ESTIMATE_FORCE_TOPIC = "/estimate/force"
ESTIMATE_SLIP_TOPIC = "/estimate/slip"


def marker_pose_topic(marker_id: int) -> str:
    return f"/markers/{int(marker_id)}"


def marker_detection_topic(marker_id: int) -> str:
    return f"/markers/{int(marker_id)}/detection"


# MCAP metadata record names.
META_SESSION = "session"
META_LABELS = "labels"
META_OUTCOME = "outcome"
META_CLOCK_SYNC = "clock_sync"
META_RECOVERED = "recovered"
META_LOG_TIME = "log_time"  # {"epoch": "unix", "offset_ns": log_time - host_t_ns, "chosen": how}
# What each device's driver counted over the trial: {device: {"received", "lost", "duplicate",
# "out_of_order", "corrupt", "reconnects", and "dropped" where the driver's buffer can overflow}}.
META_STREAM_HEALTH = "stream_health"
META_LAYOUT = "foxglove.layout"  # the Foxglove layout, as the SDK's MCAPWriter.write_layout stores it
META_LAYOUT_APP = "layerskin.foxglove_app_layout"  # the same layout in the app's Layouts > Import format

# ---------------------------------------------------------------------------- protobuf schemas

PROTO_CLASSES = {
    **{cls.DESCRIPTOR.full_name: cls
       for cls in (RawImage, PoseInFrame, CompressedImage, FrameTransform, Log, ImageAnnotations)},
    **M.CLASSES,
}
"""Every schema a session writes, by full name: Foxglove's and the session's own (messages.py)."""

encode = M.encode
"""encode(name, body, t_ns): the payload of one of the session's own messages (see messages.py)."""


def proto_class(schema):
    """A protobuf class, or the full name of one in PROTO_CLASSES, -> the class."""
    if isinstance(schema, str):
        try:
            return PROTO_CLASSES[schema]
        except KeyError:
            raise ValueError(f"no session schema named {schema!r}; known: {sorted(PROTO_CLASSES)}") from None
    return schema


def proto_schema_data(cls) -> bytes:
    """Serialized FileDescriptorSet for a protobuf class (MCAP `protobuf` schema encoding)."""
    return build_file_descriptor_set(cls).SerializeToString()


def to_jsonable(value):
    """json.dumps default: numpy scalars and arrays become plain Python values."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if hasattr(value, "items"):  # e.g. an OmegaConf DictConfig
        return {str(k): v for k, v in value.items()}
    if isinstance(value, (tuple, set, frozenset)):
        return list(value)
    raise TypeError(f"cannot store {type(value).__name__} {value!r} in the session log as JSON")


# One encoder for every message: json.dumps with arguments builds a new encoder per call, which
# cost as much as the encoding itself on the 1 kHz wrench stream (benchmarks/log_json).
# allow_nan=False: NaN/inf are not JSON and would not reopen in other tools.
_ENCODER = json.JSONEncoder(default=to_jsonable, allow_nan=False, separators=(",", ":"))


def dumps(obj) -> bytes:
    return _ENCODER.encode(obj).encode()


# ---------------------------------------------------------------------------- fast RawImage bytes

_PIXELS = SKIN_SHAPE[0] * SKIN_SHAPE[1]
SKIN_DATA_BYTES = 2 * _PIXELS


def _varint(value: int) -> bytes:
    """Protobuf base-128 varint of a non-negative int (unrolled up to 4 bytes: nanoseconds and
    small seconds take this path once per skin message)."""
    if value < 0x80:
        return bytes((value,))
    if value < 0x4000:
        return bytes((value & 0x7F | 0x80, value >> 7))
    if value < 0x200000:
        return bytes((value & 0x7F | 0x80, value >> 7 & 0x7F | 0x80, value >> 14))
    if value < 0x10000000:
        return bytes((value & 0x7F | 0x80, value >> 7 & 0x7F | 0x80, value >> 14 & 0x7F | 0x80, value >> 21))
    out = bytearray()
    while True:
        bits = value & 0x7F
        value >>= 7
        if value:
            out.append(bits | 0x80)
        else:
            out.append(bits)
            return bytes(out)


def _skin_tail() -> bytes:
    """RawImage fields 2..6 up to the pixel bytes: width, height, encoding, step, data header."""
    msg = RawImage(
        width=SKIN_SHAPE[1],
        height=SKIN_SHAPE[0],
        encoding="mono16",
        step=2 * SKIN_SHAPE[1],
        data=bytes(SKIN_DATA_BYTES),
    )
    full = msg.SerializeToString()  # timestamp unset, frame_id empty: tail is everything
    return full[: len(full) - SKIN_DATA_BYTES]


SKIN_TAIL = _skin_tail()
"""Bytes that precede the 512 pixel bytes at the end of every skin RawImage payload."""

_SKIN_FRAME_FIELD = b"\x3a" + bytes((len(SKIN_FRAME),)) + SKIN_FRAME.encode()  # field 7, frame_id
_SKIN_REST = _SKIN_FRAME_FIELD + SKIN_TAIL


_last_sec: list = [None, b"", ()]  # one-entry cache: consecutive frames share their second
_HEAD_START = [b"\x0a" + bytes((n,)) for n in range(128)]  # field 1 tag + submessage length


def skin_head(t_ns: int) -> bytes:
    """Everything of a skin foxglove.RawImage payload before its 512 pixel bytes.

    head + pixels (16x16 little-endian uint16) parses as RawImage(timestamp=t_ns, frame_id="skin",
    width=16, height=16, encoding="mono16", step=32, data=pixels), built without a protobuf
    object per message. frame_id (field 7) is written right after the timestamp rather than in
    field-number order, so the pixels still end the message, which the reader relies on (and
    checks); protobuf parsers accept fields in any order.
    """
    sec, nsec = divmod(t_ns, 1_000_000_000)
    if sec != _last_sec[0]:
        ts = b"\x08" + _varint(sec) if sec else b""
        # Per nanosecond-varint length k (1..5): message start, seconds, nanos tag.
        starts = tuple(_HEAD_START[len(ts) + 1 + k] + ts + b"\x10" for k in range(6))
        _last_sec[0], _last_sec[1], _last_sec[2] = sec, ts, starts
    if nsec:
        v = _varint(nsec)
        return _last_sec[2][len(v)] + v + _SKIN_REST
    # The timestamp submessage is always present (even empty), as protobuf writes a set field.
    ts = _last_sec[1]
    return _HEAD_START[len(ts)] + ts + _SKIN_REST


def skin_payload(t_ns: int, pixels: bytes) -> bytes:
    """A whole skin RawImage payload (see skin_head)."""
    return skin_head(t_ns) + pixels


def pose_payload(position_m, orientation_xyzw, frame_id: str, t_ns: int) -> bytes:
    msg = PoseInFrame(frame_id=frame_id)
    msg.timestamp.FromNanoseconds(int(t_ns))
    p = msg.pose.position
    p.x, p.y, p.z = (float(v) for v in position_m)
    q = msg.pose.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in orientation_xyzw)
    return msg.SerializeToString()


def transform_payload(parent: str, child: str, translation_m, rotation_xyzw, t_ns: int) -> bytes:
    msg = FrameTransform(parent_frame_id=parent, child_frame_id=child)
    msg.timestamp.FromNanoseconds(int(t_ns))
    t, q = msg.translation, msg.rotation
    t.x, t.y, t.z = (float(v) for v in translation_m)
    q.x, q.y, q.z, q.w = (float(v) for v in rotation_xyzw)
    return msg.SerializeToString()


# Protocol event kinds -> foxglove.Log level (anything else is INFO).
LOG_LEVELS = {"error": Log.ERROR, "safety": Log.WARNING, "guard": Log.WARNING}


def log_payload(kind: str, message: str, detail: dict, t_ns: int) -> bytes:
    text = message if not detail else f"{message} {dumps(detail).decode()}"
    msg = Log(level=LOG_LEVELS.get(kind, Log.INFO), message=text, name=kind)
    msg.timestamp.FromNanoseconds(int(t_ns))
    return msg.SerializeToString()


def _colour(msg, rgba) -> None:
    msg.r, msg.g, msg.b, msg.a = rgba


def outlines_payload(outlines_px, t_ns: int, rgba=(0.1, 1.0, 0.2, 1.0), thickness: float = 2.0) -> bytes:
    """ImageAnnotations: one closed outline per (K, 2) array of pixel corners (x, y)."""
    msg = ImageAnnotations()
    msg.timestamp.FromNanoseconds(int(t_ns))
    for corners in outlines_px:
        a = msg.points.add(type=PointsAnnotation.LINE_LOOP, thickness=thickness)
        a.timestamp.FromNanoseconds(int(t_ns))
        _colour(a.outline_color, rgba)
        for x, y in corners:
            p = a.points.add()
            p.x, p.y = float(x), float(y)
    return msg.SerializeToString()


def cop_payload(centre_px, t_ns: int, diameter_px: float = 1.5, rgba=(1.0, 0.1, 0.1, 1.0)) -> bytes:
    """ImageAnnotations: a filled dot at the centre of pressure (x, y pixels; none when NaN)."""
    msg = ImageAnnotations()
    msg.timestamp.FromNanoseconds(int(t_ns))
    x, y = (float(v) for v in centre_px)
    if np.isfinite(x) and np.isfinite(y):
        c = msg.circles.add(diameter=diameter_px, thickness=0.3)
        c.timestamp.FromNanoseconds(int(t_ns))
        c.position.x, c.position.y = x, y
        _colour(c.fill_color, rgba)
        _colour(c.outline_color, (1.0, 1.0, 1.0, 1.0))
    return msg.SerializeToString()
