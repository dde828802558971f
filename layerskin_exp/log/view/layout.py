"""The Foxglove layout every session file carries (and the live view offers): built with the
Foxglove SDK's layout types, stored as the SDK stores layouts in an MCAP file (metadata record
"foxglove.layout"). `python -m layerskin_exp.log layout > skin.json` exports it for
Foxglove's Layouts > Import.

    ┌ superficial layer ┬ deep layer ┬ 3D: base, tool, skin, camera, markers ┐
    ├ force / TCP / jaw plots ┬ skin totals and CoP plots ┬ camera + markers ┬ Log ┤
"""

from __future__ import annotations

import foxglove.layouts as fl

from layerskin_exp.log.session import schema as S
from layerskin_exp.log.view.frame_tree import BASE
from layerskin_exp.types import ADC_MAX

SUMMARY_TOPIC = S.SKIN_SUMMARY_TOPIC


def _layer(layer: str) -> fl.ImagePanel:
    return fl.ImagePanel(
        title=f"{layer} layer (0-{ADC_MAX} counts)",
        config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(
                image_topic=S.SKIN_TOPICS[layer],
                # Foxglove's default 16-bit range is 0..10000: the 12-bit counts would look grey.
                min_value=0,
                max_value=ADC_MAX,
                color_mode="colormap",
                color_map="turbo",
                annotations={S.cop_topic(layer): fl.ImageAnnotationSettings(visible=True)},
            )
        ),
    )


def _plot(title: str, series: list[tuple[str, str]]) -> fl.PlotPanel:
    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=v, label=lab, timestamp_method="receiveTime") for v, lab in series],
            show_legend=True,
        ),
    )


def session_layout() -> fl.Layout:
    """Both layers on a fixed 0..4095 colour scale with their CoP, the 3D frame tree, plots of
    force, arm and jaw against host time, skin totals and CoP, the camera with marker outlines,
    and the protocol events."""
    three_d = fl.ThreeDeePanel(
        title="rig frames",
        config=fl.ThreeDeeConfig(follow_tf=BASE, topics={S.TCP_TOPIC: fl.BaseRendererPoseTopicSettings(visible=True)}),
    )
    top = fl.SplitContainer(
        direction="row",
        items=[
            fl.SplitItem(content=_layer("superficial")),
            fl.SplitItem(content=_layer("deep")),
            fl.SplitItem(content=three_d),
        ],
    )
    motion = _plot(
        "force (N), TCP (m), jaw (mm)",
        [(f"{S.WRENCH_TOPIC}.force_n[{i}]", f"F{a} N") for i, a in enumerate("xyz")]
        + [(f"{S.TCP_TOPIC}.pose.position.{a}", f"TCP {a} m") for a in "xyz"]
        + [(f"{S.GRIPPER_TOPIC}.position_mm", "jaw mm"), (f"{S.STAGE_TOPIC}.position_mm[2]", "stage z mm")],
    )
    skin = _plot(
        "skin totals (counts) and CoP (mm)",
        [(f"{SUMMARY_TOPIC}.{layer}.total_counts", f"{layer} total") for layer in S.SKIN_TOPICS]
        + [(f"{SUMMARY_TOPIC}.{layer}.cop_mm[{i}]", f"{layer} CoP {a}") for layer in S.SKIN_TOPICS
           for i, a in enumerate("xy")],
    )
    camera = fl.ImagePanel(
        title="camera + markers",
        config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(
                image_topic=S.CAMERA_TOPIC,
                annotations={S.CAMERA_MARKERS_TOPIC: fl.ImageAnnotationSettings(visible=True)},
            )
        ),
    )
    events = fl.LogPanel(title="protocol events", config=fl.LogConfig(topic_to_render=S.LOG_TOPIC))
    bottom = fl.SplitContainer(
        direction="row",
        items=[
            fl.SplitItem(content=motion),
            fl.SplitItem(content=skin),
            fl.SplitItem(content=camera),
            fl.SplitItem(content=events),
        ],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="column", items=[fl.SplitItem(proportion=3, content=top), fl.SplitItem(proportion=2, content=bottom)]
        )
    )
