"""Session folders out to other formats.

    from layerskin_exp.log.export import export_lerobot, check_lerobot
    report = export_lerobot("data/force_calibration/1844c3702b", "out/calib_lerobot")
    problems = check_lerobot("out/calib_lerobot")   # [] for a well-formed dataset

`python -m layerskin_exp.log export lerobot SESSIONS OUT [--fps N]` is the same from the shell.
The LeRobot v3.0 layout is written with pyarrow (and OpenCV for the camera's video), without the
`lerobot` package: see layerskin_exp.log.export.lerobot and docs/export.md.
"""

from layerskin_exp.log.export.lerobot import ExportError, ExportReport, LeftOut, export_lerobot
from layerskin_exp.log.export.lerobot_check import check_lerobot

__all__ = ["ExportError", "ExportReport", "LeftOut", "check_lerobot", "export_lerobot"]
