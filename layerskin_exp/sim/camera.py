"""The marker camera: render the ArUco markers on the superficial layer, then detect them as the lab does.

Rendering is exact projective geometry: each marker (with a white quiet zone) is a plane, so
its image is the homography of the printed marker, drawn with cv2.warpPerspective onto a
supersampled canvas and averaged down (INTER_AREA), then blurred and given sensor noise. Only a
region around the markers is rendered (the rest of a real frame is background the detector
would reject); detection is the real pipeline: cv2.aruco.ArucoDetector with subpixel corner
refinement and cv2.solvePnP(SOLVEPNP_IPPE_SQUARE) on a pinhole model without distortion.

Frames: camera x right, y down, z forward (OpenCV). Marker frame as ArUco defines it: x right,
y up on the printed marker, z out of it; lengths in mm inside, m in the detections.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from layerskin_exp.sim.rig_config import CameraConfig

QUIET_ZONE = 0.25  # white margin around each marker, fraction of the marker side
ROI_MARGIN_PX = 20  # background around the markers; the detector needs it to find their outlines


@dataclass
class Detection:
    """One marker found in one image: pose in the camera frame (mm, rotation vector) and corners (4, 2) px."""

    marker_id: int
    rvec: np.ndarray
    tvec_mm: np.ndarray
    corners_px: np.ndarray


def marker_object_points(size_mm: float) -> np.ndarray:
    """(4, 3) marker corners in the marker frame, in ArUco's order (TL, TR, BR, BL)."""
    h = size_mm / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


class MarkerImager:
    """Renders marker planes seen by a pinhole camera and detects them."""

    def __init__(self, cfg: CameraConfig) -> None:
        self.cfg = cfg
        self.K = np.array([[cfg.fx_px, 0.0, cfg.cx_px], [0.0, cfg.fy_px, cfg.cy_px], [0.0, 0.0, 1.0]])
        self.dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, cfg.dictionary))
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.cornerRefinementWinSize = 4
        params.relativeCornerRefinmentWinSize = 1.0  # the default 0.3 module shrinks the window to ~1 px
        params.cornerRefinementMinAccuracy = 0.01
        params.cornerRefinementMaxIterations = 50
        self.detector = cv2.aruco.ArucoDetector(self.dictionary, params)
        # Printed stickers: the marker with a white quiet zone, at ~24 px per marker bit.
        side = 24 * (self.dictionary.markerSize + 2)
        margin = int(round(side * QUIET_ZONE))
        self.stickers = {}
        for mid in cfg.marker_ids:
            img = np.full((side + 2 * margin, side + 2 * margin), 255, np.uint8)
            img[margin:margin + side, margin:margin + side] = cv2.aruco.generateImageMarker(self.dictionary, mid, side)
            self.stickers[mid] = img
        self.obj_pts = marker_object_points(cfg.marker_size_mm)
        s = cfg.marker_size_mm * (1.0 + 2.0 * QUIET_ZONE) / 2.0
        self.sticker_pts = np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])
        self.background_gray = 90  # silicone seen by the camera
        self._noise_bank: np.ndarray | None = None

    def project(self, pts_cam_mm: np.ndarray) -> np.ndarray:
        """(N, 3) camera-frame points (mm) -> (N, 2) pixel coordinates (pixel centres are integers)."""
        p = pts_cam_mm @ self.K.T
        return p[:, :2] / p[:, 2:3]

    def render(self, poses: dict[int, tuple[np.ndarray, np.ndarray]], rng: np.random.Generator | None
               ) -> tuple[np.ndarray, tuple[int, int]]:
        """Image of the region holding the markers.

        poses: marker id -> (R (3, 3), t (3,) mm), marker frame in the camera frame.
        Returns the grey image (h, w) uint8 and its top-left pixel (x0, y0) in the full frame.
        """
        cfg, ss = self.cfg, self.cfg.supersample
        quads = {mid: self.project(self.sticker_pts @ R.T + t) for mid, (R, t) in poses.items()}
        allq = np.concatenate(list(quads.values()))
        x0 = int(np.clip(np.floor(allq[:, 0].min()) - ROI_MARGIN_PX, 0, cfg.width_px - 1))
        y0 = int(np.clip(np.floor(allq[:, 1].min()) - ROI_MARGIN_PX, 0, cfg.height_px - 1))
        x1 = int(np.clip(np.ceil(allq[:, 0].max()) + ROI_MARGIN_PX + 1, x0 + 1, cfg.width_px))
        y1 = int(np.clip(np.ceil(allq[:, 1].max()) + ROI_MARGIN_PX + 1, y0 + 1, cfg.height_px))
        w, h = x1 - x0, y1 - y0
        canvas = np.full((h * ss, w * ss), self.background_gray, np.uint8)
        for mid, q in quads.items():
            sticker = self.stickers[mid]
            n = sticker.shape[0]
            src = np.array([[-0.5, -0.5], [n - 0.5, -0.5], [n - 0.5, n - 0.5], [-0.5, n - 0.5]], np.float32)
            dst = ((q - [x0, y0] + 0.5) * ss - 0.5).astype(np.float32)
            H = cv2.getPerspectiveTransform(src, dst)
            cv2.warpPerspective(sticker, H, (w * ss, h * ss), dst=canvas, flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_TRANSPARENT)
        img = cv2.resize(canvas, (w, h), interpolation=cv2.INTER_AREA) if ss > 1 else canvas
        if cfg.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma_px)
        if rng is not None and cfg.noise_std_gray > 0:
            # Sensor noise: a random window of a pre-drawn Gaussian bank (one draw per frame is the
            # costliest step of rendering otherwise).
            if self._noise_bank is None:
                self._noise_bank = rng.normal(0.0, cfg.noise_std_gray, 1 << 20).astype(np.float32)
            k = int(rng.integers(0, self._noise_bank.size - img.size))
            noise = self._noise_bank[k:k + img.size].reshape(img.shape)
            img = np.clip(img + noise, 0, 255).astype(np.uint8)
        return img, (x0, y0)

    def detect(self, img: np.ndarray, origin_px: tuple[int, int]) -> list[Detection]:
        """ArUco detection + IPPE_SQUARE PnP on an image whose top-left pixel is origin_px."""
        corners, ids, _ = self.detector.detectMarkers(img)
        out = []
        if ids is None:
            return out
        for c, mid in zip(corners, ids.ravel(), strict=True):
            if int(mid) not in self.stickers:
                continue
            pts = c.reshape(4, 2).astype(np.float64) + np.asarray(origin_px, float)
            ok, rvec, tvec = cv2.solvePnP(self.obj_pts, pts, self.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
            if ok:
                out.append(Detection(int(mid), rvec.ravel(), tvec.ravel(), pts))
        return out

    def full_frame(self, roi: np.ndarray, origin_px: tuple[int, int]) -> np.ndarray:
        """(H, W) uint8: the rendered region pasted into a background frame of the camera's size."""
        frame = np.full((self.cfg.height_px, self.cfg.width_px), self.background_gray, np.uint8)
        x0, y0 = origin_px
        frame[y0:y0 + roi.shape[0], x0:x0 + roi.shape[1]] = roi
        return frame
