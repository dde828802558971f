"""The marker camera: render the ArUco markers on the superficial layer, then detect them as the lab does.

Rendering is exact projective geometry: each marker (with a white quiet zone) is a plane, so
its image is the homography of the printed marker, drawn with cv2.warpPerspective onto a
supersampled canvas and averaged down (INTER_AREA), then blurred and given sensor noise. Only a
region around the markers is rendered (the rest of a real frame is background the detector
would reject).

Detection: cv2.aruco.ArucoDetector finds and decodes the markers (subpixel corners). Its
corners are then refined from the marker outlines: each outer side is located to a few
thousandths of a pixel from intensity profiles across it, well away from the corners, and the
corners are the intersections of the four fitted lines (cornerSubPix, being a gradient
estimator on a blurred 90-degree corner, pulls each corner ~0.1-0.2 px inward and drifts
with the inner bit pattern inside its window: a 0.5 % scale error, i.e. ~0.7 mm of depth at
120 mm, and tilt errors of several degrees). The two markers lie on one rigid printed layer
(layout from the config), so their 8 corners give one joint pose (cv2.aruco.Board +
cv2.solvePnP IPPE + cv2.solvePnPRefineLM), far better conditioned in depth and tilt than a
single 38-px square; each marker's pose is that layer pose plus its known offset. A marker seen
alone falls back to cv2.solvePnP(SOLVEPNP_IPPE_SQUARE). Pinhole model without distortion.

Frames: camera x right, y down, z forward (OpenCV). Marker frame as ArUco defines it: x right,
y up on the printed marker, z out of it; lengths in mm inside, m in the detections. The layer
frame has the markers' axes, its origin at the markers' mean position.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from layerskin_exp.sim.rig_config import CameraConfig

QUIET_ZONE = 0.25  # white margin around each marker, fraction of the marker side
ROI_MARGIN_PX = 20  # background around the markers; the detector needs it to find their outlines
# Edge profiles for the corner refinement (px). Across a side: +-PROFILE_HALF_PX about the
# detector's outline, inside the black border (1 module, ~6 px) and the quiet zone (~10 px);
# along it: PROFILES_PER_SIDE profiles, skipping CORNER_SKIP_PX at each end where the blurred
# corner rounds the edge.
PROFILE_HALF_PX = 3.0
PROFILE_STEP_PX = 0.25
PROFILES_PER_SIDE = 48
CORNER_SKIP_PX = 4.0
MIN_CONTRAST_GRAY = 40.0  # below this a side is not a clean black/white edge: keep the detector's corners
MAX_REFINE_SHIFT_PX = 1.5  # a refined corner further than this from the detector's is rejected


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
            self.stickers[mid] = img
        self.obj_pts = marker_object_points(cfg.marker_size_mm)
        s = cfg.marker_size_mm * (side + 2 * margin) / side / 2.0  # sticker half-side, mm (margin is whole pixels)
        self.sticker_pts = np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])
        # The printed layout: every marker on one plane, at its (x, y) on the layer (mm).
        centre_mm = np.array([np.mean(cfg.marker_x_mm), np.mean(cfg.marker_y_mm), 0.0])
        self.layer_offsets_mm = {int(mid): np.array([x, y, 0.0]) - centre_mm
                                 for mid, x, y in zip(cfg.marker_ids, cfg.marker_x_mm, cfg.marker_y_mm, strict=True)}
        self.board = cv2.aruco.Board([(self.obj_pts + self.layer_offsets_mm[int(m)]).astype(np.float32)
                                      for m in cfg.marker_ids], self.dictionary, np.array(cfg.marker_ids, np.int32))
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
        img = np.full((h, w), self.background_gray, np.uint8)
        # Each sticker is drawn in its own supersampled box of whole image pixels (boxes that
        # overlap are merged), then averaged down into the image: only those pixels cost ss**2.
        boxes = []
        for mid, q in quads.items():
            lo = np.maximum(np.floor(q.min(axis=0)).astype(int) - [x0, y0] - 1, 0)
            hi = np.minimum(np.ceil(q.max(axis=0)).astype(int) - [x0, y0] + 2, [w, h])
            if np.all(hi > lo):
                boxes.append([lo, hi, [mid]])
        merged = True
        while merged:
            merged = False
            for i in range(len(boxes)):
                for j in range(i + 1, len(boxes)):
                    (lo_i, hi_i, m_i), (lo_j, hi_j, m_j) = boxes[i], boxes[j]
                    if np.all(lo_i < hi_j) and np.all(lo_j < hi_i):
                        boxes[i] = [np.minimum(lo_i, lo_j), np.maximum(hi_i, hi_j), m_i + m_j]
                        del boxes[j]
                        merged = True
                        break
                if merged:
                    break
        for (bx0, by0), (bx1, by1), mids in boxes:
            canvas = np.full(((by1 - by0) * ss, (bx1 - bx0) * ss), self.background_gray, np.uint8)
            for mid in mids:
                n = self.stickers[mid].shape[0]
                src = np.array([[-0.5, -0.5], [n - 0.5, -0.5], [n - 0.5, n - 0.5], [-0.5, n - 0.5]], np.float32)
                # Supersampled pixel j covers image [j / ss - 0.5, (j + 1) / ss - 0.5] (pixel centres are integers).
                dst = ((quads[mid] - [x0 + bx0, y0 + by0] + 0.5) * ss - 0.5).astype(np.float32)
                cv2.warpPerspective(self.stickers[mid], cv2.getPerspectiveTransform(src, dst), canvas.shape[::-1],
                                    dst=canvas, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_TRANSPARENT)
            img[by0:by1, bx0:bx1] = cv2.resize(canvas, (bx1 - bx0, by1 - by0), interpolation=cv2.INTER_AREA)
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
        """Markers in an image whose top-left pixel is origin_px: ArUco detection, outline-refined
        corners, then a joint layer pose when two or more markers are found, IPPE_SQUARE otherwise."""
        corners, ids, _ = self.detector.detectMarkers(img)
        if ids is None:
            return []
        keep = [k for k, mid in enumerate(ids.ravel()) if int(mid) in self.stickers]
        if not keep:
            return []
        refined = refine_marker_corners(img, np.stack([corners[k].reshape(4, 2) for k in keep]))
        found = {int(ids.ravel()[k]): refined[j] + origin_px for j, k in enumerate(keep)}
        layer = self.layer_pose(found) if len(found) >= 2 else None
        out = []
        for mid, pts in found.items():
            if layer is not None:
                R = cv2.Rodrigues(layer[0])[0]
                rvec, tvec = layer[0], layer[1] + R @ self.layer_offsets_mm[mid]
            else:
                ok, rvec, tvec = cv2.solvePnP(self.obj_pts, pts, self.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
                if not ok:
                    continue
            out.append(Detection(mid, np.ravel(rvec).copy(), np.ravel(tvec).copy(), pts))
        return out

    def layer_pose(self, corners_px: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
        """Joint pose of the marker layer from all found corners: (rvec (3,), tvec (3,) mm) of the
        layer frame in the camera frame, or None if PnP fails.

        corners_px: marker id -> (4, 2) full-frame pixel corners in ArUco order.
        """
        mids = list(corners_px)
        obj, img = self.board.matchImagePoints([corners_px[m].astype(np.float32).reshape(1, 4, 2) for m in mids],
                                               np.array(mids, np.int32))
        obj = obj.reshape(-1, 3).astype(np.float64)
        img = np.concatenate([corners_px[m] for m in mids])  # same order as obj, full float64 precision
        ok, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, self.K, None, flags=cv2.SOLVEPNP_IPPE)
        if not ok:
            return None
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, self.K, None, rvecs[0].copy(), tvecs[0].copy())
        return rvec.ravel(), tvec.ravel()

    def full_frame(self, roi: np.ndarray, origin_px: tuple[int, int]) -> np.ndarray:
        """(H, W) uint8: the rendered region pasted into a background frame of the camera's size."""
        frame = np.full((self.cfg.height_px, self.cfg.width_px), self.background_gray, np.uint8)
        x0, y0 = origin_px
        frame[y0:y0 + roi.shape[0], x0:x0 + roi.shape[1]] = roi
        return frame


_R_PX = np.arange(-PROFILE_HALF_PX, PROFILE_HALF_PX + 1e-9, PROFILE_STEP_PX, dtype=np.float32)  # (I,) across a side
_U = np.linspace(0.0, 1.0, PROFILES_PER_SIDE)  # (J,) fractions of a side's usable length
_PLATEAU = max(1, int(round(0.75 / PROFILE_STEP_PX)))  # samples in the outer 0.75 px of each profile end


def refine_marker_corners(img: np.ndarray, corners_px: np.ndarray) -> np.ndarray:
    """(M, 4, 2) marker corners refined from the markers' straight outer sides.

    img: grey image (h, w); corners_px: (M, 4, 2) detector corners in img's pixel coordinates
    (pixel centres are integers), in order around each marker. Each side's edge is located by
    the coverage integral of intensity profiles across it (exact for a symmetric blur of a step,
    no threshold), a line is fitted through those edge points, and each corner is the
    intersection of its two sides. A marker whose edges are not clean keeps its input corners.
    """
    c = np.asarray(corners_px, np.float64).reshape(-1, 4, 2)
    d = np.roll(c, -1, axis=1) - c  # side k runs from corner k to corner k + 1
    length = np.linalg.norm(d, axis=2)  # (M, 4)
    t = d / length[..., None]
    n = np.stack([t[..., 1], -t[..., 0]], axis=2)
    n *= np.sign(np.sum((c + d / 2 - c.mean(axis=1, keepdims=True)) * n, axis=2))[..., None]  # outward
    s = CORNER_SKIP_PX + np.maximum(length - 2 * CORNER_SKIP_PX, 0.0)[..., None] * _U  # (M, 4, J)
    # Sample points, x and y planes apart (2, M, 4, J, I) so the innermost axis is a profile.
    base = (c[:, :, None, :] + s[..., None] * t[:, :, None, :]).transpose(3, 0, 1, 2).astype(np.float32)
    xy = base[..., None] + n.transpose(2, 0, 1).astype(np.float32)[..., None, None] * _R_PX
    prof = cv2.remap(img.astype(np.float32), xy[0].reshape(-1, _R_PX.size), xy[1].reshape(-1, _R_PX.size),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).reshape(xy.shape[1:])  # (M, 4, J, I)
    dark = prof[..., :_PLATEAU].mean(axis=(2, 3))  # (M, 4) inside: the black border
    bright = prof[..., -_PLATEAU:].mean(axis=(2, 3))  # outside: the quiet zone
    contrast = bright - dark
    cover = (prof - dark[..., None, None]) / np.maximum(contrast, 1e-6)[..., None, None]
    edge = PROFILE_HALF_PX - np.trapezoid(cover, dx=PROFILE_STEP_PX, axis=3)  # (M, 4, J) offset along n
    # Least-squares line edge = a + b s per side: the side is c + a n + s (t + b n).
    sm, em = s.mean(axis=2, keepdims=True), edge.mean(axis=2, keepdims=True)
    b = np.sum((s - sm) * (edge - em), axis=2) / np.maximum(np.sum((s - sm) ** 2, axis=2), 1e-12)
    a = em[..., 0] - b * sm[..., 0]
    p0 = c + a[..., None] * n
    dirs = t + b[..., None] * n
    # Corner k is where side k - 1 meets side k: p_prev + u d_prev = p0 + v dirs.
    p_prev, d_prev = np.roll(p0, 1, axis=1), np.roll(dirs, 1, axis=1)
    det = d_prev[..., 0] * -dirs[..., 1] + dirs[..., 0] * d_prev[..., 1]
    rhs = p0 - p_prev
    u = (rhs[..., 0] * -dirs[..., 1] + dirs[..., 0] * rhs[..., 1]) / np.where(det == 0.0, np.nan, det)
    out = p_prev + u[..., None] * d_prev
    bad = ((length.min(axis=1) < 2 * CORNER_SKIP_PX + 4.0) | (contrast.min(axis=1) < MIN_CONTRAST_GRAY)
           | ~np.isfinite(out).all(axis=(1, 2)) | ~(np.abs(out - c).max(axis=(1, 2)) <= MAX_REFINE_SHIFT_PX))
    out[bad] = c[bad]
    return out
