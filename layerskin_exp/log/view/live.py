"""LiveView: what a SessionWriter writes, served while it runs over Foxglove's WebSocket protocol.

Attach one to a writer (`writer.live = view`) and it sees every record the writer logs. Skin
frames (424 Hz) and fast streams are thinned to one message per `period_ns` of host time per
topic (per child frame on /tf); protocol events are never dropped. The payloads are the very
bytes written to the file, handed to the Foxglove SDK's server (Rust, its own threads), so
the writer pays one time comparison per frame and, ~30 times a second, one send.

Channels for the fixed topics are advertised at start, so a client can subscribe before the
first trial begins; marker topics are advertised when they first appear.
"""

from __future__ import annotations

import logging

from layerskin_exp.log.session import schema as S
from layerskin_exp.log.view.skin_summary import DISPLAY_PERIOD_NS

log = logging.getLogger(__name__)

# topic -> schema (protobuf class or JSON schema name) of what a session can carry from the start
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
}


class LiveView:
    """A Foxglove WebSocket server on host:port (port 0: any free port, see .port).

    Open it in Foxglove with "Open connection" -> ws://127.0.0.1:<port>; `layout_json()` is the
    same layout the session files carry. close() stops the server.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, period_ns: int = DISPLAY_PERIOD_NS,
                 name: str = "layerskin-exp") -> None:
        import foxglove

        self._foxglove = foxglove
        self.period_ns = int(period_ns)
        self.context = foxglove.Context()
        self._channels: dict[str, object] = {}
        self._last: dict[tuple, int] = {}
        self._last_frame_ns: int | None = None
        for topic, schema in FIXED_TOPICS.items():
            self._channel(topic, schema)
        self.server = foxglove.start_server(name=name, host=host, port=port, context=self.context)
        self.host, self.port = host, self.server.port
        log.info("live view on ws://%s:%d", host, self.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def _channel(self, topic: str, schema):
        ch = self._channels.get(topic)
        if ch is None:
            fg = self._foxglove
            if isinstance(schema, str):
                spec = fg.Schema(name=schema, encoding="jsonschema", data=S.JSON_SCHEMAS[schema])
                encoding = "json"
            else:
                spec = fg.Schema(name=schema.DESCRIPTOR.full_name, encoding="protobuf",
                                 data=S.proto_schema_data(schema))
                encoding = "protobuf"
            ch = self._channels[topic] = fg.Channel(topic, schema=spec, message_encoding=encoding,
                                                    context=self.context)
        return ch

    def frame(self, frame, head: bytes, t_ns: int) -> None:
        """Both layers of a skin frame (head: its RawImage bytes before the pixels; t_ns: its log
        time, Unix ns), thinned."""
        t = int(t_ns)
        if self._last_frame_ns is not None and t - self._last_frame_ns < self.period_ns:
            return
        self._last_frame_ns = t
        self._channels[S.SKIN_TOPICS["superficial"]].log(head + frame.superficial.tobytes(), log_time=t)
        self._channels[S.SKIN_TOPICS["deep"]].log(head + frame.deep.tobytes(), log_time=t)

    def message(self, topic: str, schema, payload: bytes, t_ns: int, key: str | None = "") -> None:
        """One message as written to the file. key: thinned per (topic, key); None: always sent."""
        if key is not None:
            k = (topic, key)
            last = self._last.get(k)
            if last is not None and t_ns - last < self.period_ns:
                return
            self._last[k] = t_ns
        self._channel(topic, schema).log(payload, log_time=int(t_ns))

    @staticmethod
    def layout_json(setup: str, *, estimate: bool = False, camera: bool = False) -> str:
        """The app-format layout (Layouts > Import) of a rig's live view."""
        import json

        from layerskin_exp.log.view.layout import rig_layout

        return json.dumps(rig_layout(setup, estimate=estimate, camera=camera))

    def close(self) -> None:
        self.server.stop()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

