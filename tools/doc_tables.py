"""Tables of the user guide that are generated from the code, the configs and committed outputs.

Each generated table sits in a page under docs/ between two markers:

    <!-- generated: NAME -->
    ...
    <!-- end generated: NAME -->

`python tools/doc_tables.py` rewrites every such section from its source; `--check` only
compares and exits 1 naming the sections that differ (tests/test_docs.py runs the check, so a
table edited by hand, or a config changed without regenerating the page, fails the suite).

Sources:
  protocol-keys:<app>      conf/<app>.yaml and the schemas in protocols/config.py; the allowed
                           range of each key is the refusal the schema gives an out-of-range value
  device-options:<device>  hardware/<device>/config.py (the driver's dataclass), same probing
  device-faults:<device>   the fault-injection arguments the device's emulator declares
  sim-params               conf/sim/default.yaml (value and the comment that gives its source)
  brackets                 layerskin_exp/sim/brackets.yaml
  campaign-force:<folder>  docs/<folder>/results.json (a report's force table)
  lerobot-load:<name>      docs/<name>.json (tools/lerobot_load_check.py --json: its --markdown)
  campaign-characterisation:<folder>  the same file's characterisation, beside the study's
  benchmark-run:<stem>     docs/benchmarks/<stem>.json, a `python -m benchmarks.run --json` output
  benchmark-list:<stem>    benchmarks/*.py: each one's name, the first line of its docstring, and
                           whether docs/benchmarks/<stem>.json holds it
  study:<part>             analysis/study.py, the study's published values the report prints
                           beside ours (force, characterisation, tracking, slip)
  yardstick3d:<stem>       docs/validation/<stem>.json (python -m layerskin_exp.sim.fem_reference.yardstick3d
                           --json): the fast model against the 3D model, the design and its variants
  session-channels         a session written here by SessionWriter (one message of each kind, and
                           the views protocols/runner.py adds): each channel's topic, encoding,
                           schema and fields as the file holds them; rates from the configs
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

SECTION = re.compile(r"(<!-- generated: (?P<name>[^ ]+) -->\n)(?P<body>.*?)(<!-- end generated: (?P=name) -->)", re.S)

# Unit of a key, read from how its name ends (the project's keys carry their unit).
UNITS = [
    ("_mm_s2", "mm/s²"), ("_rad_s2", "rad/s²"), ("_m_s2", "m/s²"), ("_mm_s", "mm/s"), ("_deg_s", "deg/s"),
    ("_rad_s", "rad/s"), ("_m_s", "m/s"), ("_m_rad", "m, rad"), ("_mm", "mm"), ("_deg", "deg"), ("_kg", "kg"),
    ("_m", "m"), ("_n", "N"), ("_ms", "ms"), ("_s", "s"), ("_hz", "Hz"), ("_pct", "%"), ("_kpa", "kPa"),
    ("_mpa", "MPa"), ("_kohm", "kΩ"), ("_mohm", "MΩ"), ("_counts", "counts"), ("_frames", "frames"),
    ("_bytes", "bytes"), ("_fraction", "fraction"), ("_port", "port"),
]


# Keys whose name does not carry their unit.
UNIT_OF_KEY = {"grip_depth": "mm"}


def unit_of(key: str) -> str:
    if key in UNIT_OF_KEY:
        return UNIT_OF_KEY[key]
    name = key.rsplit(".", 1)[-1]
    for suffix, unit in UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def cell(text) -> str:
    """A value or text as one Markdown table cell."""
    if text is None:
        return "null"
    if isinstance(text, bool):
        return str(text).lower()
    s = str(text).replace("|", "\\|").replace("\n", " ").strip()
    return s


def code(value) -> str:
    if isinstance(value, (list, tuple)):
        value = "[" + ", ".join(cell(v) for v in value) + "]"
    return f"`{cell(value)}`"


def table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


# ---- comments of a YAML file, by dotted key -----------------------------------------------------

def yaml_comments(path: Path) -> dict[str, str]:
    """dotted key -> the comment on its line plus the comment-only lines that continue it."""
    out: dict[str, str] = {}
    stack: list[tuple[int, str]] = []
    last: str | None = None
    last_col = -1
    for raw in path.read_text().splitlines():
        stripped = raw.strip()
        if not stripped:
            last = None
            continue
        indent = len(raw) - len(raw.lstrip())
        if stripped.startswith("#"):
            if last is not None and indent > last_col:
                out[last] = (out.get(last, "") + " " + stripped.lstrip("# ").strip()).strip()
            continue
        m = re.match(r"(\s*)([A-Za-z_][\w]*):(.*)$", raw)
        if not m or stripped.startswith("- "):
            last = None
            continue
        key, rest = m.group(2), m.group(3)
        while stack and stack[-1][0] >= indent:
            stack.pop()
        dotted = ".".join([k for _, k in stack] + [key])
        stack.append((indent, key))
        comment = ""
        if "#" in rest:
            hash_at = rest.index("#")
            comment = rest[hash_at + 1:].strip()
            last_col = len(raw) - len(rest) + hash_at - 1
        else:
            last_col = indent
        out[dotted] = comment
        last = dotted
    return out


# ---- the refusals a schema gives -----------------------------------------------------------------

def _probe_values(value):
    if isinstance(value, bool):
        return []
    if isinstance(value, int):
        return [-1, 10**9]
    if isinstance(value, float) or value is None:
        return [-1.0, 0.0, 1e9]
    if isinstance(value, str):
        return [""]
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, (int, float)) for v in value):
        return [[-1e9] * len(value), [1e9] * len(value), [0] * len(value)]
    return []


def _refusal(key: str, err: Exception) -> str | None:
    msg = str(err)
    prefix = f"{key}="
    if not msg.startswith(prefix):
        return None
    return msg.split(": ", 1)[1] if ": " in msg else None


def _join(refusals: list[str]) -> str:
    seen: list[str] = []
    for r in refusals:
        if r not in seen:
            seen.append(r)
    return "; ".join(seen)


# ---- protocol keys --------------------------------------------------------------------------------

def _compose_dict(app: str):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    import protocols.config  # noqa: F401 - stores the schemas
    from layerskin_exp.config import CONF_DIR, VERSION_BASE

    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base=VERSION_BASE):
            return hydra_compose(config_name=app)
    finally:
        GlobalHydra.instance().clear()


def _leaves(node, prefix=""):
    """(dotted key, value) of every leaf of a plain container tree."""
    for k, v in node.items():
        if isinstance(v, dict):
            yield from _leaves(v, f"{prefix}{k}.")
        else:
            yield f"{prefix}{k}", v


def protocol_keys(app: str) -> str:
    from omegaconf import OmegaConf
    from omegaconf.errors import ValidationError

    from layerskin_exp.config import ConfigError, validate

    cfg = _compose_dict(app)
    comments = yaml_comments(ROOT / "conf" / f"{app}.yaml")
    if app == "grip_depth":
        for name in ("translation", "torsion"):
            for k, c in yaml_comments(ROOT / "conf" / "trajectory" / f"{name}.yaml").items():
                comments.setdefault(f"trajectory.{k}", c)
    import protocols.config as schemas

    root = {"force_calibration": schemas.ForceCalibrationConfig, "grip_depth": schemas.GripDepthConfig}[app]
    for key, comment in _schema_comments(root).items():
        if not comments.get(key):
            comments[key] = comment
    rows = []
    for key, value in _leaves(OmegaConf.to_container(cfg, resolve=False)):
        if key.split(".")[0] in ("hardware", "skin", "sim"):
            continue
        refusals = []
        for probe in _probe_values(value):
            trial = copy.deepcopy(cfg)
            try:
                OmegaConf.update(trial, key, probe, merge=False)
            except ValidationError:  # the schema's type refuses the probe itself (e.g. None for a list)
                continue
            try:
                validate(trial)
            except ConfigError as err:
                r = _refusal(key, err)
                if r:
                    refusals.append(r)
        rows.append([f"`{key}`", unit_of(key), code(value), cell(comments.get(key, "")), cell(_join(refusals))])
    return table(["key", "unit", "default", "what it sets", "refused unless"], rows)


# ---- device options -------------------------------------------------------------------------------

DEVICES = {
    "skin_board": ("hardware.skin_board.config", "SkinBoardConfig"),
    "platform": ("hardware.platform.config", "GrblPlatformConfig"),
    "netft": ("hardware.netft.config", "NetFTConfig"),
    "ur5e": ("hardware.ur5e.config", "UR5eConfig"),
    "hande": ("hardware.hande.config", "HandEConfig"),
    "camera": ("hardware.camera.config", "CameraConfig"),
}


def _field_comments(cls) -> dict[str, str]:
    """field -> the comment on its line in the class body (its own class or a base's)."""
    import inspect

    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        try:
            src = inspect.getsource(klass)
        except (OSError, TypeError):
            continue
        for line in src.splitlines():
            m = re.match(r"\s+(\w+): [^=]+=.*?#\s*(.*)$", line)
            if m and "noqa" not in m.group(2):
                out[m.group(1)] = m.group(2).strip()
    return out


def _schema_comments(cls, prefix: str = "") -> dict[str, str]:
    """dotted key -> the inline comment of its field, through the nested dataclasses of `cls`."""
    import typing

    out = {f"{prefix}{k}": v for k, v in _field_comments(cls).items()}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        kind = hints.get(f.name)
        if dataclasses.is_dataclass(kind):
            out.update(_schema_comments(kind, f"{prefix}{f.name}."))
    return out


def device_options(device: str) -> str:
    import importlib

    from layerskin_exp.config import ConfigError

    module, name = DEVICES[device]
    cls = getattr(importlib.import_module(module), name)
    comments = _field_comments(cls)
    base = f"hardware.{device}"
    default = cls()
    rows = []
    for f in dataclasses.fields(cls):
        value = getattr(default, f.name)
        refusals = []
        for probe in _probe_values(value):
            if isinstance(value, tuple) and isinstance(probe, list):
                probe = tuple(probe)
            try:
                cls(**{f.name: probe})
            except ConfigError as err:
                r = _refusal(f"{base}.{f.name}", err)
                if r:
                    refusals.append(r)
            except (TypeError, ValueError):
                pass
        rows.append([f"`{base}.{f.name}`", unit_of(f.name), code(value), cell(comments.get(f.name, "")),
                     cell(_join(refusals))])
    return table(["key", "unit", "default", "note", "refused unless"], rows)


def device_faults(device: str) -> str:
    from hardware.config import fault_parameters

    rows = [[f"`+hardware.faults.{device}.{k}`", code(v)] for k, v in sorted(fault_parameters(device).items())]
    return table(["setting", "default"], rows)


# ---- the simulator --------------------------------------------------------------------------------

def sim_params() -> str:
    import yaml

    path = ROOT / "conf" / "sim" / "default.yaml"
    data = yaml.safe_load(path.read_text())
    comments = yaml_comments(path)
    rows = []

    def walk(node, prefix):
        for k, v in node.items():
            if k == "defaults":
                continue
            key = f"{prefix}{k}"
            if isinstance(v, dict):
                walk(v, key + ".")
            else:
                rows.append([f"`sim.{key}`", code(v), cell(comments.get(key, ""))])

    walk(data, "")
    return table(["key", "default", "source or reasoning (conf/sim/default.yaml)"], rows)


def brackets() -> str:
    import yaml

    data = yaml.safe_load((ROOT / "layerskin_exp" / "sim" / "brackets.yaml").read_text())["parameters"]
    rows = []
    for key, e in data.items():
        span = code(e["levels"]) if "levels" in e else f"{cell(e.get('low'))} – {cell(e.get('high'))}"
        screened = "no: " + cell(e.get("why", "")) if e.get("screen") is False else "yes"
        rows.append([f"`{key}`", code(e["nominal"]), span, screened, cell(e.get("source", ""))])
    return table(["parameter", "nominal", "bracket", "screened", "source, and what would settle it"], rows)


# ---- the session's channels ----------------------------------------------------------------------

# How often each reader stream (or, for views, each topic) is written: config keys whose values are
# read below (`skin.*`, `sim.*` from the grip_depth composition; `hardware.<device>.*` from the
# driver's dataclass), or a sentence for what follows something else.
RATES = {
    "skin": ("1000/skin.frame_period_ms", "1000/skin.frame_period_ms"),
    "wrench": ("sim.rig.ft.rate_hz", "the box's RDT output rate, set on the box"),
    "stage": ("sim.rig.platform.rate_hz", "hardware.platform.status_rate_hz"),
    "tcp": ("sim.rig.arm.rate_hz", "hardware.ur5e.rtde_frequency_hz"),
    "gripper": ("sim.rig.gripper.rate_hz", "hardware.hande.poll_rate_hz"),
    "markers": ("sim.rig.camera.fps", "hardware.camera.fps"),
    "camera": ("sim.rig.camera.fps", "hardware.camera.fps"),
}
RATES_WHEN = {
    "estimate_force": "one per downsampled skin frame, with `estimator=...`",
    "estimate_slip": "one per downsampled skin frame, with `estimator=...` and a slip detector",
    "events": "as the protocol's events occur",
    "transforms": "every {tf_ms:g} ms and whenever the jaw moves",
    "/log": "with each event",
    "/skin/summary": "every {display_ms:g} ms of skin frames",
    "cop": "every {display_ms:g} ms of skin frames",
    "/camera/markers": "with each saved image that has detections",
}


def _rate(spec: str, cfg) -> str:
    from omegaconf import OmegaConf

    per_ms = spec.startswith("1000/")
    key = spec.removeprefix("1000/")
    if not re.fullmatch(r"[a-z_]+(\.[a-z0-9_]+)+", key):
        return spec
    if key.startswith("hardware."):
        import importlib

        _, device, field = key.split(".")
        module, name = DEVICES[device]
        value = getattr(getattr(importlib.import_module(module), name)(), field)
    else:
        value = OmegaConf.select(cfg, key, throw_on_missing=True)
    hz = 1000.0 / value if per_ms else value
    return f"{hz:.4g} Hz (`{key}`{f' = {value:g} ms' if per_ms else ''})"


def _written_session(path: Path) -> None:
    """One message of every kind a session holds, written as the protocols write them: the records
    through SessionWriter.write, an image with its detections, and the views (skin summary and CoP,
    frame tree) as protocols/runner.py makes them."""
    import numpy as np

    from layerskin_exp.log import SessionWriter
    from layerskin_exp.log.view import FrameTree, SkinView
    from layerskin_exp.types import (
        GripperState,
        MarkerDetection,
        Pose,
        ProtocolEvent,
        SkinEstimate,
        StagePosition,
        TwoLayerFrame,
        Wrench,
    )

    t0, period = 10**18, 2_360_000
    with SessionWriter(path, metadata={"config": {}}, labels={"trial": 0}) as w:
        view, frames = SkinView(), FrameTree(w, "gripper")
        for i in range(view.baseline_frames + 1):
            counts = np.full((16, 16), 20, np.uint16)
            if i == view.baseline_frames:
                counts[6:9, 6:9] = 2000  # a press, so that the CoP is drawn
            t = t0 + i * period
            frame = TwoLayerFrame(counts, counts, i, t, t)
            w.write(frame)
            for topic, schema, payload in view.summary(frame):
                w.write_view(topic, schema, payload, t)
        t = t0 + 100 * period
        frames.update(t, opening_mm=20.0)
        pose = Pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), "camera", t, t)
        detection = MarkerDetection(0, pose, np.zeros((4, 2)), 0, t, t)
        for record in (Wrench(np.zeros(3), np.zeros(3), 0, t, t), StagePosition(np.zeros(3), 0, t, t),
                       Pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), "base", t, t),
                       GripperState(20.0, 20.0, 255, 100, False, 0, t, t), detection,
                       ProtocolEvent("phase", "press", t, t), SkinEstimate(np.zeros(3), 0.5, False, 0, t, t)):
            w.write(record)
        w.write_image(np.zeros((8, 8), np.uint8), t, t, detections=[detection])


def _fields(schema) -> list[str]:
    """The payload's top-level fields, from the schema the file stores (JSON schema or protobuf
    FileDescriptorSet), less the times every JSON payload repeats."""
    if schema.encoding == "jsonschema":
        props = json.loads(schema.data)["properties"]
        return [k for k in props if k not in ("host_t_ns", "device_t_ns", "seq")]
    from google.protobuf import descriptor_pb2

    files = descriptor_pb2.FileDescriptorSet.FromString(schema.data).file
    for f in files:
        for m in f.message_type:
            if f"{f.package}.{m.name}".lstrip(".") == schema.name:
                return [fld.name for fld in m.field]
    return []


def session_channels() -> str:
    import inspect
    import tempfile

    from mcap.reader import make_reader

    from layerskin_exp.log.session import schema as S
    from layerskin_exp.log.view import FrameTree
    from layerskin_exp.log.view.skin_summary import DISPLAY_PERIOD_NS

    cfg = _compose_dict("grip_depth")
    when = {"tf_ms": inspect.signature(FrameTree).parameters["period_ns"].default / 1e6,
            "display_ms": DISPLAY_PERIOD_NS / 1e6}
    with tempfile.TemporaryDirectory() as d:
        _written_session(Path(d) / "s.mcap")
        with open(Path(d) / "s.mcap", "rb") as fh:
            summary = make_reader(fh).get_summary()
    rows = []
    generic = {S.marker_pose_topic(0): "/markers/<id>", S.marker_detection_topic(0): "/markers/<id>/detection"}
    for channel in sorted(summary.channels.values(), key=lambda c: ("stream" not in c.metadata, c.id)):
        schema = summary.schemas[channel.schema_id]
        stream = channel.metadata.get("stream")
        topic = generic.get(channel.topic, channel.topic)
        if stream in RATES:
            sim, bench = RATES[stream]
            rate = f"sim {_rate(sim, cfg)}; bench {_rate(bench, cfg)}"
        else:
            key = stream or ("cop" if channel.topic.endswith("/cop") else channel.topic)
            rate = RATES_WHEN[key].format(**when)
        fields = ", ".join(f"`{f}`" for f in _fields(schema))
        encoding = channel.message_encoding
        if schema.encoding != encoding:
            encoding += f" ({schema.encoding})"
        rows.append([f"`{topic}`", f"`{stream}`" if stream else "(view)", encoding, f"`{schema.name}`", fields, rate])
    return table(["topic", "reader stream", "encoding", "schema", "fields", "rate"], rows)


# ---- committed report outputs ---------------------------------------------------------------------

def campaign_force(folder: str) -> str:
    data = json.loads((DOCS / folder / "results.json").read_text())
    force, study = data["force"], data.get("study", {}).get("force", {})
    training = data.get("force_training", {})
    rows = []
    for model, axes in force.items():
        r2 = [f"{axes[a]['r2']:.3f}" if isinstance(axes.get(a), dict) else "–" for a in ("Fx", "Fy", "Fz")]
        ref = study.get(model, {})
        ref_r2 = [f"{ref[a]['r2']:.3f}" if isinstance(ref.get(a), dict) and "r2" in ref[a] else "–"
                  for a in ("Fx", "Fy", "Fz")]
        t = training.get(model)
        conv = "" if not t else (f"{t.get('epochs', '?')} epochs, "
                                 + ("converged" if t.get("converged") else "not converged"))
        own = (t or {}).get("baseline_r2") or {}
        own_r2 = " / ".join(_f3(own.get(a)) for a in ("Fx", "Fy", "Fz")) if own else "–"
        rows.append([model, *r2, " / ".join(ref_r2), conv, own_r2])
    return table(["model", "R² Fx", "R² Fy", "R² Fz", "the study's R² (Fx / Fy / Fz)", "training",
                  "R² of a linear model of its own inputs (Fx / Fy / Fz)"], rows)


def _f3(v, digits: int = 3) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def _pct(v) -> str:
    return "–" if v is None else f"{100 * v:.1f} %"


def _char_rows(c: dict, h: dict, slides: dict | None) -> dict[str, str]:
    """outcome -> value, for a report's characterisation (results.json) or the study's
    (analysis/study.py: the same keys, the height bins as lowest_bin / highest_bin)."""
    u, r, s = c.get("uniformity", {}), c.get("repeatability", {}), c.get("cop_shift", {})
    bins = h.get("bins") or [h.get("lowest_bin"), h.get("highest_bin")]
    lo, hi = (bins[0] or {}), (bins[-1] or {})
    span = lambda b: f"{b.get('fz_low_n', (b.get('fz_n') or [None])[0])}–{b.get('fz_high_n', (b.get('fz_n') or [None, None])[1])} N"  # noqa: E731
    out = {
        "CV across positions at the matched load": f"{_pct(u.get('cv'))} (95 % CI {_pct(u.get('ci_low'))} – "
                                                  f"{_pct(u.get('ci_high'))}; at {u.get('matched_load_n')} N, {u.get('n_positions')} positions)",
        "median within-position CV": f"{_pct(r.get('median_cv'))} ({r.get('n_positions')} positions)",
        "inter-layer CoP shift at 1.9–2.1 N of shear, median (p10 – p90)":
            f"{_f3(s.get('median_mm'), 2)} mm ({_f3(s.get('p10_mm'), 2)} – {_f3(s.get('p90_mm'), 2)})",
        "effective height h_x / h_y, all shear frames": f"{_f3(h['overall'].get('h_x_mm'), 2)} / "
                                                        f"{_f3(h['overall'].get('h_y_mm'), 2)} mm",
        f"h_x / h_y at the lowest normal-load bin ({span(lo)})": f"{_f3(lo.get('h_x_mm'), 2)} / "
                                                              f"{_f3(lo.get('h_y_mm'), 2)} mm (R² {_f3(lo.get('r2_x'))} / {_f3(lo.get('r2_y'))})",
        f"h_x / h_y at the highest normal-load bin ({span(hi)})": f"{_f3(hi.get('h_x_mm'), 2)} / "
                                                               f"{_f3(hi.get('h_y_mm'), 2)} mm (R² {_f3(hi.get('r2_x'))} / {_f3(hi.get('r2_y'))})",
    }
    if slides is not None:
        out["normal load while the slides' shear first reaches "
            f"{slides.get('shear_at_n')} N, median"] = f"{_f3(slides.get('fz_at_shear_n'), 2)} N"
        out["largest shear per slide, median"] = f"{_f3(slides.get('median_max_shear_n'), 2)} N"
    return out


def campaign_characterisation(folder: str) -> str:
    """A report's characterisation (docs/<folder>/results.json) beside the study's, both as the
    report stored them. The study gives no slide-load figures: its column says so."""
    data = json.loads((DOCS / folder / "results.json").read_text())
    study = data.get("study", {})
    ours = _char_rows(data["characterization"], data["heights"], data["characterization"].get("slide_loads"))
    theirs = _char_rows(study.get("characterization", {}), study.get("heights", {}), None)
    rows = [[k, v, theirs.get(k, "not reported")] for k, v in ours.items()]
    # the study's bins are its own: shown with their spans in the study's column when they differ
    for k in theirs:
        if k not in ours:
            rows.append([k, "–", theirs[k]])
    return table(["outcome", "this campaign", "the study"], rows)


# ---- committed benchmark runs ---------------------------------------------------------------------

def benchmark_run(stem: str) -> str:
    """docs/benchmarks/<stem>.json (written by `python -m benchmarks.run ... --json`): where and when
    it ran, the command that refreshes it, and each benchmark's figures (benchmarks.run.markdown)."""
    from benchmarks.run import markdown

    path = DOCS / "benchmarks" / f"{stem}.json"
    record = json.loads(path.read_text())
    m = record["machine"]
    names = list(record["results"])
    head = (f"Measured {record['date']} on {m['cpu']}, {m['cores']} cores (1-minute load {m['load_1min']} before, "
            f"{m.get('load_1min_after', '?')} after: other jobs shared the machine where it exceeds the cores), "
            f"{m['os']}, Python {m['python']}, torch {m['torch']}, commit `{record.get('commit')}`. Refresh "
            f"(then `python tools/doc_tables.py`):\n\n"
            f"```bash\npython -m benchmarks.run {' '.join(names)} --json {path.relative_to(ROOT)}\n```\n\n")
    return head + markdown(record)


def benchmark_list(stem: str) -> str:
    """Every benchmark module: its name, the first line of its docstring, and whether the committed
    run docs/benchmarks/<stem>.json holds it."""
    from benchmarks.run import HERE, available

    ran = json.loads((DOCS / "benchmarks" / f"{stem}.json").read_text())["results"]
    rows = []
    for path in sorted(HERE.glob("*.py")):
        if path.stem in ("__init__", "run"):
            continue
        doc = re.match(r'\s*(?:"""|\'\'\')(.*?)(?:\n\n|"""|\'\'\')', path.read_text(), re.S)
        first = " ".join(doc.group(1).split()) if doc else ""
        how = f"`python -m benchmarks.run {path.stem}`" if path.stem in available() else f"`python -m benchmarks.{path.stem}`"
        rows.append([f"`{path.stem}`", cell(first), how, "yes" if path.stem in ran else "no"])
    return table(["benchmark", "what it measures", "run", f"in {stem}.json"], rows)


# ---- the study's published values (analysis/study.py) ---------------------------------------------

def study_values(part: str) -> str:
    from analysis import study

    if part == "force":
        rows = [[m, *(f"{v[a]['r2']:.3f}" for a in ("Fx", "Fy", "Fz")), *(f"{v[a]['mae']:.3f}" for a in ("Fx", "Fy", "Fz"))]
                for m, v in study.FORCE.items()]
        return table(["model", "R² Fx", "R² Fy", "R² Fz", "MAE Fx (N)", "MAE Fy (N)", "MAE Fz (N)"], rows)
    if part == "characterisation":
        rows = [[k, v] for k, v in _char_rows(study.CHARACTERIZATION, study.HEIGHTS, None).items()]
        r = study.FORCE_RANGE_N
        rows.append(["force range of the calibration campaign", cell(f"Fx {r['Fx']['min_n']} – {r['Fx']['max_n']} N, "
                     f"Fy {r['Fy']['min_n']} – {r['Fy']['max_n']} N, |Fz| up to {r['abs_Fz_max_n']} N")])
        return table(["outcome", "the study"], rows)
    if part == "tracking":
        rows = [[motion, layer, g, f"{v['a']:.2f}", f"{v['r2']:.3f}", f"{v['mae']:.2f}"]
                for motion, layers in study.TRACKING.items() for layer, depths in layers.items()
                for g, v in depths.items()]
        rows += [["preload (T-s5 estimate)", "", g, "", "", f"{n} N"] for g, n in study.PRELOAD_N.items()]
        return table(["motion", "layer", "grip depth (mm)", "slope a", "R²", "MAE (mm or °)"], rows)
    if part == "slip":
        rows = [[motion, cue, *(f"{v[s]:.3f}" for s in ("global", "grip", "oracle"))]
                for motion, cues in study.SLIP.items() for cue, v in cues.items()]
        lat = study.SLIP_LATENCY_MS
        rows.append(["median tactile lead over vision", "", f"{lat['before']} ms before latency compensation",
                     f"{lat['after']} ms after", ""])
        return table(["motion", "cue", "F1 global", "F1 per grip depth", "F1 oracle"], rows)
    raise SystemExit(f"doc_tables: no study values {part!r} (force, characterisation, tracking, slip)")


def lerobot_load(name: str) -> str:
    import importlib.util

    spec = importlib.util.spec_from_file_location("lerobot_load_check", ROOT / "tools" / "lerobot_load_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.markdown(json.loads((DOCS / f"{name}.json").read_text()))


_YARDSTICK_ROWS = {"deep_cop_counts_mm": "deep count-CoP travel (mm)",
                   "superficial_cop_counts_mm": "superficial count-CoP travel, own frame (mm)",
                   "interlayer_shift_counts_mm": "change of the inter-layer count shift (mm)",
                   "sheet_travel_mm": "sheet travel over the deep sheet (mm)",
                   "depth_at_load": "cap depth at equal F_z (mm)", "contact_radius": "contact radius (mm)",
                   "peak_superficial_kpa": "peak superficial pressure (kPa)",
                   "peak_deep_taxel_kpa": "peak deep taxel pressure (kPa)",
                   "tangential_stiffness": "tangential stiffness (N/mm)"}


def yardstick3d(stem: str) -> str:
    """Rows x 3D states; each cell 3D / the design / each variant, a failing value marked."""
    rec = json.loads((DOCS / "validation" / f"{stem}.json").read_text())["designs"]
    names = list(rec)
    states = list(dict.fromkeys(r["state"] for r in rec[names[0]]["rows"]))
    by = {n: {(r["state"], r["metric"]): r for r in rec[n]["rows"]} for n in names}

    def num(v):
        return "–" if v is None or v != v else f"{v:.3g}"

    rows = []
    for metric, label in _YARDSTICK_ROWS.items():
        cells = []
        for st in states:
            first = by[names[0]].get((st, metric))
            if first is None:
                cells.append("")
                continue
            vals = [num(first["3d"])] + [num(by[n][(st, metric)]["fast"]) + ("" if by[n][(st, metric)]["passed"] else " ✗")
                                          for n in names]
            cells.append(" / ".join(vals))
        rows.append([label, *cells])
    head = ", ".join(f"{n}: {rec[n]['passed']} of {rec[n]['total']} rows agree" for n in names)
    return (f"Each cell is 3D / {' / '.join(names)}; ✗ marks a row outside its band. {head}.\n\n"
            + table(["3D state", *states], rows))


def render(name: str) -> str:
    kind, _, arg = name.partition(":")
    makers = {"protocol-keys": protocol_keys, "device-options": device_options, "device-faults": device_faults,
              "sim-params": lambda _: sim_params(), "brackets": lambda _: brackets(),
              "campaign-force": campaign_force, "lerobot-load": lerobot_load, "campaign-characterisation": campaign_characterisation,
              "study": study_values, "session-channels": lambda _: session_channels(),
              "benchmark-run": benchmark_run, "benchmark-list": benchmark_list,
              "yardstick3d": yardstick3d}
    if kind not in makers:
        raise SystemExit(f"doc_tables: unknown generated section {name!r}")
    return makers[kind](arg)


def pages() -> list[Path]:
    return sorted(p for p in DOCS.rglob("*.md") if "<!-- generated: " in p.read_text())


def update(path: Path, write: bool) -> list[str]:
    """The names of the sections of `path` that differ from their source (rewritten if `write`)."""
    text = path.read_text()
    stale: list[str] = []

    def repl(m: re.Match) -> str:
        body = render(m.group("name"))
        if body != m.group("body"):
            stale.append(m.group("name"))
        return m.group(1) + body + m.group(4)

    new = SECTION.sub(repl, text)
    if write and new != text:
        path.write_text(new)
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 naming stale sections")
    args = parser.parse_args(argv)
    stale = {str(p.relative_to(ROOT)): s for p in pages() if (s := update(p, write=not args.check))}
    for page, names in stale.items():
        print(f"{page}: {'stale' if args.check else 'regenerated'}: {', '.join(names)}")
    if args.check and stale:
        print("regenerate with: python tools/doc_tables.py", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
