"""The simulated marker camera's images: render the ArUco markers on the superficial layer.

Rendering is exact projective geometry: each marker (with a white quiet zone) is a plane, so
its image is the homography of the printed marker, drawn with cv2.warpPerspective onto a
supersampled canvas and averaged down (INTER_AREA), then blurred and given sensor noise. Only a
region around the markers is rendered; the rest of the frame is uniform background, so a frame
is held sparsely (SensorFrame: the rendered patch and where it sits) and composed in full only
when an image is kept. While the markers hold still (poses equal to within rounding, e.g. a hold
or a stuck contact) the blurred patch is reused and only the sensor noise is drawn again: a
window at a random offset of one fixed bank of floored Gaussian read noise per process.

Detection is the lab's: `layerskin_exp.vision` (MarkerTracker: tracked ArUco search, corners
refined from the marker outlines, joint layer PnP). It reads nothing from the renderer.
Pinhole model without distortion.

Frames: camera x right, y down, z forward (OpenCV). Marker frame as ArUco defines it: x right,
y up on the printed marker, z out of it; lengths in mm inside, m in the detections.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from layerskin_exp.sim.rig_config import CameraConfig
from layerskin_exp.vision import Detection, MarkerTracker

QUIET_ZONE = 0.25  # white margin around each marker, fraction of the marker side
ROI_MARGIN_PX = 20  # background rendered (blurred, noisy) around the stickers
# Poses (rotation entries, translations in m) that differ by no more than this render as one:
# 1e-9 m moves a corner ~1e-5 px at the working distance, far below the render's own accuracy.
# A contact that holds the layer still while the arm moves gives poses equal only to rounding.
STILL_POSE_TOL = 1e-9


NOISE_BANK_SEED = 0x5EED_CA3  # the sensor's read-noise bank is a fixed draw; each frame takes a random window of it
NOISE_BANK_MIN = 1 << 20  # values in a bank (at least twice the frame's pixel count)
_noise_banks: dict[tuple[float, int], tuple[np.ndarray, np.ndarray]] = {}


def sensor_noise_bank(std_gray: float, min_size: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian read noise N(0, std_gray), floored to whole grey levels and split by sign: (up, down),
    each (n,) uint8 with floor(noise) = up - down (one of them 0 at every index).

    One fixed draw (NOISE_BANK_SEED) per process and noise level, shared by every camera: drawing
    a million values costs ~15 ms, as much as ~30 frames of rendering. A frame's noise is a window
    at a random offset, drawn from the trial's generator, so frames and trials stay distinct
    realisations and a seed still fixes them all.
    """
    n = max(NOISE_BANK_MIN, int(min_size))
    key = (float(std_gray), n)
    if key not in _noise_banks:
        noise = np.floor(np.random.default_rng(NOISE_BANK_SEED).normal(0.0, std_gray, n))
        _noise_banks[key] = (np.clip(noise, 0, 255).astype(np.uint8), np.clip(-noise, 0, 255).astype(np.uint8))
    return _noise_banks[key]


@dataclass
class SensorFrame:
    """A grey frame held sparsely: `patch` (h, w) uint8 with its top-left pixel at origin_px (x0, y0)
    in a frame of shape (H, W) that is background_gray everywhere else."""

    patch: np.ndarray
    origin_px: tuple[int, int]
    shape: tuple[int, int]
    background_gray: int

    def crop(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """Pixels [y0:y1, x0:x1] of the frame (clipped to it), (h, w) uint8; a view when they lie in the patch."""
        H, W = self.shape
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, W), min(y1, H)
        px, py = self.origin_px
        ph, pw = self.patch.shape
        if px <= x0 and py <= y0 and x1 <= px + pw and y1 <= py + ph:
            return self.patch[y0 - py:y1 - py, x0 - px:x1 - px]
        out = np.full((max(y1 - y0, 0), max(x1 - x0, 0)), self.background_gray, np.uint8)
        ix0, iy0, ix1, iy1 = max(x0, px), max(y0, py), min(x1, px + pw), min(y1, py + ph)
        if ix0 < ix1 and iy0 < iy1:
            out[iy0 - y0:iy1 - y0, ix0 - x0:ix1 - x0] = self.patch[iy0 - py:iy1 - py, ix0 - px:ix1 - px]
        return out

    def full(self) -> np.ndarray:
        """The whole frame (H, W) uint8."""
        return self.crop(0, 0, self.shape[1], self.shape[0])



class MarkerImager:
    """Renders marker planes seen by a pinhole camera (SensorFrames) and detects them (a MarkerTracker).

    reuse_still=False renders every frame afresh, track=False searches every frame in full
    (both for comparison: the results are the same).
    """

    def __init__(self, cfg: CameraConfig, track: bool = True, reuse_still: bool = True) -> None:
        self.cfg, self.reuse_still = cfg, reuse_still
        self.tracker = MarkerTracker(cfg, track)
        self.K = self.tracker.K
        self.dictionary = self.tracker.dictionary
        self.obj_pts = self.tracker.obj_pts
        self.layer_offsets_mm = self.tracker.layer_offsets_mm
        # Printed stickers: the marker with a white quiet zone. One sticker pixel spans about one
        # supersampled canvas pixel at the working distance, so the warp's bilinear ramp across an
        # edge is the canvas pixel's area coverage (a finer sticker would be point-sampled: edges
        # then snap to the canvas grid, ~0.1 px at 2x supersampling).
        modules = self.dictionary.markerSize + 2
        module_px = cfg.fx_px * cfg.marker_size_mm / cfg.distance_mm / modules * cfg.supersample
        bit_px = max(2, int(round(module_px)))
        side = bit_px * modules
        margin = int(round(side * QUIET_ZONE))
        self.stickers = {}
        for mid in cfg.marker_ids:
            img = np.full((side + 2 * margin, side + 2 * margin), 255, np.uint8)
            img[margin:margin + side, margin:margin + side] = cv2.aruco.generateImageMarker(self.dictionary, mid, side)
            self.stickers[int(mid)] = img
        n = side + 2 * margin
        self._sticker_src = np.array([[-0.5, -0.5], [n - 0.5, -0.5], [n - 0.5, n - 0.5], [-0.5, n - 0.5]], np.float32)
        s = cfg.marker_size_mm * (side + 2 * margin) / side / 2.0  # sticker half-side, mm (margin is whole pixels)
        self.sticker_pts = np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])
        self.background_gray = 90  # silicone seen by the camera
        self._noise: tuple[np.ndarray, np.ndarray] | None = None  # sensor_noise_bank, on the first noisy frame
        self._clean: tuple[tuple, np.ndarray, np.ndarray, tuple[int, int]] | None = None  # last noise-free render

    def project(self, pts_cam_mm: np.ndarray) -> np.ndarray:
        """(N, 3) camera-frame points (mm) -> (N, 2) pixel coordinates (pixel centres are integers)."""
        p = pts_cam_mm @ self.K.T
        return p[:, :2] / p[:, 2:3]

    def render(self, poses: dict[int, tuple[np.ndarray, np.ndarray]], rng: np.random.Generator | None
               ) -> SensorFrame:
        """One camera frame of the markers.

        poses: marker id -> (R (3, 3), t (3,) mm), marker frame in the camera frame. rng: sensor
        noise (None: noise-free). The frame is the rendered region (stickers plus ROI_MARGIN_PX,
        blurred and noisy) in uniform background.
        """
        cfg = self.cfg
        ids = tuple(poses)
        key = np.concatenate([a for R, t in poses.values() for a in (R.ravel(), t * 1e-3)])  # t in m
        if (self.reuse_still and self._clean is not None and self._clean[0] == ids
                and np.abs(self._clean[1] - key).max() <= STILL_POSE_TOL):
            clean, origin = self._clean[2], self._clean[3]
        else:
            clean, origin = self._render_clean(poses)
            self._clean = (ids, key, clean, origin)
        if rng is not None and cfg.noise_std_gray > 0:
            # Sensor noise: a random window of a pre-drawn bank, added with saturation. The bank
            # holds floor(noise), so clean + floor(noise) clipped to 0..255 is the quantised
            # floor(clip(clean + noise)) of an integer-valued clean image.
            if self._noise is None:
                self._noise = sensor_noise_bank(cfg.noise_std_gray, 2 * cfg.width_px * cfg.height_px)
            up, down = self._noise
            k = int(rng.integers(0, up.size - clean.size))
            img = cv2.subtract(cv2.add(clean, up[k:k + clean.size].reshape(clean.shape)),
                               down[k:k + clean.size].reshape(clean.shape))
        else:
            img = clean.copy()
        return SensorFrame(img, origin, (cfg.height_px, cfg.width_px), self.background_gray)

    def _render_clean(self, poses: dict[int, tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, tuple[int, int]]:
        """Blurred, noise-free image (h, w) uint8 of the region holding the stickers, and its top-left pixel."""
        cfg, ss = self.cfg, self.cfg.supersample
        mids = [int(m) for m in poses]
        quads = self.project(np.concatenate([self.sticker_pts @ R.T + t for R, t in poses.values()])).reshape(-1, 4, 2)
        qlo, qhi = quads.min(axis=1), quads.max(axis=1)  # (M, 2) each
        x0 = int(np.clip(np.floor(qlo[:, 0].min()) - ROI_MARGIN_PX, 0, cfg.width_px - 1))
        y0 = int(np.clip(np.floor(qlo[:, 1].min()) - ROI_MARGIN_PX, 0, cfg.height_px - 1))
        x1 = int(np.clip(np.ceil(qhi[:, 0].max()) + ROI_MARGIN_PX + 1, x0 + 1, cfg.width_px))
        y1 = int(np.clip(np.ceil(qhi[:, 1].max()) + ROI_MARGIN_PX + 1, y0 + 1, cfg.height_px))
        w, h = x1 - x0, y1 - y0
        img = np.full((h, w), self.background_gray, np.uint8)
        # Each sticker is drawn in its own supersampled box of whole image pixels (boxes that
        # overlap are merged), then averaged down into the image: only those pixels cost ss**2.
        lo = np.maximum(np.floor(qlo).astype(int) - [x0 + 1, y0 + 1], 0).tolist()
        hi = np.minimum(np.ceil(qhi).astype(int) - [x0 - 2, y0 - 2], [w, h]).tolist()
        boxes = [[*lo[k], *hi[k], [k]] for k in range(len(mids)) if hi[k][0] > lo[k][0] and hi[k][1] > lo[k][1]]
        merged = True
        while merged:
            merged = False
            for i in range(len(boxes)):
                for j in range(i + 1, len(boxes)):
                    a, b = boxes[i], boxes[j]
                    if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                        boxes[i] = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]), a[4] + b[4]]
                        del boxes[j]
                        merged = True
                        break
                if merged:
                    break
        for bx0, by0, bx1, by1, ks in boxes:
            canvas = np.full(((by1 - by0) * ss, (bx1 - bx0) * ss), self.background_gray, np.uint8)
            for k in ks:
                # Supersampled pixel j covers image [j / ss - 0.5, (j + 1) / ss - 0.5] (pixel centres are integers).
                dst = ((quads[k] - [x0 + bx0, y0 + by0] + 0.5) * ss - 0.5).astype(np.float32)
                cv2.warpPerspective(self.stickers[mids[k]], cv2.getPerspectiveTransform(self._sticker_src, dst),
                                    canvas.shape[::-1], dst=canvas, flags=cv2.INTER_LINEAR,
                                    borderMode=cv2.BORDER_TRANSPARENT)
            img[by0:by1, bx0:bx1] = cv2.resize(canvas, (bx1 - bx0, by1 - by0), interpolation=cv2.INTER_AREA)
        if cfg.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma_px)
        return img, (x0, y0)

    def detect(self, frame: np.ndarray | SensorFrame) -> list[Detection]:
        """Markers in one full frame, by this camera's tracker (see MarkerTracker.detect)."""
        return self.tracker.detect(frame)

    def reset_tracking(self) -> None:
        """Start the next detection with a full-frame search (a new trial, a new camera session)."""
        self.tracker.reset()

