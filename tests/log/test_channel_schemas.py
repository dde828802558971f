"""Every channel decodes to named fields in the official `mcap` reader (mcap-protobuf-support's
decoder, which knows nothing of this project: it builds each message from the schema the file
stores), and files of format_version 1 (JSON channels) read back as the same session.

fixtures/session_format1.mcap was written by layerskin-exp 0.2's SessionWriter from
`_fixture_records()` below (the same records, the same epoch offset); reading it and a file
the current writer makes from those records must give identical streams.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from log_records import HOST0_NS, records
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from layerskin_exp.log import SessionWriter, load_session
from layerskin_exp.log.session import schema as S
from layerskin_exp.types import SkinEstimate, Wrench

FORMAT1 = Path(__file__).parent / "fixtures" / "session_format1.mcap"
EPOCH_NS = 1_700_000_000_000_000_000


def _fixture_records() -> list:
    out = records(40)
    out.append(Wrench([np.nan, 1.0, 2.0], [0.0, np.nan, 0.0], 99, 5_200_000_000, HOST0_NS + 200_000_000, status=0))
    for k in range(3):
        out.append(SkinEstimate(np.array([0.1 * k, -0.2, 1.5]), 0.3 * k if k else None, k == 2, k,
                                5_000_000_000 + k, HOST0_NS + k * 1000))
    return out


def _write_current(path: Path) -> Path:
    with SessionWriter(path, metadata={"protocol": "fixture"}, labels={"trial": 0}, epoch_offset_ns=EPOCH_NS) as w:
        for r in _fixture_records():
            w.write(r)
    return path


def _same(a, b, where: str) -> None:
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, where
        np.testing.assert_array_equal(a, b, err_msg=where)  # NaN equals NaN here
    else:
        assert a == b, where


def test_a_format1_file_reads_as_the_same_session_as_one_written_now(tmp_path):
    with open(FORMAT1, "rb") as fh:
        summary = make_reader(fh).get_summary()
    old_encodings = {c.topic: c.message_encoding for c in summary.channels.values()}
    assert old_encodings[S.WRENCH_TOPIC] == old_encodings[S.EVENTS_TOPIC] == "json"  # really the old form

    old, new = load_session(FORMAT1), load_session(_write_current(tmp_path / "current.mcap"))
    assert old.complete and new.complete and old.warnings == new.warnings == []
    assert set(old.streams) == set(new.streams) >= {"skin", "wrench", "stage", "gripper", "markers", "events",
                                                    "estimate_force", "estimate_slip", "tcp"}
    for name, arrays in old.streams.items():
        assert set(arrays) == set(new.streams[name]), name
        for key, value in arrays.items():
            _same(value, new.streams[name][key], f"{name}.{key}")
    w = new.streams["wrench"]
    assert np.isnan(w["force_n"][-1, 0]) and w["force_n"][-1, 1] == 1.0  # NaN kept, not dropped
    assert new.streams["events"]["detail"][0] == {"i": 0, "nested": {"ok": True}}


def _fields(msg) -> dict:
    return {f.name: v for f, v in msg.ListFields()}


def test_every_channel_decodes_to_named_fields_in_the_official_mcap_reader(tmp_path):
    path = _write_current(tmp_path / "s.mcap")
    s = load_session(path)
    decoded: dict[str, list] = {}
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for schema, channel, _msg, m in reader.iter_decoded_messages():
            assert schema.encoding == "protobuf" and channel.message_encoding == "protobuf", channel.topic
            decoded.setdefault(channel.topic, []).append(m)
    assert set(decoded) >= {S.WRENCH_TOPIC, S.EVENTS_TOPIC, S.marker_detection_topic(0), S.STAGE_TOPIC,
                            S.GRIPPER_TOPIC, S.ESTIMATE_FORCE_TOPIC, S.ESTIMATE_SLIP_TOPIC}
    for topic, msgs in decoded.items():
        assert all(_fields(m) for m in msgs), f"{topic}: a message with no named field"

    wrench = decoded[S.WRENCH_TOPIC]
    declared = {f.name for f in wrench[0].DESCRIPTOR.fields}  # from the file's schema (proto3 omits zeros)
    assert {"timestamp", "host_t_ns", "device_t_ns", "seq", "status", "force_n", "torque_nm"} <= declared
    np.testing.assert_array_equal([list(m.force_n) for m in wrench], s.streams["wrench"]["force_n"])
    np.testing.assert_array_equal([m.seq for m in wrench], s.streams["wrench"]["seq"])
    events = decoded[S.EVENTS_TOPIC]
    assert [m.kind for m in events] == s.streams["events"]["kind"]
    assert [m.message for m in events] == s.streams["events"]["message"]
    det = decoded[S.marker_detection_topic(1)]
    mk = s.streams["markers"]
    corners = mk["corners_px"][mk["marker_id"] == 1]
    np.testing.assert_array_equal([[(p.x, p.y) for p in m.corners_px] for m in det], corners)
    assert [m.frame_seq for m in det] == mk["frame_seq"][mk["marker_id"] == 1].tolist()
    grip = decoded[S.GRIPPER_TOPIC][0]
    assert {"position_mm", "requested_mm", "speed", "force"} <= set(_fields(grip))
