"""Short simulated sessions read the way Foxglove reads them: every message decoded with the schema
stored in the file, and checked against the rules Foxglove's panels rely on (frame ids, one Unix
timeline, image geometry, a connected frame tree), and each rig's layout checked against the
app's import format with every panel on a topic the file has."""

from __future__ import annotations

import json

import numpy as np
import pytest
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from layerskin_exp.log import load_session
from layerskin_exp.log.session import schema as S
from layerskin_exp.types import ADC_MAX
from protocols.app import run_app
from protocols.calibration import run_campaign
from protocols.grip import run_grip_trial
from tests.protocols.conftest import TINY_CALIBRATION, TINY_GRIP, compose_app

FOXGLOVE_SCHEMAS = {"foxglove.RawImage", "foxglove.PoseInFrame", "foxglove.CompressedImage",
                    "foxglove.FrameTransform", "foxglove.Log", "foxglove.ImageAnnotations"}



@pytest.fixture(scope="module")
def grip_session(tmp_path_factory):
    data = tmp_path_factory.mktemp("fox")
    cfg, _ = compose_app("grip_depth", [*TINY_GRIP, f"data_root={data}", "save_images=true",
                                        "sim.rig.camera.keep_images=true", "progress=false"])
    result = run_app(cfg, "gripper", run_grip_trial)
    assert result.outcome == "complete"
    return result.path


@pytest.fixture(scope="module")
def platform_session(tmp_path_factory):
    data = tmp_path_factory.mktemp("fox_platform")
    cfg, _ = compose_app("force_calibration", [*TINY_CALIBRATION, "positions.count=1", f"data_root={data}",
                                               "progress=false"])
    run_app(cfg, "platform", run_campaign)
    return sorted(data.rglob("*press*.mcap"))[0]


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


def _ns(ts) -> int:
    return ts.seconds * 1_000_000_000 + ts.nanos


def test_every_message_decodes_against_foxglove_schema_rules(grip_session):
    seen_topics, frame_ids, edges = set(), set(), {}
    with open(grip_session, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        decoders = _decoders(summary)
        for _sid, schema in summary.schemas.items():
            # every channel self-describing protobuf: Foxglove's schemas or the session's own
            assert schema.encoding == "protobuf", schema.name
            assert schema.name in FOXGLOVE_SCHEMAS or schema.name.startswith("layerskin."), schema.name
        n, log_times = 0, []
        for schema, channel, msg in reader.iter_messages():
            n += 1
            log_times.append(msg.log_time)
            seen_topics.add(channel.topic)
            where = f"{channel.topic} #{n}"
            assert channel.message_encoding == "protobuf"
            m = decoders[schema.id].FromString(msg.data)
            # one timeline: every message's timestamp is its log (host receive) time
            assert _ns(m.timestamp) == msg.log_time, where
            if schema.name.startswith("layerskin."):
                named = {f.name for f, _ in m.ListFields()}
                assert "timestamp" in named and len(named) > 1, where
                if schema.name == "layerskin.ProtocolEvent":
                    assert m.kind and isinstance(json.loads(m.detail_json), dict), where
                if schema.name == "layerskin.MarkerDetection":
                    assert len(m.corners_px) == 4, where
                continue
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

    # log times are Unix-epoch ns (the simulator dates a run between 2000 and 2100)
    assert all(946_684_800 * 10**9 <= t < 4_102_444_800 * 10**9 for t in log_times)


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


# ---------------------------------------------------------------------------- the app's layout format
# Panel types of the Foxglove app's panel catalogue (the prefix of a panel id), and the fields of
# the app's layout document (LayoutData: configById, layout, globalVariables, userNodes).
APP_PANEL_TYPES = {"3D", "Image", "Plot", "RosOut", "StateTransitions", "RawMessages", "Indicator", "Gauge",
                   "Table", "Tab", "SourceInfo", "TopicGraph", "map", "Parameters", "Publish"}


def _mosaic_leaves(node, where="layout") -> list[str]:
    if isinstance(node, str):
        return [node]
    assert isinstance(node, dict) and {"first", "second", "direction"} <= set(node), where
    assert node["direction"] in ("row", "column"), where
    assert 0 < node.get("splitPercentage", 50) < 100, where
    return _mosaic_leaves(node["first"], where + ".first") + _mosaic_leaves(node["second"], where + ".second")


def _panel_topics(panel_id: str, config: dict) -> set[str]:
    """The topics a panel shows, read from its app config the way the app reads them."""
    kind = panel_id.split("!", 1)[0]
    if kind == "Image":
        mode = config["imageMode"]
        return {mode["imageTopic"], *mode.get("annotations", {})}
    if kind == "Plot":
        return {p["value"].split(".", 1)[0] for p in config["paths"]}  # "/topic.field[i]"
    if kind == "RosOut":
        return {config["topicToRender"]}
    if kind == "3D":
        return {"/tf", *config.get("topics", {})}  # the scene is the frame tree, plus pose topics
    raise AssertionError(f"{panel_id}: no rule for this panel type")


def check_app_layout(doc: dict, file_topics: set[str]) -> dict[str, dict]:
    """Assert `doc` is a layout the app imports and every panel shows topics the file has."""
    assert {"configById", "layout", "globalVariables", "userNodes"} <= set(doc)
    assert isinstance(doc["globalVariables"], dict) and isinstance(doc["userNodes"], dict)
    leaves = _mosaic_leaves(doc["layout"])
    assert sorted(leaves) == sorted(doc["configById"]), "every configured panel placed exactly once"
    for pid, config in doc["configById"].items():
        assert pid.split("!", 1)[0] in APP_PANEL_TYPES and "!" in pid, pid
        missing = _panel_topics(pid, config) - file_topics
        assert not missing, f"{pid} ({config.get('foxglovePanelTitle')}) shows topics the file lacks: {missing}"
        # titled for both apps: Foxglove reads foxglovePanelTitle, Lichtblick lichtblickPanelTitle
        assert config.get("foxglovePanelTitle") and config.get("lichtblickPanelTitle") == config["foxglovePanelTitle"], pid
    return doc["configById"]


def _file_layout(path) -> tuple[dict, set[str]]:
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        topics = {c.topic for c in reader.get_summary().channels.values()}
        meta = {r.name: r.metadata for r in reader.iter_metadata()}
    return json.loads(meta[S.META_LAYOUT_APP][""]), topics


def _by_title(config_by_id: dict) -> dict[str, dict]:
    return {c.get("foxglovePanelTitle", pid): c for pid, c in config_by_id.items()}


def test_each_rig_gets_its_layout_in_the_app_import_format(grip_session, platform_session):
    grip, grip_topics = _file_layout(grip_session)
    plat, plat_topics = _file_layout(platform_session)
    g, p = _by_title(check_app_layout(grip, grip_topics)), _by_title(check_app_layout(plat, plat_topics))
    assert {"jaw (mm)", "TCP (m)", "camera + markers"} <= set(g) and "stage (mm)" not in g and "force (N)" not in g
    assert {"force (N)", "stage (mm)"} <= set(p) and "jaw (mm)" not in p and "camera + markers" not in p
    for cfg in (g, p):
        # plots grouped by unit: counts, CoP and each motion on their own axes
        totals, cop = cfg["skin totals above baseline (counts)"], cfg["centre of pressure (mm, on contact)"]
        assert all(x["value"].endswith("total_counts") for x in totals["paths"])
        assert all(".cop_mm[" in x["value"] for x in cop["paths"])
        for layer in S.SKIN_TOPICS:
            mode = next(c["imageMode"] for c in cfg.values() if c.get("imageMode", {}).get("imageTopic")
                        == S.SKIN_TOPICS[layer])
            assert (mode["minValue"], mode["maxValue"]) == (0, ADC_MAX) and S.cop_topic(layer) in mode["annotations"]
    # the check can fail: a panel on a topic the file lacks, or a panel left out of the tree
    with pytest.raises(AssertionError, match="lacks"):
        check_app_layout(grip, plat_topics)
    broken = json.loads(json.dumps(plat))
    broken["layout"] = broken["layout"]["second"]
    with pytest.raises(AssertionError, match="placed"):
        check_app_layout(broken, plat_topics)


def test_skin_images_show_plus_y_up_like_the_figures():
    """Image row i holds the taxels at y_i; the figures draw +y upwards (matplotlib's default,
    origin="lower" for maps). Foxglove draws row 0 at the top, so rows whose y grows with i must
    be flipped vertically, and only then."""
    from layerskin_exp.config import SkinConfig
    from layerskin_exp.log.view.layout import rig_layout

    y = np.asarray(SkinConfig().taxel_centres_mm(), float)  # y_i of row i (and x_j of column j)
    rows_grow_up = bool(np.all(np.diff(y) > 0))
    for setup in ("platform", "gripper"):
        for c in rig_layout(setup)["configById"].values():
            mode = c.get("imageMode", {})
            if mode.get("imageTopic") in S.SKIN_TOPICS.values():
                assert mode.get("flipVertical", False) == rows_grow_up and not mode.get("flipHorizontal", False)


def test_estimate_panels_when_estimates_are_logged(tmp_path):
    from log_records import records

    from layerskin_exp.log import SessionWriter
    from layerskin_exp.types import SkinEstimate

    for with_estimate in (False, True):
        path = tmp_path / f"e{with_estimate}.mcap"
        with SessionWriter(path, metadata={"backend": "lab"}) as w:
            for r in records(40):
                w.write(r)
            if with_estimate:
                for k in range(3):
                    w.write(SkinEstimate(np.array([0.1, 0.2, 1.0]), 0.3, False, k, 10**9 + k, 10**9 + k))
        doc, topics = _file_layout(path)
        cfg = check_app_layout(doc, topics)
        shown = set().union(*(_panel_topics(pid, c) for pid, c in cfg.items()))
        assert ({S.ESTIMATE_FORCE_TOPIC, S.ESTIMATE_SLIP_TOPIC} <= shown) == with_estimate
        assert not (shown & {S.ESTIMATE_FORCE_TOPIC, S.ESTIMATE_SLIP_TOPIC}) or with_estimate
    # the estimate's force shares the F/T force axis (both N)
    force = _by_title(cfg)["force (N)"]
    assert {x["value"].split(".")[0] for x in force["paths"]} == {S.WRENCH_TOPIC, S.ESTIMATE_FORCE_TOPIC}


def test_rig_layouts_for_the_live_view_name_only_that_rigs_topics():
    from layerskin_exp.log.view.layout import rig_layout, rig_topics

    for setup in ("platform", "gripper"):
        for estimate in (False, True):
            topics = rig_topics(setup, estimate=estimate, camera=True)
            check_app_layout(rig_layout(setup, estimate=estimate, camera=True), topics)
    # the gripper's 3D panel shows the markers' poses the live view serves, beside the TCP
    scene = next(c for pid, c in rig_layout("gripper")["configById"].items() if pid.startswith("3D!"))
    assert set(scene["topics"]) == {S.TCP_TOPIC, S.marker_pose_topic(0), S.marker_pose_topic(1)}
    with pytest.raises(ValueError, match="setup='arm'"):
        rig_topics("arm")


# ---------------------------------------------------------------------------- CoP only on contact


def test_contact_threshold_is_above_the_noise_total():
    """The threshold against an independent Monte Carlo of the noise totals: with z=5 noise alone
    (sigma 1..4 counts, 256 taxels) practically never reaches it, while the former fixed 200
    counts sat under the noise total at sigma 2 (the CoP drawn before contact)."""
    from layerskin_exp.log.view.skin_summary import noise_total_threshold

    rng = np.random.default_rng(0)
    for sigma in (1.0, 2.0, 4.0):
        noise = np.rint(rng.normal(0.0, sigma, (16 + 20_000, 16, 16)))
        base = noise[:16].mean(axis=0)
        thr = noise_total_threshold(noise[:16] - base)
        totals = np.clip(noise[16:] - base, 0, None).sum(axis=(1, 2))
        assert (totals > thr).mean() < 1e-3, sigma
        assert thr < 3 * totals.mean()  # and not so high that light contact is missed
        if sigma == 2.0:
            assert (totals > 200).mean() > 0.5
    # a noiseless baseline still leaves the ADC's rounding: the threshold never drops to 0
    assert noise_total_threshold(np.zeros((16, 16, 16))) > 0


def test_cop_is_drawn_only_on_contact(grip_session):
    s = load_session(grip_session)
    ev = s.streams["events"]
    contact_ns = int(s.unix_ns(ev["host_t_ns"][ev["kind"].index("contact")]))
    phases = [(int(s.unix_ns(t)), m) for t, k, m in zip(ev["host_t_ns"], ev["kind"], ev["message"], strict=True)
              if k == "phase"]
    hold = next(t for t, m in phases if m == "hold")
    release = next(t for t, m in phases if m == "release")
    before, during, dots_before, dots_during = [], [], 0, 0
    with open(grip_session, "rb") as fh:
        for _, channel, msg in make_reader(fh).iter_messages(
                topics=[S.SKIN_SUMMARY_TOPIC, S.cop_topic("superficial"), S.cop_topic("deep")]):
            t = msg.log_time
            if channel.topic == S.SKIN_SUMMARY_TOPIC:
                m = S.PROTO_CLASSES["layerskin.SkinSummary"].FromString(msg.data)
                body = {layer: {"cop_mm": list(getattr(m, layer).cop_mm)} for layer in S.SKIN_TOPICS}
                (before if t < contact_ns - 50_000_000 else during if hold <= t < release else []).append(body)
            else:
                n = len(ImageAnnotations.FromString(msg.data).circles)
                if t < contact_ns - 50_000_000:
                    dots_before += n
                elif hold <= t < release:
                    dots_during += n
    assert len(before) >= 5 and len(during) >= 3
    assert not any(b[layer]["cop_mm"] for b in before for layer in S.SKIN_TOPICS) and dots_before == 0
    assert all(b[layer]["cop_mm"] for b in during for layer in S.SKIN_TOPICS) and dots_during == 2 * len(during)
