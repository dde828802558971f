"""LiveView: what a SessionWriter writes, served while it runs over Foxglove's WebSocket protocol.

Attach one to a writer (`writer.live = view`) and it sees every record the writer logs. Skin
frames (424 Hz) and fast streams are thinned to one message per `period_ns` of host time per
topic (per child frame on /tf); protocol events are never dropped. The payloads are the very
bytes written to the file, with the file's log times (Unix ns), handed to the Foxglove SDK's
server (Rust, its own threads), so the writer pays one time comparison per frame and, ~30 times
a second, one send.

Channels for the topics the rig's setup streams (`layout.rig_topics`: a grip rig has no F/T or
stage channel, a platform no arm, gripper or markers) are advertised at start, so a client can
subscribe before the first trial begins; the optional ones (estimates, camera images) are
advertised when they first appear. A client that joins
late gets what was sent on a topic so far when it subscribes to it, sent to it alone: every
protocol event (/log) and the latest REPLAY_MAX_PER_TOPIC messages of each other topic (about
ten minutes at display rate), so a run that ended before the client connected (--hold) is
shown whole: maps, plots, poses and events.

Subprotocols: the SDK's server (foxglove-sdk 0.30) speaks `foxglove.sdk.v1` (and `.v1.1`), which
the current Foxglove app offers. It refuses clients that offer only `foxglove.websocket.v1`
(older Foxglove Studio releases, ws-protocol clients) with HTTP 400; the SDK does not allow
accepting them. A refusal is reported once as a warning naming the subprotocol, later ones at
debug level, instead of the SDK's error line per refused connection.

Who may connect: the SDK's server accepts any client, so it listens on an internal loopback port
and a gate on host:port reads each connection's HTTP upgrade request first. A client is let
through when its Host header and its Origin header (a browser's page; absent from non-browser
clients) name one of `allowed_hosts` (by default this machine, localhost / 127.0.0.1 / [::1],
and the Foxglove web app, app.foxglove.dev), or when it presents the view's `token` (a remote
viewer: ws://<host>:<port>/?token=<token>). Any other is answered 403 and logged in one warning
line naming its address and what was refused: a web page on another site (Origin), or a name
rebound to this machine (Host), cannot read the run.
"""

from __future__ import annotations

import hmac
import logging
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from urllib.parse import parse_qs, urlsplit

from layerskin_exp.log.session import schema as S
from layerskin_exp.log.view.layout import rig_topics
from layerskin_exp.log.view.skin_summary import DISPLAY_PERIOD_NS
from layerskin_exp.rig import MARKER_IDS

log = logging.getLogger(__name__)

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.sdk.v1.1")
REPLAY_MAX_EVENTS = 100_000  # events kept for late clients (a campaign logs tens per trial)
REPLAY_MAX_PER_TOPIC = 20_000  # messages kept per other topic: ~10 min at the ~30 Hz display rate
# Messages the SDK queues per client before dropping the oldest (its default, 1024, drops most of
# a replay): room for every event and the kept messages of 20 topics.
CLIENT_BACKLOG = REPLAY_MAX_EVENTS + 20 * REPLAY_MAX_PER_TOPIC

# topic -> schema (protobuf class or the name of one of the session's own messages) of what a session can carry from the start;
# a live view advertises those its rig's setup streams (rig_topics)
FIXED_TOPICS = {
    S.SKIN_TOPICS["superficial"]: S.RawImage,
    S.SKIN_TOPICS["deep"]: S.RawImage,
    S.cop_topic("superficial"): S.ImageAnnotations,
    S.cop_topic("deep"): S.ImageAnnotations,
    S.SKIN_SUMMARY_TOPIC: "layerskin.SkinSummary",
    S.WRENCH_TOPIC: "layerskin.Wrench",
    S.STAGE_TOPIC: "layerskin.StagePosition",
    S.TCP_TOPIC: S.PoseInFrame,
    S.GRIPPER_TOPIC: "layerskin.GripperState",
    S.TF_TOPIC: S.FrameTransform,
    S.LOG_TOPIC: S.Log,
    **{S.marker_pose_topic(m): S.PoseInFrame for m in MARKER_IDS},
}


class _RefusedClients(logging.Filter):
    """The SDK logs an ERROR per refused handshake; one warning says what it means."""

    warned = False

    def filter(self, record: logging.LogRecord) -> bool:
        if "handshake failed" not in record.getMessage():
            return True
        if not _RefusedClients.warned:
            _RefusedClients.warned = True
            log.warning("live view: refused a client (%s); the server speaks %s, so a client offering only "
                        "foxglove.websocket.v1 (older Foxglove Studio) cannot connect; use the current Foxglove "
                        "app. Further refusals are logged at debug level.", record.getMessage(),
                        " / ".join(SUBPROTOCOLS))
        else:
            log.debug("live view: %s", record.getMessage())
        return False


_SDK_SERVER_LOG = logging.getLogger("foxglove.websocket.server")
if not any(isinstance(f, _RefusedClients) for f in _SDK_SERVER_LOG.filters):
    _SDK_SERVER_LOG.addFilter(_RefusedClients())


DEFAULT_ALLOWED_HOSTS = ("localhost", "127.0.0.1", "::1", "app.foxglove.dev")
_MAX_REQUEST = 16384  # bytes of an upgrade request's head (a browser's is ~1 KB)
_REQUEST_TIMEOUT_S = 5.0


def _host_name(value: str) -> str:
    """The host of a Host header ("127.0.0.1:8765", "[::1]:8765", "localhost"), lower case."""
    value = value.strip().lower()
    if value.startswith("["):
        return value[1:value.find("]")] if "]" in value else value
    return value.rsplit(":", 1)[0] if value.count(":") == 1 else value


class _Gate:
    """Listens on host:port; forwards each connection whose upgrade request passes `refusal` to
    the SDK's server on 127.0.0.1:upstream_port, byte for byte, and answers the others 403."""

    def __init__(self, host: str, port: int, upstream_port: int, allowed_hosts: Iterable[str],
                 token: str | None) -> None:
        self.upstream_port = upstream_port
        self.allowed = {_host_name(h) for h in allowed_hosts}
        self.token = token or None
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.create_server((host, port), family=family)
        self.port = self.sock.getsockname()[1]
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._closed = False
        self._acceptor = threading.Thread(target=self._accept, name="live-view-gate", daemon=True)
        self._acceptor.start()

    def refusal(self, target: str, headers: dict[str, str]) -> str | None:
        """Why a client with this request target and headers (names lower case) is refused, or None."""
        if self.token is not None:
            given = parse_qs(urlsplit(target).query).get("token", [""])[0]
            if hmac.compare_digest(given.encode(), self.token.encode()):
                return None
        host = _host_name(headers.get("host", ""))
        origin = headers.get("origin")
        allowed = ", ".join(sorted(self.allowed))
        hint = ("" if self.token is None else "; a remote viewer adds ?token=<live token> to the URL")
        if host not in self.allowed:
            return f"Host {headers.get('host', '(none)')!r} is not an allowed host ({allowed}){hint}"
        if origin is not None and (urlsplit(origin.strip()).hostname or origin.strip().lower()) not in self.allowed:
            return f"Origin {origin!r} is not an allowed host ({allowed}){hint}"
        return None

    def _accept(self) -> None:
        while True:
            try:
                conn, addr = self.sock.accept()
            except OSError:
                return  # closed
            if self._closed:
                conn.close()
                return
            threading.Thread(target=self._serve, args=(conn, addr), name="live-view-client", daemon=True).start()

    def _serve(self, conn: socket.socket, addr) -> None:
        peer = f"{addr[0]}:{addr[1]}"
        try:
            conn.settimeout(_REQUEST_TIMEOUT_S)
            head = b""
            while b"\r\n\r\n" not in head:
                chunk = conn.recv(4096)
                if not chunk or len(head) + len(chunk) > _MAX_REQUEST:
                    conn.close()
                    return
                head += chunk
            lines = head.split(b"\r\n\r\n", 1)[0].decode("latin-1").split("\r\n")
            parts = lines[0].split(" ")
            target = parts[1] if len(parts) >= 2 else ""
            headers = {}
            for line in lines[1:]:
                name, sep, value = line.partition(":")
                if sep:
                    headers[name.strip().lower()] = value.strip()
            why = self.refusal(target, headers)
            if why is not None:
                log.warning("live view: refused the client at %s: %s", peer, why)
                conn.sendall(b"HTTP/1.1 403 Forbidden\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
                conn.close()
                return
            conn.settimeout(None)
            up = socket.create_connection(("127.0.0.1", self.upstream_port))
        except OSError:
            conn.close()
            return
        with self._lock:
            if self._closed:
                conn.close()
                up.close()
                return
            self._open.update((conn, up))
        up.sendall(head)
        threading.Thread(target=self._pipe, args=(up, conn), daemon=True).start()
        self._pipe(conn, up)

    def _pipe(self, src: socket.socket, dst: socket.socket) -> None:
        """Copy src to dst until either ends; then close both."""
        try:
            while True:
                data = src.recv(65536)
                if not data:
                    break
                dst.sendall(data)
        except OSError:
            pass
        for s in (src, dst):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()
        with self._lock:
            self._open.difference_update((src, dst))

    def close(self) -> None:
        with self._lock:
            self._closed = True
            open_, self._open = list(self._open), set()
        try:  # wakes the accept() under way (a plain close leaves the port listening until it returns)
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.sock.close()
        self._acceptor.join(timeout=5.0)
        for s in open_:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()


class _Listener:
    """The SDK's ServerListener: a subscription to a topic gets what was sent on it before."""

    def __init__(self, view: LiveView) -> None:
        self.view = view

    def on_subscribe(self, client, channel) -> None:
        self.view._replay(client, channel.topic)

    def __getattr__(self, name: str):
        # every other ServerListener callback (on_unsubscribe, on_client_advertise, ...): no-op
        if name.startswith("on_"):
            return lambda *args, **kwargs: None
        raise AttributeError(name)


class LiveView:
    """A Foxglove WebSocket server on host:port (port 0: any free port, see .port) for a session
    of the rig `setup` ("platform" or "gripper"), whose channels it advertises at start.

    allowed_hosts: the names a client's Host and Origin headers may give; token: lets any client
    that adds ?token=<token> to the URL in (a remote viewer); see the module docstring.

    Open it in Foxglove with "Open connection" -> Foxglove WebSocket -> ws://127.0.0.1:<port>;
    `layout_json(setup)` is the rig's layout in the app's import format. close() stops the
    server; hold(stop) keeps it serving (after a run) until stop() says so or Ctrl-C.
    """

    def __init__(self, setup: str, host: str = "127.0.0.1", port: int = 8765, period_ns: int = DISPLAY_PERIOD_NS,
                 name: str = "layerskin-exp", allowed_hosts: Iterable[str] = DEFAULT_ALLOWED_HOSTS,
                 token: str | None = None) -> None:
        import foxglove

        streamed = rig_topics(setup)  # refuses an unknown setup, naming it

        self._foxglove = foxglove
        self.period_ns = int(period_ns)
        self.context = foxglove.Context()
        self._channels: dict[str, object] = {}
        self._last: dict[tuple, int] = {}
        self._last_frame_ns: int | None = None
        self._sent: dict[str, deque] = {}  # topic -> (payload, log time) of what was sent, for late clients
        self._lock = threading.Lock()
        for topic, schema in FIXED_TOPICS.items():
            if topic in streamed:
                self._channel(topic, schema)
        self.server = foxglove.start_server(name=name, host="127.0.0.1", port=0, context=self.context,
                                            server_listener=_Listener(self), message_backlog_size=CLIENT_BACKLOG)
        try:
            self.gate = _Gate(host, port, self.server.port, allowed_hosts, token)
        except BaseException:
            self.server.stop()
            raise
        self.host, self.port = host, self.gate.port
        log.info("live view on ws://%s:%d (subprotocol %s)", host, self.port, " / ".join(SUBPROTOCOLS))

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def _channel(self, topic: str, schema):
        ch = self._channels.get(topic)
        if ch is None:
            fg = self._foxglove
            cls = S.proto_class(schema)
            spec = fg.Schema(name=cls.DESCRIPTOR.full_name, encoding="protobuf", data=S.proto_schema_data(cls))
            ch = self._channels[topic] = fg.Channel(topic, schema=spec, message_encoding="protobuf",
                                                    context=self.context)
        return ch

    def frame(self, frame, head: bytes, t_ns: int) -> None:
        """Both layers of a skin frame (head: its RawImage bytes before the pixels; t_ns: its log
        time, Unix ns), thinned."""
        t = int(t_ns)
        if self._last_frame_ns is not None and t - self._last_frame_ns < self.period_ns:
            return
        self._last_frame_ns = t
        self._send(S.SKIN_TOPICS["superficial"], S.RawImage, head + frame.superficial.tobytes(), t)
        self._send(S.SKIN_TOPICS["deep"], S.RawImage, head + frame.deep.tobytes(), t)

    def message(self, topic: str, schema, payload: bytes, t_ns: int, key: str | None = "") -> None:
        """One message as written to the file. key: thinned per (topic, key); None: always sent.
        Protocol events (/log) are never thinned."""
        if key is not None and topic != S.LOG_TOPIC:
            k = (topic, key)
            last = self._last.get(k)
            if last is not None and t_ns - last < self.period_ns:
                return
            self._last[k] = t_ns
        self._send(topic, schema, payload, int(t_ns))

    def _send(self, topic: str, schema, payload: bytes, t_ns: int) -> None:
        """Send to the subscribed clients and keep for later ones (under the lock, so a client
        subscribing meanwhile gets the message either live or replayed)."""
        with self._lock:
            sent = self._sent.get(topic)
            if sent is None:
                sent = self._sent[topic] = deque(maxlen=REPLAY_MAX_EVENTS if topic == S.LOG_TOPIC
                                                 else REPLAY_MAX_PER_TOPIC)
            sent.append((payload, t_ns))
            self._channel(topic, schema).log(payload, log_time=t_ns)

    @staticmethod
    def layout_json(setup: str, *, estimate: bool = False, camera: bool = False) -> str:
        """The app-format layout (Layouts > Import) of a rig's live view."""
        import json

        from layerskin_exp.log.view.layout import rig_layout

        return json.dumps(rig_layout(setup, estimate=estimate, camera=camera))

    def _replay(self, client, topic: str) -> None:
        """Send what was sent on `topic` so far to one client (its sink), not again to the others.

        foxglove-sdk 0.30's Python Client carries only its id; a websocket client's sink id is
        drawn from the same sequence as its client id as long as the process opens no other SDK
        sink (this module opens none), so the id addresses its sink. tests/log/test_live.py checks
        that a late client gets each event once and an early one sees no repeat."""
        sink = getattr(client, "sink_id", None) or client.id
        with self._lock:
            channel = self._channels.get(topic)
            for payload, t_ns in self._sent.get(topic, ()) if channel is not None else ():
                channel.log(payload, log_time=t_ns, sink_id=sink)

    def hold(self, stop: Callable[[], bool] = lambda: False, poll_s: float = 0.2) -> None:
        """Keep serving until stop() is true or Ctrl-C (after a run, so a client can still look)."""
        print(f"run finished; the live view stays up on {self.url}, replaying the run to clients that connect "
              "now, until you stop it (Ctrl-C)", flush=True)
        try:
            while not stop():
                time.sleep(poll_s)
        except KeyboardInterrupt:
            pass

    def close(self) -> None:
        self.gate.close()
        self.server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

