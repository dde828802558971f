"""Configuration of the lab marker camera (RealSense D435 colour stream, or any V4L2 camera)."""

from __future__ import annotations

from dataclasses import dataclass

from layerskin_exp.config import require, retire
from layerskin_exp.vision.camera_model import CameraModelConfig

K = "hardware.camera"
BACKENDS = ("v4l2", "realsense", "any")


@dataclass
class CameraConfig(CameraModelConfig):
    """Where the frames come from and the camera model from a calibration (image size, fx/fy/cx/cy,
    distance_mm: see CameraModelConfig); the printed markers are the rig's (`layerskin_exp.rig`).

    source: a device index ("0") or a device path / video file ("/dev/video2"). backend: "v4l2"
    (OpenCV's V4L2 capture), "realsense" (pyrealsense2's colour stream; needs the package), or
    "any" (OpenCV picks). Intrinsics fx/fy/cx/cy (px) and dist_coeffs (OpenCV's order k1, k2,
    p1, p2, k3) come from a calibration at width_px x height_px; distance_mm (the working
    distance to the marker plane) sets the tracker's expected marker size.
    latency_ms: image pipeline delay, used as the capture time's offset from the host receive
    time when the backend gives no frame timestamp (the study's fixed compensation: ~72 ms).
    stall_timeout_s: no frame for this long is a fault. A 30 fps camera delivers every 33 ms
    with USB jitter on top, so the 50 ms bound of the fast streams (skin, F/T) would trip on
    one late frame; the camera guards no force limit, so 0.2 s (six frames) is the default.
    """

    KEY = K

    source: str = "0"
    backend: str = "v4l2"
    fps: float = 30.0
    dist_coeffs: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    latency_ms: float = 75.0
    connect_timeout_s: float = 3.0
    stall_timeout_s: float = 0.2

    def __post_init__(self) -> None:
        require(isinstance(self.source, str) and self.source.strip() != "", f"{K}.source", self.source,
                "a device index such as '0' or a device path such as /dev/video2")
        require(self.backend in BACKENDS, f"{K}.backend", self.backend, f"one of {list(BACKENDS)}")
        self.check_model()
        require(0 < self.fps <= 240, f"{K}.fps", self.fps, "must be 0..240")
        require(0 <= self.cx_px <= self.width_px and 0 <= self.cy_px <= self.height_px, f"{K}.cx_px",
                (self.cx_px, self.cy_px), "the principal point must lie in the image")
        require(len(self.dist_coeffs) in (4, 5, 8, 12, 14), f"{K}.dist_coeffs", self.dist_coeffs,
                "OpenCV distortion: 4, 5, 8, 12 or 14 coefficients")
        require(0 <= self.latency_ms < 1000, f"{K}.latency_ms", self.latency_ms, "must be 0..1000 ms")
        require(self.connect_timeout_s > 0, f"{K}.connect_timeout_s", self.connect_timeout_s, "must be > 0 s")
        require(0 < self.stall_timeout_s <= 2.0, f"{K}.stall_timeout_s", self.stall_timeout_s,
                "must be > 0 and <= 2 s (a few frame periods)")


for _key in ("marker_ids", "marker_size_mm", "marker_x_mm", "marker_y_mm", "dictionary"):
    retire(f"{K}.{_key}", "the markers printed on the skin are the rig's: layerskin_exp.rig.MARKER_*")
