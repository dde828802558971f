"""A short simulated session read the way Foxglove reads it: every message decoded with the schema
stored in the file, and checked against the rules Foxglove's panels rely on (frame ids, one
timeline, image geometry, a connected frame tree, a layout with the 12-bit range)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from layerskin_exp.log import load_session
from layerskin_exp.log.session import schema as S
from layerskin_exp.types import ADC_MAX
from protocols.app import run_app
from protocols.grip import run_grip_trial
from tests.protocols.conftest import TINY_GRIP, compose_app

FOXGLOVE_SCHEMAS = {"foxglove.RawImage", "foxglove.PoseInFrame", "foxglove.CompressedImage",
                    "foxglove.FrameTransform", "foxglove.Log", "foxglove.ImageAnnotations"}
JSON_TYPES = {"integer": int, "number": (int, float), "string": str, "boolean": bool, "array": list,
              "object": dict}


@pytest.fixture(scope="module")
def grip_session(tmp_path_factory):
    data = tmp_path_factory.mktemp("fox")
    cfg, _ = compose_app("grip_depth", [*TINY_GRIP, f"data_root={data}", "save_images=true",
                                        "sim.rig.camera.keep_images=true", "progress=false"])
    result = run_app(cfg, "gripper", run_grip_trial)
    assert result.outcome == "complete"
    return result.path


def _decoders(summary):
    """Message classes built from each protobuf schema's FileDescriptorSet, as Foxglove builds them."""
    out = {}
    for sid, schema in summary.schemas.items():
        if schema.encoding != "protobuf":
            continue
        fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
        pool = descriptor_pool.DescriptorPool()
        for fd in fds.file:
            pool.Add(fd)
        out[sid] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return out


def _check_json(value, schema: dict, where: str) -> None:
    expected = schema.get("type")
    if expected is not None:
        assert isinstance(value, JSON_TYPES[expected]) and not (
            expected in ("integer", "number") and isinstance(value, bool)), f"{where}: {value!r} is not {expected}"
    if expected == "object":
        for key in schema.get("required", []):
            assert key in value, f"{where}: required {key!r} missing"
        for key, sub in schema.get("properties", {}).items():
            if key in value:
                _check_json(value[key], sub, f"{where}.{key}")
    if expected == "array" and "items" in schema:
        for i, item in enumerate(value):
            if item is not None:  # NaN is stored as null
                _check_json(item, schema["items"], f"{where}[{i}]")


def _ns(ts) -> int:
    return ts.seconds * 1_000_000_000 + ts.nanos


def test_every_message_decodes_against_foxglove_schema_rules(grip_session):
    seen_topics, frame_ids, edges = set(), set(), {}
    with open(grip_session, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        decoders = _decoders(summary)
        for _sid, schema in summary.schemas.items():
            if schema.encoding == "protobuf":
                assert schema.name in FOXGLOVE_SCHEMAS
            else:
                assert schema.encoding == "jsonschema" and json.loads(schema.data)["type"] == "object"
        n = 0
        for schema, channel, msg in reader.iter_messages():
            n += 1
            seen_topics.add(channel.topic)
            where = f"{channel.topic} #{n}"
            if schema.encoding == "jsonschema":
                assert channel.message_encoding == "json"
                _check_json(json.loads(msg.data), json.loads(schema.data), where)
                continue
            assert channel.message_encoding == "protobuf"
            m = decoders[schema.id].FromString(msg.data)
            # one timeline: every Foxglove timestamp is the message's log (host receive) time
            assert _ns(m.timestamp) == msg.log_time, where
            if schema.name == "foxglove.FrameTransform":
                q = m.rotation
                assert abs(np.linalg.norm([q.x, q.y, q.z, q.w]) - 1) < 1e-6, where
                assert m.parent_frame_id and m.child_frame_id, where
                edges[m.child_frame_id] = m.parent_frame_id
            elif schema.name == "foxglove.Log":
                assert m.level in (1, 2, 3, 4, 5) and m.name and m.message, where
            elif schema.name == "foxglove.ImageAnnotations":
                for c in m.circles:
                    assert _ns(c.timestamp) == msg.log_time and c.diameter > 0, where
                for p in m.points:
                    assert _ns(p.timestamp) == msg.log_time and len(p.points) == 4, where
            else:
                assert m.frame_id, f"{where}: empty frame_id"
                frame_ids.add(m.frame_id)
            if schema.name == "foxglove.RawImage":
                assert (m.width, m.height, m.encoding) == (16, 16, "mono16") and m.step * m.height == len(m.data)
                assert m.frame_id == "skin"
                assert int(np.frombuffer(m.data, "<u2").max()) <= ADC_MAX
            if schema.name == "foxglove.PoseInFrame" and channel.topic == S.TCP_TOPIC:
                assert m.frame_id == "base"
            if schema.name == "foxglove.CompressedImage":
                assert m.format == "png" and m.frame_id == "camera"
        metadata = {r.name: r.metadata for r in reader.iter_metadata()}

    expected = {S.SKIN_TOPICS["superficial"], S.SKIN_TOPICS["deep"], S.TCP_TOPIC, S.TF_TOPIC, S.LOG_TOPIC,
                S.EVENTS_TOPIC, S.CAMERA_TOPIC, S.CAMERA_MARKERS_TOPIC, S.cop_topic("deep"), S.SKIN_SUMMARY_TOPIC}
    assert expected <= seen_topics
    # the frame tree: every frame a message names reaches "base"
    assert {("tool", "base"), ("skin", "tool"), ("camera", "base")} <= set(edges.items())
    assert any(c.startswith("marker_") and p == "camera" for c, p in edges.items())
    for frame in frame_ids | set(edges):
        hops, f = 0, frame
        while f != "base":
            assert f in edges and hops < 10, f"frame {frame!r} is not connected to base"
            f, hops = edges[f], hops + 1

    # the layout: both layers on the 0..4095 scale, plots and the 3D panel, naming topics in the file
    layout = json.loads(metadata[S.META_LAYOUT][""])
    text = json.dumps(layout)
    panels = []

    def walk(node):
        if isinstance(node, dict):
            if node.get("type") == "panel":
                panels.append(node)
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(layout["content"])
    images = {p["config"]["imageMode"]["imageTopic"]: p["config"]["imageMode"] for p in panels
              if p["panelType"] == "Image"}
    for layer in ("superficial", "deep"):
        mode = images[S.SKIN_TOPICS[layer]]
        assert (mode["minValue"], mode["maxValue"]) == (0, ADC_MAX)
        assert S.cop_topic(layer) in mode["annotations"]
    assert {"Image", "Plot", "ThreeDee", "Log"} <= {p["panelType"] for p in panels}  # SDK panel types
    assert S.TCP_TOPIC in text and S.WRENCH_TOPIC in text and S.LOG_TOPIC in text


def test_reader_keeps_its_streams_and_aligned_times(grip_session):
    s = load_session(grip_session)
    assert s.complete and s.warnings == []
    assert {"skin", "tcp", "gripper", "markers", "events", "transforms", "camera"} <= set(s.streams)
    for name in ("skin", "tcp", "gripper", "markers"):
        a = s.streams[name]
        # device clocks are hundreds of seconds away from the host's; t_ns maps them onto it
        np.testing.assert_array_equal(a["t_ns"], s.clock_sync[name].to_host(a["device_t_ns"]))
        delay = a["host_t_ns"] - a["t_ns"]
        assert delay.min() >= -1_000_000 and np.median(delay) < 20_000_000, name
    prov = s.metadata["provenance"]
    assert prov["version"] and {"git_commit", "git_dirty", "overrides"} <= set(prov)
    assert s.metadata["config"]["grip_depth"] == 6  # the resolved config beside it
    tf = s.streams["transforms"]
    assert tf["translation_m"].shape == (len(tf["child_frame_id"]), 3)
    tool = np.array(tf["child_frame_id"]) == "tool"
    np.testing.assert_allclose(tf["translation_m"][tool], s.streams["tcp"]["position_m"])
