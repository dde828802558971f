"""Every record type written by SessionWriter comes back bit-exactly from load_session."""

from __future__ import annotations

import json

import numpy as np
import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from log_records import frame, records
from mcap.reader import make_reader

from layerskin_exp import __version__
from layerskin_exp.log import SessionClosedError, SessionWriter, load_session
from layerskin_exp.log.session import schema as S
from layerskin_exp.types import (
    GripperState,
    MarkerDetection,
    Pose,
    ProtocolEvent,
    StagePosition,
    TwoLayerFrame,
    Wrench,
)

META = {
    "config": {"skin": {"pitch_mm": 1.5}, "seeds": [1, 2]},
    "backend": "sim",
    "calibration": {"gain": [0.5, 2.0]},
}
LABELS = {"position_index": 3, "direction_rad": -0.25, "motion": "shear", "trial_index": 0}


def _write(path, recs, **kw):
    with SessionWriter(path, metadata=META, labels=LABELS, **kw) as w:
        for r in recs:
            w.write(r)
    return w


def _of(recs, cls):
    return [r for r in recs if type(r) is cls]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_every_stream_round_trips_exactly(tmp_path, compression):
    recs = records(600)
    path = tmp_path / "s.mcap"
    _write(path, recs, compression=compression)
    s = load_session(path)
    assert s.complete and s.outcome == "complete" and s.warnings == []
    assert s.labels == LABELS
    assert s.metadata["config"] == META["config"] and s.metadata["calibration"] == META["calibration"]
    assert s.metadata["backend"] == "sim" and s.metadata["version"] == __version__

    frames = _of(recs, TwoLayerFrame)
    skin = s.streams["skin"]
    assert skin["superficial"].dtype == np.uint16 and skin["superficial"].shape == (600, 16, 16)
    np.testing.assert_array_equal(skin["superficial"], np.stack([f.superficial for f in frames]))
    np.testing.assert_array_equal(skin["deep"], np.stack([f.deep for f in frames]))
    assert skin["superficial"].min() == 0 and skin["superficial"].max() == 4095
    np.testing.assert_array_equal(skin["seq"], [f.seq for f in frames])
    np.testing.assert_array_equal(skin["device_t_ns"], [f.device_t_ns for f in frames])
    np.testing.assert_array_equal(skin["host_t_ns"], [f.host_t_ns for f in frames])

    wr = _of(recs, Wrench)
    w = s.streams["wrench"]
    assert np.any(w["force_n"] < 0)
    np.testing.assert_array_equal(w["force_n"], np.stack([r.force_n for r in wr]))  # exact floats
    np.testing.assert_array_equal(w["torque_nm"], np.stack([r.torque_nm for r in wr]))
    np.testing.assert_array_equal(w["status"], [r.status for r in wr])
    np.testing.assert_array_equal(w["seq"], [r.seq for r in wr])

    st = _of(recs, StagePosition)
    np.testing.assert_array_equal(s.streams["stage"]["position_mm"], np.stack([r.position_mm for r in st]))

    poses = _of(recs, Pose)
    tcp = s.streams["tcp"]
    np.testing.assert_array_equal(tcp["position_m"], np.stack([p.position_m for p in poses]))
    np.testing.assert_array_equal(tcp["orientation_xyzw"], np.stack([p.orientation_xyzw for p in poses]))
    assert tcp["frame_id"] == ["base"] * len(poses)

    gr = _of(recs, GripperState)
    g = s.streams["gripper"]
    np.testing.assert_array_equal(g["position_mm"], [r.position_mm for r in gr])
    np.testing.assert_array_equal(g["object_detected"], [r.object_detected for r in gr])
    assert g["object_detected"].dtype == bool and g["speed"].dtype == np.int64

    md = _of(recs, MarkerDetection)
    m = s.streams["markers"]
    assert len(m["marker_id"]) == len(md)
    np.testing.assert_array_equal(np.sort(m["marker_id"]), np.sort([d.marker_id for d in md]))
    for mid in (0, 1):
        mine = [d for d in md if d.marker_id == mid]
        sel = m["marker_id"] == mid
        np.testing.assert_array_equal(m["position_m"][sel], np.stack([d.pose.position_m for d in mine]))
        np.testing.assert_array_equal(
            m["orientation_xyzw"][sel], np.stack([d.pose.orientation_xyzw for d in mine])
        )
        np.testing.assert_array_equal(m["corners_px"][sel], np.stack([d.corners_px for d in mine]))
        np.testing.assert_array_equal(m["frame_seq"][sel], [d.frame_seq for d in mine])

    ev = _of(recs, ProtocolEvent)
    e = s.streams["events"]
    assert e["kind"] == [x.kind for x in ev] and e["message"] == [x.message for x in ev]
    assert e["detail"] == [x.detail for x in ev]
    np.testing.assert_array_equal(e["t_ns"], [x.host_t_ns for x in ev])


def test_camera_images_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    imgs = [rng.integers(0, 256, (48, 64), dtype=np.uint8) for _ in range(3)]
    with SessionWriter(tmp_path / "c.mcap") as w:
        for i, im in enumerate(imgs):
            w.write_image(im, device_t_ns=10 + i, host_t_ns=100 + i, seq=i)
    cam = load_session(tmp_path / "c.mcap").streams["camera"]
    np.testing.assert_array_equal(cam["image"], np.stack(imgs))
    np.testing.assert_array_equal(cam["seq"], [0, 1, 2])


def test_other_pose_topics_become_their_own_stream(tmp_path):
    p = Pose(np.array([0.1, -0.2, 0.3]), np.array([0.0, 0.0, 0.0, 1.0]), "world", 5, 7, seq=1)
    with SessionWriter(tmp_path / "p.mcap") as w:
        w.write_pose(p, topic="/fixture/rod")
    s = load_session(tmp_path / "p.mcap")
    assert "tcp" not in s.streams
    np.testing.assert_array_equal(s.streams["/fixture/rod"]["position_m"], [[0.1, -0.2, 0.3]])


def test_skin_payload_is_the_protobuf_encoding(tmp_path):
    """The hand-built RawImage bytes parse as the same message protobuf builds (frame_id "skin"),
    end with the pixels, and decode back."""
    # Every varint length of the seconds and nanoseconds fields, consecutive calls within one
    # second (the writer caches the seconds part) and across seconds.
    nanos = (0, 1, 127, 128, 16_383, 16_384, 2_097_151, 2_097_152, 268_435_455, 268_435_456, 999_999_999)
    secs = (0, 1, 127, 128, 5, 2**21, 2**28, 2**35 + 17)  # protobuf Timestamp ends in year 9999
    devs = [999, 1_000_000_000, 5_123_456_789] + [s * 1_000_000_000 + n for s in secs for n in nanos]
    for dev in devs:
        f = frame(dev % 97)
        expected = RawImage(width=16, height=16, encoding="mono16", step=32, data=f.superficial.tobytes(),
                            frame_id="skin")
        expected.timestamp.FromNanoseconds(dev)
        payload = S.skin_payload(dev, f.superficial.tobytes())
        back = RawImage.FromString(payload)
        assert back == expected and len(payload) == len(expected.SerializeToString())
        assert payload.endswith(S.SKIN_TAIL + f.superficial.tobytes())
        assert back.timestamp.ToNanoseconds() == dev
        np.testing.assert_array_equal(np.frombuffer(back.data, "<u2").reshape(16, 16), f.superficial)


def test_file_opens_with_the_mcap_library(tmp_path):
    """Foxglove-facing layout: RawImage channels with protobuf schemas, log/publish/sequence."""
    path = tmp_path / "s.mcap"
    off = _write(path, records(50)).epoch_offset_ns
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        assert topics["/skin/superficial"] == "foxglove.RawImage"
        assert topics["/arm/tcp"] == "foxglove.PoseInFrame"
        assert topics["/ft/wrench"] == "layerskin.Wrench"
        for _schema, _channel, msg in reader.iter_messages(topics=["/skin/deep"]):
            f = frame(msg.sequence)
            # log time: host receive time on the Unix epoch; publish time: the device's own
            assert (msg.log_time, msg.publish_time) == (f.host_t_ns + off, f.device_t_ns)
            img = RawImage.FromString(msg.data)
            assert img.timestamp.ToNanoseconds() == msg.log_time
            assert img.encoding == "mono16" and img.step == 32
            np.testing.assert_array_equal(np.frombuffer(img.data, "<u2").reshape(16, 16), f.deep)
        names = {m.name for m in reader.iter_metadata()}
        assert {"session", "labels", "config", "outcome", "clock_sync"} <= names


def test_reader_falls_back_to_protobuf_when_layout_differs(tmp_path):
    """A RawImage with frame_id set (pixels no longer last) still decodes exactly, via protobuf."""
    path = tmp_path / "mixed.mcap"
    f0, f1 = frame(0), frame(1)
    with SessionWriter(path) as w:
        w.write(f0)
        for channel, arr in ((w._skin_sup, f1.superficial), (w._skin_deep, f1.deep)):
            msg = RawImage(
                width=16, height=16, encoding="mono16", step=32, data=arr.tobytes(), frame_id="skin"
            )
            w._add(channel, f1.host_t_ns, f1.device_t_ns, 1, msg.SerializeToString())
    skin = load_session(path).streams["skin"]
    np.testing.assert_array_equal(skin["superficial"], np.stack([f0.superficial, f1.superficial]))
    np.testing.assert_array_equal(skin["deep"], np.stack([f0.deep, f1.deep]))


def test_context_manager_records_abort_and_reraises(tmp_path):
    path = tmp_path / "a.mcap"
    with pytest.raises(RuntimeError, match="motor stalled"):
        with SessionWriter(path, labels=LABELS) as w:
            w.write(frame(0))
            raise RuntimeError("motor stalled")
    s = load_session(path)
    assert s.outcome == "aborted: RuntimeError: motor stalled" and not s.complete
    np.testing.assert_array_equal(s.streams["skin"]["superficial"][0], frame(0).superficial)

    with pytest.raises(KeyboardInterrupt):
        with SessionWriter(tmp_path / "k.mcap") as w:
            raise KeyboardInterrupt
    assert load_session(tmp_path / "k.mcap").outcome == "aborted: interrupted"


def test_write_after_close_and_bad_records_raise_clearly(tmp_path):
    w = SessionWriter(tmp_path / "c.mcap")
    with pytest.raises(TypeError, match="cannot log a str"):
        w.write("hello")
    with pytest.raises(ValueError, match="shape"):
        w.write(TwoLayerFrame(np.zeros((8, 8), np.uint16), np.zeros((16, 16), np.uint16), 0, 0, 0))
    with pytest.raises(ValueError, match="0..65535"):
        w.write(TwoLayerFrame(np.full((16, 16), -1), np.zeros((16, 16), np.uint16), 0, 0, 0))
    w.close("aborted: operator stop")
    with pytest.raises(SessionClosedError, match="closed"):
        w.write(frame(1))
    assert load_session(tmp_path / "c.mcap").outcome == "aborted: operator stop"
    with pytest.raises(FileExistsError, match="overwrite"):
        SessionWriter(tmp_path / "c.mcap")


def test_int_arrays_are_accepted_as_counts(tmp_path):
    f = frame(2)
    g = TwoLayerFrame(f.superficial.astype(np.int64), f.deep.astype(np.float64), 2, 1, 1)
    with SessionWriter(tmp_path / "i.mcap") as w:
        w.write(g)
    skin = load_session(tmp_path / "i.mcap").streams["skin"]
    np.testing.assert_array_equal(skin["superficial"][0], f.superficial)
    np.testing.assert_array_equal(skin["deep"][0], f.deep)


def test_gather_rows_matches_slicing_at_every_alignment():
    from layerskin_exp.log.session.reader import _gather_rows

    rng = np.random.default_rng(5)
    data = rng.integers(0, 256, 20_000, dtype=np.uint8)
    start = np.concatenate([np.arange(16), rng.integers(0, data.size - 512, 300), [data.size - 512]])
    rows = _gather_rows(data, start, 512)
    assert rows.shape == (start.size, 512) and rows.dtype == np.uint8
    for i, s in enumerate(start.tolist()):
        np.testing.assert_array_equal(rows[i], data[s : s + 512])


def test_streams_argument_decodes_only_those(tmp_path):
    recs = records(200)
    path = tmp_path / "s.mcap"
    _write(path, recs)
    full = load_session(path)
    part = load_session(path, streams={"skin", "wrench", "not_in_file"})
    assert set(full.streams) > {"skin", "wrench"} and set(part.streams) == {"skin", "wrench"}
    for name in ("skin", "wrench"):
        for key, value in full.streams[name].items():
            np.testing.assert_array_equal(part.streams[name][key], value)
    assert set(load_session(path, streams="events").streams) == {"events"}
    assert part.labels == full.labels and part.outcome == "complete"


def _arrays(s) -> dict:
    return {(name, k): v for name, a in s.streams.items() for k, v in a.items()}


def test_log_times_are_unix_and_the_aligned_arrays_do_not_depend_on_the_offset(tmp_path):
    """Two offsets, same records: MCAP log times differ by exactly the offset difference, and
    every array the reader returns (host, device and aligned times included) is identical."""
    recs = records(300)
    year_2000_ns = 946_684_800 * 10**9
    a = _write(tmp_path / "a.mcap", recs, epoch_offset_ns=year_2000_ns)
    b = _write(tmp_path / "b.mcap", recs, epoch_offset_ns=year_2000_ns + 7 * 86_400 * 10**9 + 123)
    sa, sb = load_session(a.path), load_session(b.path)
    assert (sa.epoch_offset_ns, sb.epoch_offset_ns) == (a.epoch_offset_ns, b.epoch_offset_ns)
    xa, xb = _arrays(sa), _arrays(sb)
    assert xa.keys() == xb.keys()
    for key, v in xa.items():
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(v, xb[key], err_msg=str(key))
        else:
            assert v == xb[key], key
    # the aligned timeline is the host one, as the records gave it
    np.testing.assert_array_equal(sa.streams["skin"]["host_t_ns"], [f.host_t_ns for f in _of(recs, TwoLayerFrame)])
    with open(b.path, "rb") as fh:
        logs = [(m.log_time, m.channel_id) for _, _, m in make_reader(fh).iter_messages()]
    host = sorted(int(t) for t in np.concatenate([v for (n, k), v in xb.items() if k == "host_t_ns"]))
    assert min(t for t, _ in logs) == host[0] + b.epoch_offset_ns
    assert all(t >= year_2000_ns for t, _ in logs)


def test_offset_is_chosen_from_the_backend(tmp_path):
    """Hardware sessions are dated by the wall clock; a simulated one written without the rig
    (which dates its trials itself, see tests/protocols/test_resume.py) when it is opened;
    a given offset is stored with how it was chosen."""
    import time

    before = time.time_ns() - time.monotonic_ns()
    with SessionWriter(tmp_path / "lab.mcap", metadata={"backend": "lab"}) as w:
        pass
    after = time.time_ns() - time.monotonic_ns()
    assert before - 1_000_000 <= w.epoch_offset_ns <= after + 1_000_000
    before = time.time_ns()
    with SessionWriter(tmp_path / "sim.mcap", metadata={"backend": "sim"}) as w:
        pass
    assert before <= w.epoch_offset_ns <= time.time_ns()
    with SessionWriter(tmp_path / "given.mcap", metadata={"backend": "sim"}, epoch_offset_ns=123,
                       epoch_how="a test's date") as w:
        pass
    assert load_session(tmp_path / "given.mcap").epoch_offset_ns == 123
    with open(tmp_path / "given.mcap", "rb") as f:
        (record,) = [m.metadata for m in make_reader(f).iter_metadata() if m.name == "log_time"]
    fields = {k: json.loads(v) for k, v in record.items() if not k.startswith("__crc32:")}  # each field's check beside it
    assert fields == {"epoch": "unix", "offset_ns": 123, "chosen": "a test's date"}
