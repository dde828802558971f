"""The live view, headless: a WebSocket client subscribes to a running simulated trial and decodes
what the Foxglove server sends (both layers, CoP summary, frame tree, events), thinned for display."""

from __future__ import annotations

import base64
import json
import time

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from omegaconf import OmegaConf
from ws_client import FoxgloveClient

from hardware import build_rig
from layerskin_exp.log import load_session
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.view.live import FIXED_TOPICS, LiveView
from protocols.app import run_app
from protocols.grip import run_grip_trial
from tests.protocols.conftest import TINY_GRIP, compose_app


def _decoder(ch: dict):
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))


def test_client_receives_a_running_trial_decimated(tmp_path):
    cfg, typed = compose_app("grip_depth", [*TINY_GRIP, f"data_root={tmp_path}", "progress=false"])
    with LiveView(port=0) as view:
        client = FoxgloveClient("127.0.0.1", view.port)
        client.read_until(lambda c: set(FIXED_TOPICS) <= {ch["topic"] for ch in c.channels.values()})
        assert client.server_info is not None
        client.subscribe(list(client.channels))
        client.start()
        time.sleep(0.2)  # the subscription reaches the server before data flows
        rig = build_rig(cfg, "gripper")
        rig.connect()
        try:
            metadata = {"config": OmegaConf.to_container(cfg, resolve=True), "backend": rig.backend,
                        "calibration": rig.skin.calibration()}
            result = run_grip_trial(typed, rig, metadata, live=view)
        finally:
            rig.disconnect()
        time.sleep(0.5)
        client.close()
    session = load_session(result.path)
    topics = {cid: ch for cid, ch in client.channels.items()}
    got: dict[str, list] = {}
    for cid, t, payload in client.messages:
        ch = topics[cid]
        msg = json.loads(payload) if ch["encoding"] == "json" else _decoder(ch).FromString(payload)
        got.setdefault(ch["topic"], []).append((t, msg))

    for layer, topic in S.SKIN_TOPICS.items():
        images = got[topic]
        assert all((m.width, m.height, m.encoding, m.frame_id) == (16, 16, "mono16", "skin") for _, m in images)
        # thinned: ~30 Hz of host time, far fewer than the 424 Hz the file holds
        n_file = len(session.streams["skin"]["seq"])
        span_s = (images[-1][0] - images[0][0]) / 1e9
        assert 5 <= len(images) <= span_s * 31 + 2 < n_file
        # the pixels are the frames written to the file at those times
        sent = np.frombuffer(images[-1][1].data, "<u2").reshape(16, 16)
        # sent with the file's log time (Unix ns), not the host's monotonic time
        i = int(np.flatnonzero(session.unix_ns(session.streams["skin"]["host_t_ns"]) == images[-1][0])[0])
        np.testing.assert_array_equal(sent, session.streams["skin"][layer][i])
    summary = [m for _, m in got[S.SKIN_SUMMARY_TOPIC]]
    assert max(m["deep"]["total_counts"] for m in summary) > 500 and any(m["deep"]["cop_mm"] for m in summary)
    # events are never dropped: every one written reaches the Log panel
    logs = [m for _, m in got[S.LOG_TOPIC]]
    assert [m.name for m in logs] == session.streams["events"]["kind"]
    assert {m.child_frame_id for _, m in got[S.TF_TOPIC]} >= {"tool", "skin", "camera"}
    assert got[S.TCP_TOPIC][0][1].frame_id == "base"


def test_live_option_serves_and_stops_with_the_run(tmp_path, capsys):
    cfg, _ = compose_app("grip_depth", [*TINY_GRIP, f"data_root={tmp_path}", "progress=false", "live=true",
                                        "live_port=0"])
    result = run_app(cfg, "gripper", run_grip_trial)
    assert result.outcome == "complete"
    out = capsys.readouterr().out
    url = next(w for w in out.split() if w.startswith("ws://127.0.0.1:"))
    port = int(url.rsplit(":", 1)[1])
    with pytest.raises((ConnectionRefusedError, ConnectionResetError)):  # the server ended with the run
        FoxgloveClient("127.0.0.1", port, timeout=2)
