"""The session's frame tree, as Foxglove's 3D panel relates frames through foxglove.FrameTransform.

    base ─┬─ tool ── skin         arm rig: base = UR5e base, tool = TCP, skin = the skin on the jaw
          ├─ camera ── marker_<id>
    base ─┬─ tool                 platform rig: base = skin frame on the table, tool = indenter tip
          └─ skin (identity)

Transforms that a stream already measures are written by the SessionWriter with the stream
(TCP pose -> base->tool, stage position -> base->tool, marker pose -> camera->marker_<id>).
The geometry no stream measures (the skin on the jaw, which moves with the jaw opening; the
camera's extrinsics; the skin on the platform table) is written by FrameTree, again every
`period_ns` of host time so that Foxglove finds it after a seek, not only at the start.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from layerskin_exp.rig import R_TCP_SKIN  # how the skin is mounted on the jaw
from layerskin_exp.types import FrameTransform

BASE, TOOL, SKIN, CAMERA = "base", "tool", "skin", "camera"
IDENTITY = (0.0, 0.0, 0.0, 1.0)


def marker_frame(marker_id: int) -> str:
    return f"marker_{int(marker_id)}"


def skin_in_tool(opening_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """(translation (3,) m, quaternion xyzw (4,)) of the skin frame in the tool (TCP) frame on the
    gripper rig: on the jaw, half the opening from the TCP along -y_tool, axes as mounted."""
    t = np.array([0.0, -0.5e-3 * float(opening_mm), 0.0])
    return t, Rotation.from_matrix(R_TCP_SKIN).as_quat()


def camera_in_base(calibration: dict | None) -> tuple[np.ndarray, np.ndarray] | None:
    """The camera's pose in base from its calibration (R_base_camera, t_base_camera_m), or None
    when the calibration does not give the extrinsics."""
    if not calibration or "R_base_camera" not in calibration or "t_base_camera_m" not in calibration:
        return None
    R = np.asarray(calibration["R_base_camera"], float)
    return np.asarray(calibration["t_base_camera_m"], float), Rotation.from_matrix(R).as_quat()


class FrameTree:
    """Writes the fixed and jaw-dependent transforms of one trial (see the module docstring).

    setup: "gripper" or "platform"; camera_calibration: the camera's calibration dict, if any.
    update(host_t_ns, opening_mm) writes them when period_ns has passed or the opening changed.
    """

    def __init__(self, writer, setup: str, camera_calibration: dict | None = None,
                 period_ns: int = 100_000_000) -> None:
        self.writer, self.setup, self.period_ns = writer, setup, int(period_ns)
        self.camera = camera_in_base(camera_calibration)
        self._last_ns: int | None = None
        self._opening_mm: float | None = None

    def update(self, host_t_ns: int, opening_mm: float | None = None) -> None:
        moved = opening_mm is not None and opening_mm != self._opening_mm
        if opening_mm is not None:
            self._opening_mm = float(opening_mm)
        if not moved and self._last_ns is not None and host_t_ns - self._last_ns < self.period_ns:
            return
        self._last_ns = int(host_t_ns)
        for tf in self.transforms(int(host_t_ns)):
            self.writer.write(tf)

    def transforms(self, host_t_ns: int) -> list[FrameTransform]:
        out = []
        if self.setup == "platform":
            out.append(FrameTransform(BASE, SKIN, np.zeros(3), np.array(IDENTITY), host_t_ns))
        elif self._opening_mm is not None:
            out.append(FrameTransform(TOOL, SKIN, *skin_in_tool(self._opening_mm), host_t_ns))
        if self.camera is not None:
            out.append(FrameTransform(BASE, CAMERA, *self.camera, host_t_ns))
        return out
