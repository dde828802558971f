"""The Foxglove layout of a session: one per rig, built from the topics the file actually has.

Panels are described once with the Foxglove SDK's layout types and written in two forms:
- the app's import format (Layouts > Import from file): {"configById": {"<Type>!<id>": config},
  "layout": a binary split tree {"first", "second", "direction", "splitPercentage"} of panel ids,
  "globalVariables", "userNodes", "playbackConfig"}; `app_layout` converts to it;
- the SDK's {version, content} tree, as the SDK's MCAPWriter.write_layout stores it.
The session writer stores both when it closes a file (it then knows every topic it wrote);
`python -m layerskin_exp.log layout gripper > grip.json` prints the app form for a live view.

    ┌ superficial ┬ deep ┬ camera + markers ┬ 3D: base, tool, skin, camera, markers ┐
    ├ force N (F/T, estimate) ┬ stage mm │ jaw mm ┬ TCP m ───────────────────────────┤
    └ skin totals (counts) ┬ CoP mm ┬ slip score ┬ protocol events ───────────────────┘

Plots are grouped by unit (a 5 mm TCP motion is not drawn on the axis of a 50 mm jaw, nor a
CoP of ±12 mm beside totals of 100,000 counts); a panel appears only when its topic does.
The skin images are flipped vertically: image row i holds taxels at y_i, and y grows with i,
so Foxglove's row-0-at-top display would show +y downwards; flipped, +x runs right and +y up,
as the maps and CoP positions are drawn in the simulator preview and the characterisation
figure. The CoP annotations are in image pixels and flip with their image.
"""

from __future__ import annotations

import json
from collections.abc import Iterable

import foxglove.layouts as fl

from layerskin_exp.log.session import schema as S
from layerskin_exp.log.view.frame_tree import BASE
from layerskin_exp.rig import MARKER_IDS
from layerskin_exp.types import ADC_MAX

SETUPS = ("platform", "gripper")
SUMMARY_TOPIC = S.SKIN_SUMMARY_TOPIC
# SDK panel type -> the app's panel type (the prefix of a panel id in configById)
APP_PANEL_TYPES = {"Image": "Image", "Plot": "Plot", "ThreeDee": "3D", "Log": "RosOut"}


def rig_topics(setup: str, *, estimate: bool = False, camera: bool = False) -> set[str]:
    """The topics a session of this rig carries (what a live view of it serves).

    setup: "platform" (force calibration: stage, F/T) or "gripper" (arm, gripper, and the
    printed markers' poses the camera tracks); estimate: the live estimator's /estimate/* topics;
    camera: saved camera images."""
    if setup not in SETUPS:
        raise ValueError(f"setup={setup!r}: use one of {', '.join(SETUPS)}")
    topics = {*S.SKIN_TOPICS.values(), *(S.cop_topic(layer) for layer in S.SKIN_TOPICS), SUMMARY_TOPIC,
              S.TF_TOPIC, S.LOG_TOPIC, S.EVENTS_TOPIC}
    if setup == "platform":
        topics |= {S.WRENCH_TOPIC, S.STAGE_TOPIC}
    else:
        topics |= {S.TCP_TOPIC, S.GRIPPER_TOPIC, *(S.marker_pose_topic(m) for m in MARKER_IDS)}
        if camera:
            topics |= {S.CAMERA_TOPIC, S.CAMERA_MARKERS_TOPIC}
    if estimate:
        topics |= {S.ESTIMATE_FORCE_TOPIC, S.ESTIMATE_SLIP_TOPIC}
    return topics


def _skin_image(layer: str, topics: set[str]) -> fl.ImagePanel:
    cop = S.cop_topic(layer)
    return fl.ImagePanel(
        title=f"{layer} layer (0-{ADC_MAX} counts; +x right, +y up)",
        config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(
                image_topic=S.SKIN_TOPICS[layer],
                # Foxglove's default 16-bit range is 0..10000: the 12-bit counts would look grey.
                min_value=0,
                max_value=ADC_MAX,
                color_mode="colormap",
                color_map="turbo",
                flip_vertical=True,  # +y up (see the module docstring)
                annotations={cop: fl.ImageAnnotationSettings(visible=True)} if cop in topics else None,
            )
        ),
    )


def _plot(title: str, series: list[tuple[str, str]]) -> fl.PlotPanel:
    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=v, label=lab, enabled=True, timestamp_method="receiveTime")
                   for v, lab in series],
            show_legend=True,
        ),
    )


def _row(panels: list) -> fl.SplitContainer | None:
    panels = [p for p in panels if p is not None]
    if not panels:
        return None
    return fl.SplitContainer(direction="row", items=[fl.SplitItem(content=p) for p in panels])


def session_layout(topics: Iterable[str]) -> fl.Layout:
    """The layout for a session with these topics: every panel shows a topic in `topics`."""
    topics = set(topics)
    has = topics.__contains__
    images = [_skin_image(layer, topics) for layer, t in S.SKIN_TOPICS.items() if has(t)]
    if has(S.CAMERA_TOPIC):
        markers = {S.CAMERA_MARKERS_TOPIC: fl.ImageAnnotationSettings(visible=True)} if has(
            S.CAMERA_MARKERS_TOPIC) else None
        images.append(fl.ImagePanel(title="camera + markers", config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(image_topic=S.CAMERA_TOPIC, annotations=markers))))
    if has(S.TF_TOPIC):
        poses = sorted(t for t in topics if t == S.TCP_TOPIC or (t.startswith("/markers/")
                                                                 and not t.endswith("/detection")))
        images.append(fl.ThreeDeePanel(title="rig frames", config=fl.ThreeDeeConfig(
            follow_tf=BASE, topics={t: fl.BaseRendererPoseTopicSettings(visible=True) for t in poses} or None)))

    force = [(f"{S.WRENCH_TOPIC}.force_n[{i}]", f"F{a} (F/T)") for i, a in enumerate("xyz") if has(S.WRENCH_TOPIC)]
    force += [(f"{S.ESTIMATE_FORCE_TOPIC}.force_n[{i}]", f"F{a} (estimate)") for i, a in enumerate("xyz")
              if has(S.ESTIMATE_FORCE_TOPIC)]
    motion = [
        _plot("force (N)", force) if force else None,
        _plot("stage (mm)", [(f"{S.STAGE_TOPIC}.position_mm[{i}]", f"stage {a}") for i, a in enumerate("xyz")])
        if has(S.STAGE_TOPIC) else None,
        _plot("jaw (mm)", [(f"{S.GRIPPER_TOPIC}.position_mm", "jaw"), (f"{S.GRIPPER_TOPIC}.requested_mm",
                                                                       "requested")])
        if has(S.GRIPPER_TOPIC) else None,
        _plot("TCP (m)", [(f"{S.TCP_TOPIC}.pose.position.{a}", f"TCP {a}") for a in "xyz"])
        if has(S.TCP_TOPIC) else None,
    ]
    skin = [
        _plot("skin totals above baseline (counts)",
              [(f"{SUMMARY_TOPIC}.{layer}.total_counts", layer) for layer in S.SKIN_TOPICS])
        if has(SUMMARY_TOPIC) else None,
        _plot("centre of pressure (mm, on contact)",
              [(f"{SUMMARY_TOPIC}.{layer}.cop_mm[{i}]", f"{layer} {a}") for layer in S.SKIN_TOPICS
               for i, a in enumerate("xy")])
        if has(SUMMARY_TOPIC) else None,
        _plot("slip score (estimate)", [(f"{S.ESTIMATE_SLIP_TOPIC}.score", "score")])
        if has(S.ESTIMATE_SLIP_TOPIC) else None,
        fl.LogPanel(title="protocol events", config=fl.LogConfig(topic_to_render=S.LOG_TOPIC))
        if has(S.LOG_TOPIC) else None,
    ]
    rows = [(3, _row(images)), (2, _row(motion)), (2, _row(skin))]
    items = [fl.SplitItem(proportion=p, content=r) for p, r in rows if r is not None]
    if not items:
        raise ValueError(f"no panel to show for topics {sorted(topics)}")
    return fl.Layout(content=fl.SplitContainer(direction="column", items=items))


def _plain(obj):
    """An SDK layout object as plain JSON data (what to_json writes)."""
    return json.loads(json.dumps(obj, default=fl._BaseModel._to_json_default))


def app_layout(layout: fl.Layout) -> dict:
    """The SDK layout in the Foxglove app's import format (see the module docstring)."""
    config_by_id: dict[str, dict] = {}

    def node(content: dict):
        if content["type"] == "panel":
            kind = APP_PANEL_TYPES.get(content["panelType"])
            if kind is None:
                raise ValueError(f"panel type {content['panelType']!r} has no app equivalent here")
            pid = f"{kind}!{len(config_by_id) + 1:x}"
            config = dict(content.get("config") or {})
            if content.get("title"):  # Foxglove reads the first key, Lichtblick the second
                config["foxglovePanelTitle"] = config["lichtblickPanelTitle"] = content["title"]
            config_by_id[pid] = config
            return pid
        return split(content["direction"], content["items"])

    def split(direction: str, items: list):
        if len(items) == 1:
            return node(items[0]["content"])
        weights = [float(i.get("proportion", 1)) for i in items]
        first = node(items[0]["content"])
        return {"first": first, "second": split(direction, items[1:]), "direction": direction,
                "splitPercentage": 100.0 * weights[0] / sum(weights)}

    tree = _plain(layout)
    root = node(tree["content"])
    return {"configById": config_by_id, "layout": root, "globalVariables": tree.get("variables") or {},
            "userNodes": tree.get("userScripts") or {}, "playbackConfig": {"speed": 1.0}}


def rig_layout(setup: str, *, estimate: bool = False, camera: bool = False) -> dict:
    """The app-format layout for a live view of one rig (see rig_topics)."""
    return app_layout(session_layout(rig_topics(setup, estimate=estimate, camera=camera)))
