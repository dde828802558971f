"""The real bench (`hardware=lab`): one driver per device, on the host's monotonic clock.

Drivers acquire in their own threads; the rig wires their per-sample callbacks to its guards
(the F/T driver's every wrench, the skin driver's every frame), so a limit trips in the thread
that received the sample, not a control tick later.
"""

from __future__ import annotations

import math
import time

from hardware.interfaces import Clock, DeviceError
from hardware.rig import Rig
from layerskin_exp.config import SkinConfig

SETUPS = ("platform", "gripper")


class MonotonicClock(Clock):
    """The host's monotonic clock; sleeping is a real wait (the devices keep acquiring meanwhile)."""

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep(self, dt_s: float) -> None:
        if not (math.isfinite(dt_s) and dt_s >= 0):
            raise ValueError(f"sleep({dt_s!r}): the duration must be a finite number of seconds >= 0")
        time.sleep(dt_s)


def wire_guards(rig: Rig) -> None:
    """Route every acquired sample of the rig's drivers through its guards."""
    rig.skin.on_frames = rig.check_frames
    if rig.ft is not None:
        rig.ft.on_sample = rig.check_guards


def attach_devices(rig: Rig, hw, skin_cfg: SkinConfig, setup: str, capture_factory=None) -> Rig:
    """Build the drivers of `setup` from the device configs in `hw` (lab or loopback node).
    capture_factory: where the camera driver gets its frames (default: OpenCV capture)."""
    from hardware.skin_board import SkinBoardReader

    if setup not in SETUPS:
        raise DeviceError(f"{rig.backend}: unknown setup {setup!r}; choose one of {SETUPS}")
    rig.skin = SkinBoardReader(hw.skin_board, skin_cfg)
    if setup == "platform":
        from hardware.netft import NetFTSensor
        from hardware.platform import GrblPlatform

        rig.ft = NetFTSensor(hw.netft)
        rig.platform = GrblPlatform(hw.platform)
    else:
        from hardware.camera import OpenCVMarkerCamera
        from hardware.hande import HandEGripper
        from hardware.ur5e import UR5eArm

        rig.arm = UR5eArm(hw.ur5e)
        rig.gripper = HandEGripper(hw.hande)
        rig.camera = OpenCVMarkerCamera(hw.camera, capture_factory=capture_factory)
    wire_guards(rig)
    return rig


def build_lab_rig(hw, skin_cfg: SkinConfig, setup: str) -> Rig:
    """The bench's rig for `setup`: drivers pointed at the addresses in `hw` (LabHardwareConfig)."""
    rig = Rig(backend="lab", clock=MonotonicClock(), skin=None)
    return attach_devices(rig, hw, skin_cfg, setup)
