"""Configuration of the lab marker camera (RealSense D435 colour stream, or any V4L2 camera)."""

from __future__ import annotations

from dataclasses import dataclass

from layerskin_exp.config import require

K = "hardware.camera"
BACKENDS = ("v4l2", "realsense", "any")


@dataclass
class CameraConfig:
    """Where the frames come from, the camera model from a calibration, and the printed markers.

    source: a device index ("0") or a device path / video file ("/dev/video2"). backend: "v4l2"
    (OpenCV's V4L2 capture), "realsense" (pyrealsense2's colour stream; needs the package), or
    "any" (OpenCV picks). Intrinsics fx/fy/cx/cy (px) and dist_coeffs (OpenCV's order k1, k2,
    p1, p2, k3) come from a calibration at width_px x height_px. distance_mm: the working
    distance to the marker plane (sets the tracker's expected marker size).
    latency_ms: image pipeline delay, used as the capture time's offset from the host receive
    time when the backend gives no frame timestamp (the study's fixed compensation: ~72 ms).
    stall_timeout_s: no frame for this long is a fault. A 30 fps camera delivers every 33 ms
    with USB jitter on top, so the 50 ms bound of the fast streams (skin, F/T) would trip on
    one late frame; the camera guards no force limit, so 0.2 s (six frames) is the default.
    """

    source: str = "0"
    backend: str = "v4l2"
    width_px: int = 1280
    height_px: int = 720
    fps: float = 30.0
    fx_px: float = 920.0
    fy_px: float = 920.0
    cx_px: float = 640.0
    cy_px: float = 360.0
    dist_coeffs: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    distance_mm: float = 120.0
    marker_ids: tuple[int, ...] = (0, 1)
    marker_size_mm: float = 5.0
    dictionary: str = "DICT_4X4_50"
    marker_x_mm: tuple[float, ...] = (-8.0, 8.0)
    marker_y_mm: tuple[float, ...] = (16.0, 16.0)
    latency_ms: float = 75.0
    connect_timeout_s: float = 3.0
    stall_timeout_s: float = 0.2

    def __post_init__(self) -> None:
        require(isinstance(self.source, str) and self.source.strip() != "", f"{K}.source", self.source,
                "a device index such as '0' or a device path such as /dev/video2")
        require(self.backend in BACKENDS, f"{K}.backend", self.backend, f"one of {list(BACKENDS)}")
        require(self.width_px >= 64 and self.height_px >= 64, f"{K}.width_px", (self.width_px, self.height_px),
                "image must be at least 64x64")
        require(0 < self.fps <= 240, f"{K}.fps", self.fps, "must be 0..240")
        require(self.fx_px > 0 and self.fy_px > 0, f"{K}.fx_px", (self.fx_px, self.fy_px), "must be > 0 (calibration)")
        require(0 <= self.cx_px <= self.width_px and 0 <= self.cy_px <= self.height_px, f"{K}.cx_px",
                (self.cx_px, self.cy_px), "the principal point must lie in the image")
        require(len(self.dist_coeffs) in (4, 5, 8, 12, 14), f"{K}.dist_coeffs", self.dist_coeffs,
                "OpenCV distortion: 4, 5, 8, 12 or 14 coefficients")
        require(self.distance_mm > 10, f"{K}.distance_mm", self.distance_mm, "must be > 10 mm")
        require(self.marker_size_mm > 0, f"{K}.marker_size_mm", self.marker_size_mm, "must be > 0")
        require(len(self.marker_ids) == len(self.marker_x_mm) == len(self.marker_y_mm) >= 1, f"{K}.marker_ids",
                self.marker_ids, "one id per marker position (marker_x_mm, marker_y_mm)")
        require(self.dictionary.startswith("DICT_"), f"{K}.dictionary", self.dictionary,
                "an OpenCV predefined ArUco dictionary name, e.g. DICT_4X4_50")
        require(0 <= self.latency_ms < 1000, f"{K}.latency_ms", self.latency_ms, "must be 0..1000 ms")
        require(self.connect_timeout_s > 0, f"{K}.connect_timeout_s", self.connect_timeout_s, "must be > 0 s")
        require(0 < self.stall_timeout_s <= 2.0, f"{K}.stall_timeout_s", self.stall_timeout_s,
                "must be > 0 and <= 2 s (a few frame periods)")
