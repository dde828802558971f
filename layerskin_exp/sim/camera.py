"""The marker camera: render the ArUco markers on the superficial layer, then detect them as the lab does.

Rendering is exact projective geometry: each marker (with a white quiet zone) is a plane, so
its image is the homography of the printed marker, drawn with cv2.warpPerspective onto a
supersampled canvas and averaged down (INTER_AREA), then blurred and given sensor noise. Only a
region around the markers is rendered; the rest of the frame is uniform background, so a frame
is held sparsely (SensorFrame: the rendered patch and where it sits) and composed in full only
when an image is kept. While the markers hold still (poses equal to within rounding, e.g. a hold
or a stuck contact) the blurred patch is reused and only the sensor noise is drawn again: a
window at a random offset of one fixed bank of floored Gaussian read noise per process.

Detection (MarkerTracker) works on full frames and reads nothing from the renderer: a full-frame
search (cv2.aruco.ArucoDetector, multi-scale adaptive threshold) acquires the markers; after
that each frame is searched only in a window around where the markers were last seen, moved
on by their last frame-to-frame motion, with one threshold scale matched to the marker's
module size and only outlines near the tracked markers' perimeter as candidates; a marker
missing from the window sends the frame back to the full-frame search.
Corners are then refined from the marker outlines: each outer side is located to a few
thousandths of a pixel from intensity profiles across it, well away from the corners, and the
corners are the intersections of the four fitted lines (cornerSubPix, being a gradient
estimator on a blurred 90-degree corner, pulls each corner ~0.1-0.2 px inward and drifts
with the inner bit pattern inside its window: a 0.5 % scale error, i.e. ~0.7 mm of depth at
120 mm, and tilt errors of several degrees). The two markers lie on one rigid printed layer
(layout from the config), so their 8 corners give one joint pose (cv2.solvePnP IPPE, or SQPnP
where IPPE degenerates, + cv2.solvePnPRefineLM; while tracked, the refinement starts from the
last frame's pose instead), far better conditioned in depth and tilt than a single 38-px
square; each marker's pose is that layer pose plus its known offset. A marker seen alone falls
back to cv2.solvePnP(SOLVEPNP_IPPE_SQUARE). Pinhole model without distortion.

Frames: camera x right, y down, z forward (OpenCV). Marker frame as ArUco defines it: x right,
y up on the printed marker, z out of it; lengths in mm inside, m in the detections. The layer
frame has the markers' axes, its origin at the markers' mean position.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np

from layerskin_exp.sim.rig_config import CameraConfig

QUIET_ZONE = 0.25  # white margin around each marker, fraction of the marker side
ROI_MARGIN_PX = 20  # background rendered (blurred, noisy) around the stickers
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
# Tracking: the search window is the markers' last corners and those moved on by their last
# motion, grown by TRACK_MARGIN_SIDES marker sides; a track that lacks some of the board's
# markers is re-searched over the full frame every REACQUIRE_FRAMES frames.
TRACK_MARGIN_SIDES = 0.5
REACQUIRE_FRAMES = 30
# Inside the window only outlines within this fraction of the tracked markers' perimeter are
# candidates (a frame changes it by far less): the sticker's own outline (1.5x) and the bit
# pattern's blobs are dropped before they are decoded.
TRACK_PERIMETER_TOL = 0.25
# Candidates closer than this (mean corner distance / perimeter) are one marker. OpenCV's 0.125
# groups a marker with the inner outline of the grey ring a cut-off window leaves around its
# white sticker (corners a quiet zone apart diagonally, ~0.09 perimeter) and may keep the ring,
# losing the marker. No duplicates appear at 0.05 (the tests check one detection per marker).
MIN_MARKER_DISTANCE_RATE = 0.05
MAX_REPROJECTION_PX = 1.0  # rms reprojection error above which an IPPE layer pose is not trusted
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
class Detection:
    """One marker found in one image: pose in the camera frame (mm, rotation vector) and corners (4, 2) px."""

    marker_id: int
    rvec: np.ndarray
    tvec_mm: np.ndarray
    corners_px: np.ndarray


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


def frame_region(frame: np.ndarray | SensorFrame, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """Pixels [y0:y1, x0:x1] of a full frame (an (H, W) array or a SensorFrame), clipped to it."""
    if isinstance(frame, SensorFrame):
        return frame.crop(x0, y0, x1, y1)
    H, W = frame.shape[:2]
    return frame[max(y0, 0):min(y1, H), max(x0, 0):min(x1, W)]


def marker_object_points(size_mm: float) -> np.ndarray:
    """(4, 3) marker corners in the marker frame, in ArUco's order (TL, TR, BR, BL)."""
    h = size_mm / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def _camera_matrix(cfg: CameraConfig) -> np.ndarray:
    return np.array([[cfg.fx_px, 0.0, cfg.cx_px], [0.0, cfg.fy_px, cfg.cy_px], [0.0, 0.0, 1.0]])


class MarkerTracker:
    """Finds the printed markers in full grey frames and gives their poses; keeps a track between frames.

    Uses only the camera model and the printed layout from cfg, and the images: the same code
    runs on real frames ((H, W) uint8 arrays) and on the simulator's SensorFrames. track=False
    searches every frame in full (the untracked pipeline, for comparison).
    """

    def __init__(self, cfg: CameraConfig, track: bool = True) -> None:
        self.cfg, self.track = cfg, track
        self.K = _camera_matrix(cfg)
        self.dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, cfg.dictionary))
        self.marker_ids = tuple(int(m) for m in cfg.marker_ids)
        self.acquirer = cv2.aruco.ArucoDetector(self.dictionary, self._params())
        # Inside the window the marker's scale is known: one threshold window of ~2 modules, and
        # outlines only of about the tracked markers' perimeter (set per frame, see _follow).
        module_px = cfg.fx_px * cfg.marker_size_mm / cfg.distance_mm / (self.dictionary.markerSize + 2)
        win = max(3, 2 * int(round(module_px)) + 1)
        self._follow_params = self._params(win)
        self.follower = cv2.aruco.ArucoDetector(self.dictionary, self._follow_params)
        self.obj_pts = marker_object_points(cfg.marker_size_mm)
        # The printed layout: every marker on one plane, at its (x, y) on the layer (mm).
        centre_mm = np.array([np.mean(cfg.marker_x_mm), np.mean(cfg.marker_y_mm), 0.0])
        self.layer_offsets_mm = {int(mid): np.array([x, y, 0.0]) - centre_mm
                                 for mid, x, y in zip(cfg.marker_ids, cfg.marker_x_mm, cfg.marker_y_mm, strict=True)}
        self._layer_obj: dict[tuple[int, ...], np.ndarray] = {}  # marker ids -> their (4 M, 3) corners on the layer
        self.full_searches = 0  # frames that needed the full-frame search, since construction (diagnostics)
        self.reset()
        # Load the compiled refinement kernels now rather than on the first frame (no latency spike there).
        refine_marker_corners(np.zeros((32, 32), np.uint8), np.array([[[8.0, 8.0], [24.0, 8.0], [24.0, 24.0], [8.0, 24.0]]]))

    @staticmethod
    def _params(window_px: int | None = None) -> cv2.aruco.DetectorParameters:
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        params.cornerRefinementWinSize = 4
        params.relativeCornerRefinmentWinSize = 1.0  # the default 0.3 module shrinks the window to ~1 px
        params.cornerRefinementMinAccuracy = 0.01
        params.cornerRefinementMaxIterations = 50
        params.minMarkerDistanceRate = MIN_MARKER_DISTANCE_RATE
        if window_px is not None:
            params.adaptiveThreshWinSizeMin = params.adaptiveThreshWinSizeMax = window_px
        return params

    def reset(self) -> None:
        """Forget the track: the next frame is searched in full."""
        self._track: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # id -> (corners (4, 2), last motion (4, 2)) px
        self._box: tuple[int, int, int, int] | None = None  # the next search window, unclipped (x0, y0, x1, y1)
        self._perimeter_px = 0.0  # largest tracked marker outline
        self._layer: tuple[tuple[int, ...], np.ndarray, np.ndarray] | None = None  # last layer pose (ids, rvec, tvec)
        self._since_full = 0

    def _update_track(self, found: dict[int, np.ndarray]) -> None:
        """Track the markers just found; the next window spans their corners and those moved on by their
        last motion, grown by TRACK_MARGIN_SIDES marker sides (plus the refinement's reach)."""
        track, xs, ys, side, perimeter = {}, [], [], 0.0, 0.0
        for mid, pts in found.items():
            last = self._track.get(mid)
            motion = pts - last[0] if last is not None else np.zeros((4, 2))
            track[mid] = (pts, motion)
            p = pts.tolist()
            for (x, y), (dx, dy) in zip(p, motion.tolist(), strict=True):
                xs += (x, x + dx)
                ys += (y, y + dy)
            sides = [math.hypot(p[k][0] - p[k - 1][0], p[k][1] - p[k - 1][1]) for k in range(4)]
            side, perimeter = max(side, sides[1]), max(perimeter, sum(sides))  # sides[1]: corner 0 to 1
        self._track, self._perimeter_px = track, perimeter
        m = TRACK_MARGIN_SIDES * side + PROFILE_HALF_PX
        self._box = (math.floor(min(xs) - m), math.floor(min(ys) - m), math.ceil(max(xs) + m) + 1,
                     math.ceil(max(ys) + m) + 1) if found else None

    def _window(self, shape: tuple[int, int]) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1) search window from the track, inside the frame of shape (H, W)."""
        x0, y0, x1, y1 = self._box
        return max(x0, 0), max(y0, 0), min(x1, shape[1]), min(y1, shape[0])

    def _follow(self, frame: np.ndarray | SensorFrame) -> dict[int, np.ndarray]:
        """Board markers found in the tracked window."""
        return self.find_in_window(frame, self._window(frame.shape), self._perimeter_px)

    def find_in_window(self, frame: np.ndarray | SensorFrame, box: tuple[int, int, int, int],
                       perimeter_px: float) -> dict[int, np.ndarray]:
        """Board markers in frame[box] (x0, y0, x1, y1) whose outlines are within TRACK_PERIMETER_TOL of
        perimeter_px, by the single-scale follower: id -> refined (4, 2) full-frame corners."""
        span = max(box[2] - box[0], box[3] - box[1], 1)  # ArUco's perimeter bounds are relative to this
        p = self._follow_params
        p.minMarkerPerimeterRate = perimeter_px * (1.0 - TRACK_PERIMETER_TOL) / span
        p.maxMarkerPerimeterRate = perimeter_px * (1.0 + TRACK_PERIMETER_TOL) / span
        self.follower.setDetectorParameters(p)
        return self._find(frame, box, self.follower)

    def _find(self, frame: np.ndarray | SensorFrame, box: tuple[int, int, int, int],
              detector: cv2.aruco.ArucoDetector) -> dict[int, np.ndarray]:
        """Board markers found in frame[box]: id -> refined (4, 2) full-frame corners, in id order."""
        x0, y0, x1, y1 = box
        corners, ids, _ = detector.detectMarkers(frame_region(frame, x0, y0, x1, y1))
        if ids is None:
            return {}
        mids = ids.ravel().tolist()
        # By id: the detector's order varies from frame to frame, the layer pose's start must not.
        keep = sorted((k for k, mid in enumerate(mids) if mid in self.layer_offsets_mm), key=mids.__getitem__)
        if not keep:
            return {}
        c = np.array([corners[k] for k in keep], np.float64).reshape(-1, 4, 2)  # window pixels
        # Refine on the frame's own pixels around the markers (the profiles reach past the window's edge).
        r = PROFILE_HALF_PX + 3.0
        (lx, ly), (hx, hy) = c.min(axis=(0, 1)).tolist(), c.max(axis=(0, 1)).tolist()
        rx0, ry0 = max(math.floor(lx + x0 - r), 0), max(math.floor(ly + y0 - r), 0)
        rx1, ry1 = math.ceil(hx + x0 + r) + 1, math.ceil(hy + y0 + r) + 1
        c += (x0 - rx0, y0 - ry0)  # exact: whole pixels added to float32 corners
        refined = refine_marker_corners(frame_region(frame, rx0, ry0, rx1, ry1), c)
        refined += (rx0, ry0)
        return {mids[k]: refined[j] for j, k in enumerate(keep)}

    def detect(self, frame: np.ndarray | SensorFrame) -> list[Detection]:
        """Markers in one full frame (H, W): tracked-window search, full-frame search when it loses a
        marker, outline-refined corners, then a joint layer pose from two or more markers."""
        found = None
        tracking = self.track and bool(self._track) and (len(self._track) == len(self.marker_ids)
                                                         or self._since_full < REACQUIRE_FRAMES)
        if tracking:
            found = self._follow(frame)
            if not set(self._track) <= set(found):
                found = None
        if found is None:
            found = self._find(frame, (0, 0, frame.shape[1], frame.shape[0]), self.acquirer)
            self._since_full = 0
            self.full_searches += 1
            self._layer = None
        else:
            self._since_full += 1
        self._update_track(found)
        ids = tuple(found)
        layer = None
        if len(found) >= 2:
            # While tracked, the last layer pose of the same markers starts the refinement.
            guess = self._layer[1:] if self._layer is not None and self._layer[0] == ids else None
            layer = self.layer_pose(found, guess)
        self._layer = None if layer is None else (ids, *layer)
        out = []
        if layer is not None:
            rvec, tvec = layer
            R = cv2.Rodrigues(rvec)[0]
            for mid, pts in found.items():
                out.append(Detection(mid, rvec.copy(), tvec + R @ self.layer_offsets_mm[mid], pts))
            return out
        for mid, pts in found.items():
            ok, rvec, tvec = cv2.solvePnP(self.obj_pts, pts, self.K, None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
            if ok:
                out.append(Detection(mid, rvec.ravel(), tvec.ravel(), pts))
        return out

    def layer_pose(self, corners_px: dict[int, np.ndarray], guess: tuple[np.ndarray, np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray] | None:
        """Joint pose of the marker layer from all found corners: (rvec (3,), tvec (3,) mm) of the
        layer frame in the camera frame, or None if PnP fails.

        corners_px: marker id -> (4, 2) full-frame pixel corners in ArUco order. guess: a pose near
        the answer (the last frame's) to refine from; without one, or when refining it leaves more
        than MAX_REPROJECTION_PX rms, the pose starts from IPPE (SQPnP where IPPE degenerates).
        """
        ids = tuple(corners_px)
        obj = self._layer_obj.get(ids)
        if obj is None:
            obj = self._layer_obj[ids] = np.concatenate([self.obj_pts + self.layer_offsets_mm[m] for m in ids])
        img = np.concatenate(list(corners_px.values()))
        if guess is not None:
            # (3, 1) vectors (solvePnPRefineLM returns (3,) ones unrefined), copies (it refines in place).
            rvec, tvec = cv2.solvePnPRefineLM(obj, img, self.K, None, guess[0].reshape(3, 1).copy(),
                                              guess[1].reshape(3, 1).copy())
            proj = cv2.projectPoints(obj, rvec, tvec, self.K, None)[0].reshape(-1, 2)
            if math.sqrt(((proj - img) ** 2).sum() / len(img)) <= MAX_REPROJECTION_PX:
                return rvec.ravel(), tvec.ravel()
        ok, rvecs, tvecs, reproj = cv2.solvePnPGeneric(obj, img, self.K, None, flags=cv2.SOLVEPNP_IPPE)
        if ok and float(reproj[0, 0]) <= MAX_REPROJECTION_PX:
            start = (rvecs[0], tvecs[0])
        else:
            # IPPE's rotation vector degenerates for an exactly fronto-parallel layer (a rotation
            # of pi): take the globally optimal SQPnP solution instead.
            ok, rvec, tvec = cv2.solvePnP(obj, img, self.K, None, flags=cv2.SOLVEPNP_SQPNP)
            if not ok:
                return None
            start = (rvec, tvec)
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, self.K, None, start[0].copy(), start[1].copy())
        return rvec.ravel(), tvec.ravel()


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


_R_PX = np.arange(-PROFILE_HALF_PX, PROFILE_HALF_PX + 1e-9, PROFILE_STEP_PX)  # (I,) offsets across a side
_U = np.linspace(0.0, 1.0, PROFILES_PER_SIDE)  # (J,) fractions of a side's usable length
_PLATEAU = max(1, int(round(0.75 / PROFILE_STEP_PX)))  # samples in the outer 0.75 px of each profile end
_jit = numba.njit(cache=True, error_model="numpy")


@_jit
def _side_frames(c):
    """Per side of each (4, 2) quad in c (M, 4, 2): length (M, 4), unit direction and outward unit normal (M, 4, 2)."""
    m_count = c.shape[0]
    length = np.empty((m_count, 4))
    t = np.empty((m_count, 4, 2))
    n = np.empty((m_count, 4, 2))
    for m in range(m_count):
        mx = (c[m, 0, 0] + c[m, 1, 0] + c[m, 2, 0] + c[m, 3, 0]) / 4.0
        my = (c[m, 0, 1] + c[m, 1, 1] + c[m, 2, 1] + c[m, 3, 1]) / 4.0
        for k in range(4):
            k1 = (k + 1) % 4
            dx, dy = c[m, k1, 0] - c[m, k, 0], c[m, k1, 1] - c[m, k, 1]
            ln = math.sqrt(dx * dx + dy * dy)
            length[m, k] = ln
            t[m, k, 0], t[m, k, 1] = dx / ln, dy / ln
            # Outward: the normal points away from the quad's centre as seen from the side's midpoint.
            side = (c[m, k, 0] + dx / 2 - mx) * t[m, k, 1] - (c[m, k, 1] + dy / 2 - my) * t[m, k, 0]
            sg = 1.0 if side > 0 else (-1.0 if side < 0 else 0.0)
            n[m, k, 0], n[m, k, 1] = sg * t[m, k, 1], -sg * t[m, k, 0]
    return length, t, n


@_jit
def _profile_maps(c, r_px, u, skip_px):
    """Sample points of the edge profiles: x and y maps (M * 4 * J, I) float32; profile j of side k
    of marker m is row (m * 4 + k) * J + j, centred on the side at skip_px + u[j] (length - 2 skip_px)."""
    length, t, n = _side_frames(c)
    n_j, n_i = u.size, r_px.size
    map_x = np.empty((c.shape[0] * 4 * n_j, n_i), np.float32)
    map_y = np.empty_like(map_x)
    for m in range(c.shape[0]):
        for k in range(4):
            usable = max(length[m, k] - 2 * skip_px, 0.0)
            for j in range(n_j):
                s = skip_px + usable * u[j]
                px, py = c[m, k, 0] + s * t[m, k, 0], c[m, k, 1] + s * t[m, k, 1]
                row = (m * 4 + k) * n_j + j
                for i in range(n_i):
                    map_x[row, i] = px + r_px[i] * n[m, k, 0]
                    map_y[row, i] = py + r_px[i] * n[m, k, 1]
    return map_x, map_y


@_jit
def _fit_corners(c, prof, r_px, u, skip_px, step_px, plateau, min_contrast, max_shift_px):
    """Corners (M, 4, 2) from the profiles (M * 4 * J, I) sampled at _profile_maps' points.

    Per side: dark (inner) and bright (outer) levels from the profiles' end plateaus, each
    profile's edge offset from its coverage integral (trapezoid rule), a least-squares line
    offset = a + b s through those, and each corner where its two sides' lines meet. A marker
    with a short or low-contrast side, or a corner moved further than max_shift_px, keeps c."""
    length, t, n = _side_frames(c)
    m_count, n_j, n_i = c.shape[0], u.size, r_px.size
    half = (n_i - 1) * step_px / 2.0
    out = c.copy()
    p0 = np.empty((4, 2))
    dirs = np.empty((4, 2))
    s = np.empty(n_j)
    edge = np.empty(n_j)
    for m in range(m_count):
        ok = True
        for k in range(4):
            if length[m, k] < 2 * skip_px + 4.0:
                ok = False
            usable = max(length[m, k] - 2 * skip_px, 0.0)
            base = (m * 4 + k) * n_j
            dark = 0.0
            bright = 0.0
            for j in range(n_j):
                for i in range(plateau):
                    dark += prof[base + j, i]
                    bright += prof[base + j, n_i - 1 - i]
            dark /= n_j * plateau
            bright /= n_j * plateau
            contrast = bright - dark
            if not contrast >= min_contrast:
                ok = False
            for j in range(n_j):
                area = 0.0
                for i in range(n_i):
                    area += prof[base + j, i]
                area = (area - 0.5 * (prof[base + j, 0] + prof[base + j, n_i - 1])) * step_px
                s[j] = skip_px + usable * u[j]
                # Edge offset along n: the profile's width minus its area of coverage (0 dark .. 1 bright).
                edge[j] = half - (area - 2 * half * dark) / max(contrast, 1e-6)
            sm, em = s.mean(), edge.mean()
            sxx = 0.0
            sxy = 0.0
            for j in range(n_j):
                sxx += (s[j] - sm) ** 2
                sxy += (s[j] - sm) * (edge[j] - em)
            b = sxy / max(sxx, 1e-12)
            a = em - b * sm
            # The side is c + a n + s (t + b n).
            for ax in range(2):
                p0[k, ax] = c[m, k, ax] + a * n[m, k, ax]
                dirs[k, ax] = t[m, k, ax] + b * n[m, k, ax]
        if not ok:
            continue
        corners = np.empty((4, 2))
        for k in range(4):
            kp = (k + 3) % 4  # corner k is where side k - 1 meets side k
            det = dirs[kp, 0] * -dirs[k, 1] + dirs[k, 0] * dirs[kp, 1]
            if det == 0.0:
                ok = False
                break
            rx, ry = p0[k, 0] - p0[kp, 0], p0[k, 1] - p0[kp, 1]
            v = (rx * -dirs[k, 1] + dirs[k, 0] * ry) / det
            corners[k, 0] = p0[kp, 0] + v * dirs[kp, 0]
            corners[k, 1] = p0[kp, 1] + v * dirs[kp, 1]
            if not (abs(corners[k, 0] - c[m, k, 0]) <= max_shift_px and abs(corners[k, 1] - c[m, k, 1]) <= max_shift_px):
                ok = False
        if ok:
            out[m] = corners
    return out


def refine_marker_corners(img: np.ndarray, corners_px: np.ndarray) -> np.ndarray:
    """(M, 4, 2) marker corners refined from the markers' straight outer sides.

    img: grey image (h, w); corners_px: (M, 4, 2) detector corners in img's pixel coordinates
    (pixel centres are integers), in order around each marker. Each side's edge is located by
    the coverage integral of intensity profiles across it (exact for a symmetric blur of a step,
    no threshold), a line is fitted through those edge points, and each corner is the
    intersection of its two sides. A marker whose edges are not clean keeps its input corners.
    The geometry runs in compiled kernels; the profiles are sampled by cv2.remap (bilinear).
    """
    c = np.ascontiguousarray(corners_px, np.float64).reshape(-1, 4, 2)
    if c.shape[0] == 0:
        return c.copy()
    map_x, map_y = _profile_maps(c, _R_PX, _U, CORNER_SKIP_PX)
    prof = cv2.remap(img.astype(np.float32), map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return _fit_corners(c, prof, _R_PX, _U, CORNER_SKIP_PX, PROFILE_STEP_PX, _PLATEAU, MIN_CONTRAST_GRAY,
                        MAX_REFINE_SHIFT_PX)
