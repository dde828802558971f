"""The marker camera's pinhole model, shared by the lab camera's config and the simulated one's.

The defaults are the rig's D435 colour stream (`layerskin_exp.rig`); a lab calibration replaces
them in `hardware.camera`. The markers the camera looks for are not a setting: they are printed
on the skin, and both configs read them from the rig (`MarkerLayout`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from layerskin_exp import rig
from layerskin_exp.config import require


@dataclass
class CameraModelConfig(rig.MarkerLayout):
    """Image size and intrinsics (px) and the working distance to the marker plane (mm).

    Subclasses set KEY, the config path their checks name (`hardware.camera`, `sim.rig.camera`).
    """

    KEY: ClassVar[str] = "camera"

    width_px: int = rig.CAMERA_WIDTH_PX
    height_px: int = rig.CAMERA_HEIGHT_PX
    fx_px: float = rig.CAMERA_FX_PX
    fy_px: float = rig.CAMERA_FY_PX
    cx_px: float = rig.CAMERA_CX_PX
    cy_px: float = rig.CAMERA_CY_PX
    distance_mm: float = rig.CAMERA_DISTANCE_MM

    def check_model(self) -> None:
        k = self.KEY
        require(self.width_px >= 64 and self.height_px >= 64, f"{k}.width_px", (self.width_px, self.height_px),
                "image must be at least 64x64")
        require(self.fx_px > 0 and self.fy_px > 0, f"{k}.fx_px", (self.fx_px, self.fy_px), "must be > 0")
        require(self.distance_mm > 10, f"{k}.distance_mm", self.distance_mm, "must be > 10 mm")
