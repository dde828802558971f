"""The session's own protobuf messages: the streams no Foxglove schema fits (wrench, stage,
gripper, marker detections, protocol events, live estimates, the skin summary view).

They are protobuf, like the Foxglove ones, so that every channel carries a self-describing schema
(a FileDescriptorSet, MCAP schema encoding "protobuf") that generic viewers decode to named fields:
the `mcap` reader with mcap-protobuf-support, Foxglove, rerun's MCAP importer. Files written before
(JSON payloads with JSON schemas) are still read by the session reader.

The messages are declared here as data and built at import into the default descriptor pool, so
no protoc step or generated code ties them to a protobuf release. Field names are those the JSON
payloads had (plot paths such as /ft/wrench.force_n[0] are unchanged); every message has a
`timestamp` (the MCAP log time, as every Foxglove message has), the host and device times and,
for device streams, the device's sequence number.
"""

from __future__ import annotations

from foxglove_schemas_protobuf.Point2_pb2 import Point2
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf import timestamp_pb2 as _timestamp_pb2

PACKAGE = "layerskin"
_F = descriptor_pb2.FieldDescriptorProto
_SCALARS = {"double": _F.TYPE_DOUBLE, "int64": _F.TYPE_INT64, "bool": _F.TYPE_BOOL, "string": _F.TYPE_STRING}
_MESSAGES = {"timestamp": ".google.protobuf.Timestamp", "point2": ".foxglove.Point2",
             "layer_summary": ".layerskin.LayerSummary"}

_TIMES = [("timestamp", "timestamp"), ("host_t_ns", "int64"), ("device_t_ns", "int64"), ("seq", "int64")]

# message name -> [(field, type)]; "repeated X" for arrays. Field numbers follow the order.
DEFINITIONS: dict[str, list[tuple[str, str]]] = {
    "LayerSummary": [("total_counts", "double"), ("cop_mm", "repeated double")],
    "Wrench": [*_TIMES, ("status", "int64"), ("force_n", "repeated double"), ("torque_nm", "repeated double")],
    "StagePosition": [*_TIMES, ("position_mm", "repeated double")],
    "GripperState": [*_TIMES, ("position_mm", "double"), ("requested_mm", "double"), ("speed", "int64"),
                     ("force", "int64"), ("object_detected", "bool"), ("fault", "int64")],
    "ForceEstimate": [*_TIMES, ("force_n", "repeated double")],
    "SlipEstimate": [*_TIMES, ("score", "double"), ("slip", "bool")],
    # corners in image pixels (x right, y down), in the detector's order
    "MarkerDetection": [("timestamp", "timestamp"), ("host_t_ns", "int64"), ("device_t_ns", "int64"),
                        ("marker_id", "int64"), ("frame_seq", "int64"), ("corners_px", "repeated point2")],
    # detail_json: the event's detail dict as JSON text (its keys vary with the event kind)
    "ProtocolEvent": [("timestamp", "timestamp"), ("host_t_ns", "int64"), ("device_t_ns", "int64"),
                      ("kind", "string"), ("message", "string"), ("detail_json", "string")],
    # display-rate per-layer totals above baseline (counts) and centre of pressure (mm; empty off contact)
    "SkinSummary": [("timestamp", "timestamp"), ("superficial", "layer_summary"), ("deep", "layer_summary")],
}


def _file() -> descriptor_pb2.FileDescriptorProto:
    fd = descriptor_pb2.FileDescriptorProto(
        name="layerskin/session.proto", package=PACKAGE, syntax="proto3",
        dependency=[_timestamp_pb2.DESCRIPTOR.name, Point2.DESCRIPTOR.file.name])
    for name, fields in DEFINITIONS.items():
        msg = fd.message_type.add(name=name)
        for number, (field, kind) in enumerate(fields, start=1):
            repeated = kind.startswith("repeated ")
            kind = kind.removeprefix("repeated ")
            f = msg.field.add(name=field, number=number,
                              label=_F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL)
            if kind in _SCALARS:
                f.type = _SCALARS[kind]
            else:
                f.type, f.type_name = _F.TYPE_MESSAGE, _MESSAGES[kind]
    return fd


def _build() -> dict[str, type]:
    pool = descriptor_pool.Default()
    fd = _file()
    try:
        file_desc = pool.FindFileByName(fd.name)
    except KeyError:
        file_desc = pool.Add(fd)
        if not hasattr(file_desc, "message_types_by_name"):  # pool.Add returns None on some releases
            file_desc = pool.FindFileByName(fd.name)
    return {f"{PACKAGE}.{name}": message_factory.GetMessageClass(file_desc.message_types_by_name[name])
            for name in DEFINITIONS}


CLASSES = _build()
"""Full name ("layerskin.Wrench") -> protobuf message class."""


def _nan(values):
    return [float("nan") if v is None else v for v in values]


def encode(name: str, body: dict, t_ns: int) -> bytes:
    """The payload of a `name` message with these fields (the keys of DEFINITIONS[name]; None in
    an array is NaN) and timestamp t_ns (the message's log time, Unix ns)."""
    cls = CLASSES[name]
    msg = cls()
    for key, value in body.items():
        if isinstance(value, list):
            if key == "corners_px":
                getattr(msg, key).extend(Point2(x=float(x), y=float(y)) for x, y in value)
            else:
                getattr(msg, key).extend(_nan(value) if None in value else value)
        elif isinstance(value, dict):  # a LayerSummary
            sub = getattr(msg, key)
            sub.total_counts = value["total_counts"]
            sub.cop_mm.extend(value["cop_mm"])
        else:
            setattr(msg, key, value)
    msg.timestamp.seconds, msg.timestamp.nanos = divmod(int(t_ns), 1_000_000_000)
    return msg.SerializeToString()

