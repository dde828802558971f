"""Marker vision shared by the lab camera and the simulated one: ArUco tracking, corner refinement, PnP.

Imports neither `hardware` nor the simulator: it works on grey images and a camera config.
"""

from layerskin_exp.vision.corners import refine_marker_corners
from layerskin_exp.vision.pose import quat_xyzw
from layerskin_exp.vision.tracker import (
    REACQUIRE_FRAMES,
    Detection,
    MarkerTracker,
    TrackerConfig,
    camera_matrix,
    frame_region,
    marker_object_points,
)

__all__ = ["REACQUIRE_FRAMES", "Detection", "MarkerTracker", "TrackerConfig", "camera_matrix", "frame_region",
           "marker_object_points", "quat_xyzw", "refine_marker_corners"]
