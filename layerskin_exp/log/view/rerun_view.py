"""Sessions in the rerun viewer: `python -m layerskin_exp.log view SESSION... [--web | --save OUT]`.

Each session becomes one rerun recording, logged from the project's reader with rr.log /
rr.send_columns rather than handed to rerun's MCAP importer: the reader reads every file this
project ever wrote (format 1 JSON channels, damaged and cut-off files, up to the damage), puts
every stream on one host timeline, and lets the wrench be logged as Scalars, the events as a
TextLog and the maps as images, so the blueprint below can name what it shows. The importer would
give each channel's fields as generic structs that no plot or log view picks up by itself.

The blueprint is the session's Foxglove layout (layout.session_layout, built from the file's own
topics) translated panel by panel: Image -> Spatial2DView of the map, Plot -> TimeSeriesView of
the same series, ThreeDee -> Spatial3DView of the frame tree, Log -> TextLogView of the events.
Plot series "TOPIC.field[i]" are logged as Scalars on entity "TOPIC/field", one series per index.

rerun-sdk is the optional extra `view` (`pip install 'layerskin-exp[view]'`; its wheel needs
Python >= 3.11).
"""

from __future__ import annotations

import os
import re
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from layerskin_exp.log.errors import SessionFileError
from layerskin_exp.log.session import messages as M
from layerskin_exp.log.session import schema as S
from layerskin_exp.log.session.reader import Session, load_session
from layerskin_exp.types import ADC_MAX

APP_ID = "layerskin-exp"
TIMELINE = "time"  # the MCAP log time: host receive time on the Unix epoch
RIG_ROOT = "/rig"  # the frame tree (/tf): /rig/base/tool/skin, /rig/base/camera/marker_0, ...
INSTALL_HINT = "pip install 'layerskin-exp[view]'  (or: pip install rerun-sdk; Python >= 3.11)"

# topic -> (reader stream, {field path in the layout's plot series: reader field})
_TOPIC_FIELDS = {
    S.WRENCH_TOPIC: ("wrench", {"force_n": "force_n", "torque_nm": "torque_nm"}),
    S.STAGE_TOPIC: ("stage", {"position_mm": "position_mm"}),
    S.GRIPPER_TOPIC: ("gripper", {"position_mm": "position_mm", "requested_mm": "requested_mm"}),
    S.TCP_TOPIC: ("tcp", {"pose.position": "position_m"}),
    S.ESTIMATE_FORCE_TOPIC: ("estimate_force", {"force_n": "force_n"}),
    S.ESTIMATE_SLIP_TOPIC: ("estimate_slip", {"score": "score"}),
}
_LEVELS = {"error": "ERROR", "safety": "WARN", "guard": "WARN"}  # as schema.LOG_LEVELS for foxglove.Log
_SERIES = re.compile(r"^(?P<topic>/[^.]+)\.(?P<field>[A-Za-z_][\w.]*?)(?:\[(?P<i>\d+)\]|\.(?P<axis>[xyz]))?$")


class ViewerError(RuntimeError):
    """The viewer cannot be opened (rerun missing, a bad argument); the message says what to do."""


def require_rerun():
    """The rerun module, or a ViewerError saying how to install it."""
    if sys.version_info < (3, 11):
        raise ViewerError(f"the viewer needs rerun-sdk, whose wheels need Python >= 3.11 (this is "
                          f"{sys.version.split()[0]}); run it from a Python 3.11+ environment: {INSTALL_HINT}")
    try:
        import rerun
        import rerun.blueprint  # noqa: F401
    except ImportError as exc:
        raise ViewerError(f"the viewer needs the rerun-sdk package, which is not installed ({exc}); "
                          f"install it with: {INSTALL_HINT}") from None
    return rerun


@dataclass(frozen=True)
class Series:
    """One plot line: the entity its Scalars are logged on and its column there."""

    entity: str
    column: int
    label: str


def parse_series(path: str, label: str) -> Series:
    """A Foxglove plot path ("/ft/wrench.force_n[0]", "/arm/tcp.pose.position.x") -> Series."""
    m = _SERIES.match(path)
    if m is None:
        raise ValueError(f"plot path {path!r} is not TOPIC.field[, [i] or .x/.y/.z]")
    column = int(m["i"]) if m["i"] is not None else "xyz".index(m["axis"]) if m["axis"] else 0
    return Series(f"{m['topic']}/{m['field'].replace('.', '/')}", column, label)


def session_topics(path) -> set[str]:
    from layerskin_exp.log.container.scan import scan

    return {c.topic for c in scan(path).channels.values()}


# ------------------------------------------------------------------------------ blueprint


def blueprint(topics: set[str]):
    """The rerun blueprint of the Foxglove layout for these topics (see the module docstring)."""
    rrb = require_rerun().blueprint
    from layerskin_exp.log.view.layout import _plain, session_layout

    tree = _plain(session_layout(topics))

    def view(panel: dict):
        kind, cfg, title = panel["panelType"], panel.get("config") or {}, panel.get("title")
        if kind == "Image":
            return rrb.Spatial2DView(origin=cfg["imageMode"]["imageTopic"], name=title)
        if kind == "Plot":
            series = [parse_series(p["value"], p.get("label") or p["value"]) for p in cfg["paths"]]
            return rrb.TimeSeriesView(origin="/", contents=sorted({s.entity for s in series}), name=title)
        if kind == "ThreeDee":
            return rrb.Spatial3DView(origin=RIG_ROOT, name=title)
        if kind == "Log":
            return rrb.TextLogView(origin=S.EVENTS_TOPIC, name=title)
        raise ValueError(f"layout panel type {kind!r} has no rerun view here")

    def node(content: dict):
        if content["type"] == "panel":
            return view(content)
        items = content["items"]
        parts = [node(i["content"]) for i in items]
        shares = [float(i.get("proportion", 1)) for i in items]
        if content["direction"] == "row":
            return rrb.Horizontal(*parts, column_shares=shares)
        return rrb.Vertical(*parts, row_shares=shares)

    return rrb.Blueprint(node(tree["content"]), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"), rrb.TimePanel(state="collapsed"))


def plot_series(topics: set[str]) -> dict[str, list[Series]]:
    """entity -> its series (in column order), for every plot of the layout of these topics."""
    from layerskin_exp.log.view.layout import _plain, session_layout

    out: dict[str, list[Series]] = {}

    def walk(content: dict) -> None:
        if content["type"] == "panel":
            if content["panelType"] == "Plot":
                for p in content["config"]["paths"]:
                    s = parse_series(p["value"], p.get("label") or p["value"])
                    out.setdefault(s.entity, []).append(s)
            return
        for item in content["items"]:
            walk(item["content"])

    walk(_plain(session_layout(topics))["content"])
    return {e: sorted(v, key=lambda s: s.column) for e, v in out.items()}


# ------------------------------------------------------------------------------ logging


_TURBO = None


def skin_rgb(maps: np.ndarray) -> np.ndarray:
    """(N, 16, 16) counts -> (N, 16, 16, 3) uint8, turbo over 0..ADC_MAX, rows flipped (+y up).

    As the stored layout shows them: rerun's Image has no value range or colormap for a
    single-channel image, and 12-bit counts in a 16-bit image would be drawn nearly black."""
    global _TURBO
    if _TURBO is None:
        from matplotlib import colormaps

        _TURBO = (colormaps["turbo"](np.linspace(0.0, 1.0, ADC_MAX + 1))[:, :3] * 255).round().astype(np.uint8)
    idx = np.clip(np.asarray(maps), 0, ADC_MAX).astype(np.intp)
    return _TURBO[idx[:, ::-1, :]]


def _summary_fields(path: Path, session: Session) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """The /skin/summary view channel (display-rate totals and CoP), which the reader skips."""
    from mcap.reader import make_reader

    times, rows = [], []
    try:
        with open(path, "rb") as fh:
            for _schema, channel, msg in make_reader(fh).iter_messages(topics=[S.SKIN_SUMMARY_TOPIC]):
                if channel.message_encoding != "protobuf":
                    return None  # format 1 (JSON): the layout's skin plots stay empty
                m = M.CLASSES["layerskin.SkinSummary"].FromString(msg.data)
                times.append(msg.log_time)
                rows.append(m)
    except Exception:  # noqa: BLE001 - a damaged file: the reader already said what it could read
        return None
    if not rows:
        return None
    fields = {}
    for layer in S.SKIN_TOPICS:
        fields[f"{layer}.total_counts"] = np.array([getattr(r, layer).total_counts for r in rows])
        fields[f"{layer}.cop_mm"] = np.array([list(getattr(r, layer).cop_mm) or [np.nan, np.nan] for r in rows])
    return np.array(times, np.int64), fields


def log_session(rr, rec, path, session: Session, topics: set[str]) -> None:
    """Everything the blueprint shows, logged to recording `rec`."""
    unix = session.unix_ns

    def timeline(t_ns):
        return rr.TimeColumn(TIMELINE, timestamp=np.asarray(t_ns, np.int64).astype("datetime64[ns]"))

    skin = session.streams.get("skin")
    if skin is not None and len(skin["t_ns"]):
        t = unix(skin["t_ns"])
        for layer, topic in S.SKIN_TOPICS.items():
            rgb = skin_rgb(skin[layer])
            for k in range(len(t)):
                rec.set_time(TIMELINE, timestamp=np.datetime64(int(t[k]), "ns"))
                rec.log(topic, rr.Image(rgb[k]))
    cam = session.streams.get("camera")
    if cam is not None and len(cam["t_ns"]):
        for k, img in enumerate(cam["image"]):
            rec.set_time(TIMELINE, timestamp=np.datetime64(int(unix(cam["t_ns"][k])), "ns"))
            rec.log(S.CAMERA_TOPIC, rr.Image(img))

    values: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for topic, (stream, fields) in _TOPIC_FIELDS.items():
        arrays = session.streams.get(stream)
        if arrays is None:
            continue
        for field, key in fields.items():
            if key in arrays:
                values[f"{topic}/{field.replace('.', '/')}"] = (unix(arrays["t_ns"]), arrays[key])
    summary = _summary_fields(Path(path), session) if S.SKIN_SUMMARY_TOPIC in topics else None
    if summary is not None:
        t, fields = summary
        for field, v in fields.items():
            values[f"{S.SKIN_SUMMARY_TOPIC}/{field.replace('.', '/')}"] = (t, v)
    for entity, series in plot_series(topics).items():
        if entity not in values:
            continue
        t, v = values[entity]
        v = np.asarray(v, np.float64).reshape(len(t), -1)
        cols = [s.column for s in series]
        rec.log(entity, rr.SeriesLines(names=[s.label for s in series]), static=True)
        rec.send_columns(entity, indexes=[timeline(t)], columns=rr.Scalars.columns(scalars=v[:, cols]))

    ev = session.streams.get("events")
    if ev is not None and len(ev["t_ns"]):
        text = [f"{k}: {m}" + (f" {d}" if d else "") for k, m, d in zip(ev["kind"], ev["message"], ev["detail"],
                                                                        strict=True)]
        rec.send_columns(S.EVENTS_TOPIC, indexes=[timeline(unix(ev["t_ns"]))],
                         columns=rr.TextLog.columns(text=text, level=[_LEVELS.get(k, "INFO") for k in ev["kind"]]))
    _log_frames(rr, rec, session, timeline)


def _log_frames(rr, rec, session: Session, timeline) -> None:
    """The frame tree (/tf) as nested entities under RIG_ROOT, each frame drawn as axes."""
    tf = session.streams.get("transforms")
    if tf is None or not len(tf["t_ns"]):
        return
    parent = {}
    for p, c in zip(tf["parent_frame_id"], tf["child_frame_id"], strict=True):
        parent.setdefault(c, p)

    def entity(frame: str) -> str:
        chain, f = [frame], frame
        while f in parent and parent[f] not in chain:
            f = parent[f]
            chain.append(f)
        return RIG_ROOT + "/" + "/".join(reversed(chain))

    children = np.asarray(tf["child_frame_id"], dtype=object)
    t = session.unix_ns(tf["t_ns"])
    for frame in dict.fromkeys(tf["child_frame_id"]):
        sel = np.flatnonzero(children == frame)
        path = entity(frame)
        rec.log(path, rr.TransformAxes3D(0.02, show_frame=True), static=True)
        rec.send_columns(path, indexes=[timeline(t[sel])], columns=rr.Transform3D.columns(
            translation=tf["translation_m"][sel], quaternion=tf["rotation_xyzw"][sel]))


# ------------------------------------------------------------------------------ the command


def _load(paths) -> list[tuple[Path, Session, set[str]]]:
    out = []
    for p in paths:
        path = Path(p)
        if not path.exists():
            raise SessionFileError(f"{path}: no such file; give the path of a session (.mcap)")
        if path.is_dir():
            found = sorted(path.rglob("*.mcap"))
            if not found:
                raise SessionFileError(f"{path}: a folder with no .mcap session in it")
            out += _load(found)
            continue
        session = load_session(path, warn=False)
        out.append((path, session, session_topics(path)))
    return out


def recordings(paths, *, rr=None):
    """[(RecordingStream, blueprint)] for the sessions at paths, everything logged."""
    sessions = _load(paths)  # bad paths are named before a missing rerun is
    rr = rr or require_rerun()
    out = []
    for path, session, topics in sessions:
        rec = rr.RecordingStream(APP_ID, recording_id=str(path.resolve()))
        rec.send_recording_name(path.stem)
        log_session(rr, rec, path, session, topics)
        out.append((rec, blueprint(topics)))
    return out


def save(paths, out) -> list[Path]:
    """Each session's recording (data and blueprint) as an .rrd: out is the file for one session,
    a folder for several (one <name>.rrd each). Returns the files written."""
    out = Path(out)
    recs = recordings(paths)
    if len(recs) > 1 or out.is_dir():
        out.mkdir(parents=True, exist_ok=True)
        targets = [out / f"{Path(rec.get_recording_id()).stem}.rrd" for rec, _ in recs]
        if len(set(targets)) < len(targets):
            raise ViewerError(f"sessions with the same file name would share one file in {out}; save them "
                              "one by one")
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        targets = [out]
    for (rec, bp), target in zip(recs, targets, strict=True):
        rec.save(target, default_blueprint=bp)
        rec.flush()
        rec.disconnect()
    return targets


def serve_command(rrd_files, *, port: int = 9090, grpc_port: int = 9876, bind: str = "127.0.0.1") -> list[str]:
    """The rerun CLI line that serves these recordings to the web viewer on http://bind:port.

    The CLI rather than rr.serve_web_viewer: the SDK's servers listen on every interface, the
    CLI's `--bind` keeps a session on this machine unless asked otherwise."""
    return [sys.executable, "-m", "rerun", *map(str, rrd_files), "--web-viewer", "--bind", bind,
            "--web-viewer-port", str(port), "--port", str(grpc_port)]


def web_address(port: int, grpc_port: int, host: str = "127.0.0.1") -> str:
    """The page that opens the served recordings."""
    return f"http://{host}:{port}/?url=rerun%2Bhttp%3A%2F%2F{host}%3A{grpc_port}%2Fproxy"


def view(paths, *, web: bool = False, port: int = 9090, grpc_port: int = 9876, bind: str = "127.0.0.1") -> None:
    """Open the sessions in the native viewer, or (web=True) serve the web viewer on
    http://bind:port until interrupted."""
    if not web:
        rr = require_rerun()
        for k, (rec, bp) in enumerate(recordings(paths, rr=rr)):
            if k == 0:
                rec.spawn(port=grpc_port, default_blueprint=bp)  # starts the viewer (needs a display)
            else:
                rec.connect_grpc(f"rerun+http://127.0.0.1:{grpc_port}/proxy", default_blueprint=bp)
            rec.flush()
        return
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory(prefix="layerskin-view-") as d:
        folder = Path(d) / "recordings"
        folder.mkdir()
        files = save(paths, folder)
        print(f"rerun web viewer: {web_address(port, grpc_port, bind)}  (Ctrl-C to stop)", flush=True)
        # Its own process group: `python -m rerun` runs the viewer binary as a child of its own,
        # and stopping the view must stop both.
        proc = subprocess.Popen(serve_command(files, port=port, grpc_port=grpc_port, bind=bind),
                                start_new_session=True)
        previous = signal.signal(signal.SIGTERM, _interrupt)  # a terminated view stops its server too
        try:
            proc.wait()
        except KeyboardInterrupt:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait()
        finally:
            signal.signal(signal.SIGTERM, previous)
    if proc.returncode not in (0, -15, None):
        raise ViewerError(f"the rerun web viewer exited with status {proc.returncode} (is port {port} or "
                          f"{grpc_port} in use? choose others with --port / --grpc-port)")


def _interrupt(signum, frame):
    raise KeyboardInterrupt
