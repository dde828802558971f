"""The live view, headless: a WebSocket client subscribes to a running simulated trial and decodes
what the Foxglove server sends (both layers, CoP summary, frame tree, events), thinned for display."""

from __future__ import annotations

import base64
import logging
import signal
import threading
import time

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from omegaconf import OmegaConf
from ws_client import FoxgloveClient

from hardware import build_rig
from layerskin_exp.log import load_session
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.view.layout import rig_topics
from layerskin_exp.log.view.live import FIXED_TOPICS, LiveView
from protocols.app import run_app
from protocols.grip import run_grip_trial
from tests.protocols.conftest import TINY_GRIP, compose_app

# what a grip rig's live view advertises at start: its setup's topics of known schema
GRIP_TOPICS = set(FIXED_TOPICS) & rig_topics("gripper")


def _decoder(ch: dict):
    fds = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(ch["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(ch["schemaName"]))


def test_client_receives_a_running_trial_decimated(tmp_path):
    cfg, typed = compose_app("grip_depth", [*TINY_GRIP, f"data_root={tmp_path}", "progress=false"])
    with LiveView("gripper", port=0) as view:
        client = FoxgloveClient("127.0.0.1", view.port)
        client.read_until(lambda c: GRIP_TOPICS <= {ch["topic"] for ch in c.channels.values()})
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
        assert ch["encoding"] == "protobuf", ch  # every channel decodes from its own schema
        msg = _decoder(ch).FromString(payload)
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
    assert max(m.deep.total_counts for m in summary) > 500 and any(m.deep.cop_mm for m in summary)
    # events are never dropped: every one written reaches the Log panel
    logs = [m for _, m in got[S.LOG_TOPIC]]
    assert [m.name for m in logs] == session.streams["events"]["kind"]
    assert {m.child_frame_id for _, m in got[S.TF_TOPIC]} >= {"tool", "skin", "camera"}
    assert got[S.TCP_TOPIC][0][1].frame_id == "base"
    # every channel advertised carried data: none of the platform's (F/T, stage) on the grip rig,
    # and the markers' poses the gripper layout's 3D panel shows
    advertised = {ch["topic"] for ch in client.channels.values()}
    assert advertised == set(got), f"advertised without data: {sorted(advertised - set(got))}"
    assert {S.WRENCH_TOPIC, S.STAGE_TOPIC}.isdisjoint(advertised)
    assert {t for t in advertised if t.startswith("/markers/")} == {S.marker_pose_topic(0), S.marker_pose_topic(1)}


def test_a_platform_campaign_carries_data_on_every_channel_its_live_view_advertises(tmp_path):
    from protocols.calibration import run_campaign

    cfg, typed = compose_app("force_calibration", ["positions.count=1", "press.repeats=1", "slide.repeats=1",
                                                   "press.hold_s=0.05", f"data_root={tmp_path}", "progress=false"])
    expected = set(FIXED_TOPICS) & rig_topics("platform")
    with LiveView("platform", port=0) as view:
        client = FoxgloveClient("127.0.0.1", view.port)
        client.read_until(lambda c: expected <= {ch["topic"] for ch in c.channels.values()})
        client.subscribe(list(client.channels))
        client.start()
        time.sleep(0.2)  # the subscription reaches the server before data flows
        rig = build_rig(cfg, "platform")
        rig.connect()
        try:
            run_campaign(typed, rig, {"config": OmegaConf.to_container(cfg, resolve=True), "backend": rig.backend,
                                      "calibration": rig.skin.calibration()}, live=view)
        finally:
            rig.disconnect()
        time.sleep(0.5)
        client.close()
    advertised = {ch["topic"] for ch in client.channels.values()}
    got = {client.channels[cid]["topic"] for cid, _, _ in client.messages}
    assert advertised == got, f"advertised without data: {sorted(advertised - got)}"
    assert {S.WRENCH_TOPIC, S.STAGE_TOPIC} <= got and not {S.TCP_TOPIC, S.GRIPPER_TOPIC} & advertised


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


def _log_client(port: int, start: bool = True) -> FoxgloveClient:
    """A client subscribed to /log; start: read on in a thread (else the caller reads)."""
    c = FoxgloveClient("127.0.0.1", port)
    c.read_until(lambda c: any(ch["topic"] == S.LOG_TOPIC for ch in c.channels.values()))
    c.subscribe([next(k for k, ch in c.channels.items() if ch["topic"] == S.LOG_TOPIC)])
    if start:
        c.start()
    return c


def _event(view: LiveView, k: int) -> int:
    t = 1_800_000_000 * 10**9 + k
    view.message(S.LOG_TOPIC, S.Log, S.log_payload("phase", f"event {k}", {}, t), t, key=None)
    return t


def test_a_late_client_gets_the_earlier_events_once_and_others_no_repeat():
    with LiveView("gripper", port=0) as view:
        early = _log_client(view.port)
        time.sleep(0.2)
        sent = [_event(view, k) for k in range(3)]
        late = _log_client(view.port)
        time.sleep(0.3)
        sent.append(_event(view, 3))
        time.sleep(0.3)
        early.close()
        late.close()
    assert [t for _, t, _ in early.messages] == sent
    assert sorted(t for _, t, _ in late.messages) == sent  # the first three replayed, then live


def test_a_late_client_gets_a_long_run_whole():
    """A replay far longer than the SDK's default per-client queue (1024) arrives whole."""
    with LiveView("gripper", port=0) as view:
        sent = [_event(view, k) for k in range(5000)]
        late = _log_client(view.port, start=False)
        late.read_until(lambda c: len(c.messages) >= len(sent), limit=20_000)
        late.close()
    assert [t for _, t, _ in late.messages] == sent


def test_a_foxglove_websocket_v1_client_is_refused_with_one_warning(caplog):
    """The SDK's server speaks foxglove.sdk.v1 only; refusals are reported once, not as an error each."""
    with caplog.at_level(logging.DEBUG), LiveView("gripper", port=0) as view:
        for _ in range(3):
            with pytest.raises(ConnectionError, match="400"):
                FoxgloveClient("127.0.0.1", view.port, subprotocol="foxglove.websocket.v1", timeout=5)
        FoxgloveClient("127.0.0.1", view.port, subprotocol="foxglove.sdk.v1.1", timeout=5).close()
        time.sleep(0.3)
    refusals = [r for r in caplog.records if "handshake failed" in r.getMessage()]
    assert len(refusals) == 3 and not [r for r in refusals if r.levelno >= logging.ERROR]
    assert sum(r.levelno == logging.WARNING for r in refusals) <= 1  # once per process
    assert all("foxglove.sdk.v1" in r.getMessage() for r in refusals if r.levelno == logging.WARNING)


def test_hold_keeps_serving_after_the_run_until_stopped(tmp_path, capsys):
    """live_hold=true (`python -m protocols.live ... --hold`): after the trial the server stays up,
    a client joining then gets the whole run (both layer maps over the trial, poses, the frame
    tree, every event), and Ctrl-C says the run has already ended and ends the hold. Run in a
    thread here, where the app leaves signal handling alone; the Ctrl-C handler is called as
    the signal would."""
    from protocols import app, runner

    cfg, _ = compose_app("grip_depth", [*TINY_GRIP, f"data_root={tmp_path}", "progress=false", "live=true",
                                        "live_port=0", "live_hold=true"])
    done = {}
    th = threading.Thread(target=lambda: done.setdefault("result", run_app(cfg, "gripper", run_grip_trial)))
    th.start()
    try:
        out = ""
        deadline = time.monotonic() + 120
        while "run finished" not in out and th.is_alive() and time.monotonic() < deadline:
            time.sleep(0.1)
            out += capsys.readouterr().out
        assert "run finished" in out and th.is_alive(), out
        port = int(out.split("ws://127.0.0.1:", 1)[1].split()[0])
        session = load_session(next(tmp_path.rglob("*.mcap")))  # closed before the hold began
        client = FoxgloveClient("127.0.0.1", port)  # after the run: the server is still up
        client.read_until(lambda c: GRIP_TOPICS <= {ch["topic"] for ch in c.channels.values()})
        client.subscribe(list(client.channels))
        events_ns = sorted(session.unix_ns(session.streams["events"]["host_t_ns"]))
        frame_ns = session.unix_ns(session.streams["skin"]["host_t_ns"])

        def by_topic(c) -> dict[str, list[int]]:
            got: dict[str, list[int]] = {}
            for cid, t, _ in c.messages:
                got.setdefault(c.channels[cid]["topic"], []).append(t)
            return got

        def whole_run(c) -> bool:  # every event, both maps up to the trial's last frames, poses
            got = by_topic(c)
            return (len(got.get(S.LOG_TOPIC, ())) >= len(events_ns)
                    and all(max(got.get(t, [0])) >= frame_ns[-1] - 2e8 for t in S.SKIN_TOPICS.values())
                    and all(got.get(t) for t in (S.TCP_TOPIC, S.TF_TOPIC, S.SKIN_SUMMARY_TOPIC)))

        client.read_until(whole_run, limit=100_000)
        client.close()
        got = by_topic(client)
        assert sorted(got[S.LOG_TOPIC]) == events_ns
        for topic in S.SKIN_TOPICS.values():  # the maps of the whole trial, thinned, at frame times
            sent = np.sort(got[topic])
            assert np.isin(sent, frame_ns).all() and len(set(sent)) == len(sent)
            assert sent[0] - frame_ns[0] < 2e8 and frame_ns[-1] - sent[-1] < 2e8
        time.sleep(0.5)
        assert th.is_alive()  # still holding
        capsys.readouterr()
        app._on_sigint(signal.SIGINT, None)
        th.join(timeout=30)
        assert not th.is_alive() and done["result"].outcome == "complete"
        assert "the run has already ended and its files are written" in capsys.readouterr().err
    finally:
        runner.request_termination("test over")
        th.join(timeout=30)
        runner._termination.clear()  # the request was this test's; later tests run trials again


def _status(port: int, path: str = "/", **headers) -> str:
    """The status line the live view answers a WebSocket upgrade with these headers."""
    try:
        client = FoxgloveClient("127.0.0.1", port, timeout=5, path=path, headers=headers)
    except ConnectionError as e:
        return str(e).splitlines()[0]
    client.close()
    return "101"


def test_a_page_on_another_site_is_refused_and_this_machine_accepted(caplog):
    # A browser page on any site may open a WebSocket to 127.0.0.1; its Origin says where it is
    # from. A name rebound to 127.0.0.1 (DNS rebinding) shows in the Host header.
    with caplog.at_level(logging.WARNING, logger="layerskin_exp.log.view.live"), \
            LiveView("gripper", port=0) as view:
        own = f"http://127.0.0.1:{view.port}"
        assert _status(view.port, Origin="http://evil.example") == "handshake refused: HTTP/1.1 403 Forbidden"
        assert _status(view.port, Host=f"evil.example:{view.port}") == "handshake refused: HTTP/1.1 403 Forbidden"
        assert _status(view.port, Origin=own) == "101"
        assert _status(view.port, Origin=f"http://localhost:{view.port}", Host=f"localhost:{view.port}") == "101"
        assert _status(view.port, Origin="https://app.foxglove.dev") == "101"  # the Foxglove web app
        assert _status(view.port) == "101"  # no Origin: not a browser page
    refused = [r.getMessage() for r in caplog.records if "refused the client" in r.getMessage()]
    assert len(refused) == 2
    assert "Origin 'http://evil.example' is not an allowed host" in refused[0]
    assert f"Host 'evil.example:{view.port}' is not an allowed host" in refused[1]


def test_a_remote_viewer_gets_in_with_the_token_only():
    with LiveView("gripper", port=0, token="s3cret-token", allowed_hosts=["127.0.0.1"]) as view:
        remote = {"Host": f"lab-pc.example:{view.port}", "Origin": "http://lab-pc.example"}
        assert _status(view.port, **remote).endswith("403 Forbidden")
        assert _status(view.port, path="/?token=wrong", **remote).endswith("403 Forbidden")
        assert _status(view.port, path="/?token=s3cret-token", **remote) == "101"
        assert _status(view.port, Origin="http://localhost:1234").endswith("403 Forbidden")  # not listed here
        assert _status(view.port) == "101"
