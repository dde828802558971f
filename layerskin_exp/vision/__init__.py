"""Marker vision shared by the lab camera and the simulated one: ArUco tracking, corner refinement, PnP.

Imports neither `hardware` nor the simulator: it works on grey images and a camera config.
"""

from layerskin_exp.vision.pose import quat_xyzw

__all__ = ["REACQUIRE_FRAMES", "Detection", "MarkerTracker", "TrackerConfig", "camera_matrix", "frame_region",
           "marker_object_points", "quat_xyzw", "refine_marker_corners"]


def __getattr__(name: str):
    """The tracker and the corner kernels (OpenCV, numba) load at first use: Hydra's schemas import
    `camera_model`, which runs this file first, and `--help` must not wait for them."""
    if name == "refine_marker_corners":
        from layerskin_exp.vision import corners

        return getattr(corners, name)
    if name in __all__:
        from layerskin_exp.vision import tracker

        return getattr(tracker, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
