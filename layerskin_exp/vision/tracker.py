"""ArUco marker tracking and pose: the detector shared by the lab camera and the simulated one.

Detection (MarkerTracker) works on full grey frames: a full-frame search (cv2.aruco.ArucoDetector,
multi-scale adaptive threshold) acquires the markers; after that each frame is searched only in
a window around where the markers were last seen, moved on by their last frame-to-frame motion,
with one threshold scale matched to the marker's module size and only outlines near the tracked
markers' perimeter as candidates; a marker missing from the window sends the frame back to the
full-frame search. Corners are then refined from the marker outlines (`corners.py`).
The markers lie on one rigid printed layer (layout from the config), so their corners give one
joint pose (cv2.solvePnP IPPE, or SQPnP where IPPE degenerates, + cv2.solvePnPRefineLM; while
tracked, the refinement starts from the last frame's pose instead), far better conditioned in
depth and tilt than a single 38-px square; each marker's pose is that layer pose plus its known
offset. A marker seen alone falls back to cv2.solvePnP(SOLVEPNP_IPPE_SQUARE).

Camera model: pinhole (fx, fy, cx, cy); lens distortion coefficients, when given (OpenCV's
order k1, k2, p1, p2[, k3...]), enter PnP only: corners are refined as straight lines in the
distorted image, which for a marker a few dozen pixels across near the image centre is well
below the refinement's own error.

Frames: camera x right, y down, z forward (OpenCV). Marker frame as ArUco defines it: x right,
y up on the printed marker, z out of it; lengths in mm inside, m in the detections. The layer
frame has the markers' axes, its origin at the markers' mean position.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from layerskin_exp.vision.corners import PROFILE_HALF_PX, refine_marker_corners

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


class TrackerConfig(Protocol):
    """What the tracker reads from a camera config: the simulator's and the lab's CameraConfig both are one.

    Intrinsics in px; distance_mm: the working distance (camera to the marker plane), which sets
    the expected marker size in the image; markers: dictionary name (cv2.aruco.DICT_*), ids,
    side (mm, black border included) and centres on the layer (mm), one per id.
    """

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    distance_mm: float
    marker_size_mm: float
    marker_ids: Sequence[int]
    dictionary: str
    marker_x_mm: Sequence[float]
    marker_y_mm: Sequence[float]


class CroppableFrame(Protocol):
    """A frame held sparsely (the simulator's SensorFrame): its shape (H, W) and any region of it."""

    shape: tuple[int, int]

    def crop(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray: ...


@dataclass
class Detection:
    """One marker found in one image: pose in the camera frame (mm, rotation vector) and corners (4, 2) px."""

    marker_id: int
    rvec: np.ndarray
    tvec_mm: np.ndarray
    corners_px: np.ndarray


def frame_region(frame: np.ndarray | CroppableFrame, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """Pixels [y0:y1, x0:x1] of a full frame (an (H, W) array or a sparsely held one), clipped to it."""
    if not isinstance(frame, np.ndarray):
        return frame.crop(x0, y0, x1, y1)
    H, W = frame.shape[:2]
    return frame[max(y0, 0):min(y1, H), max(x0, 0):min(x1, W)]


def marker_object_points(size_mm: float) -> np.ndarray:
    """(4, 3) marker corners in the marker frame, in ArUco's order (TL, TR, BR, BL)."""
    h = size_mm / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def camera_matrix(cfg: TrackerConfig) -> np.ndarray:
    return np.array([[cfg.fx_px, 0.0, cfg.cx_px], [0.0, cfg.fy_px, cfg.cy_px], [0.0, 0.0, 1.0]])



class MarkerTracker:
    """Finds the printed markers in full grey frames and gives their poses; keeps a track between frames.

    Uses only the camera model and the printed layout from cfg, and the images: the same code
    runs on real frames ((H, W) uint8 arrays) and on the simulator's SensorFrames. track=False
    searches every frame in full (the untracked pipeline, for comparison). dist_coeffs: the
    lens distortion (OpenCV's order), None for an ideal pinhole (the simulated camera).
    """

    def __init__(self, cfg: TrackerConfig, track: bool = True, dist_coeffs: Sequence[float] | None = None) -> None:
        self.cfg, self.track = cfg, track
        self.K = camera_matrix(cfg)
        self.dist = None if dist_coeffs is None or not any(dist_coeffs) else np.asarray(dist_coeffs, np.float64)
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

    def _follow(self, frame: np.ndarray | CroppableFrame) -> dict[int, np.ndarray]:
        """Board markers found in the tracked window."""
        return self.find_in_window(frame, self._window(frame.shape), self._perimeter_px)

    def find_in_window(self, frame: np.ndarray | CroppableFrame, box: tuple[int, int, int, int],
                       perimeter_px: float) -> dict[int, np.ndarray]:
        """Board markers in frame[box] (x0, y0, x1, y1) whose outlines are within TRACK_PERIMETER_TOL of
        perimeter_px, by the single-scale follower: id -> refined (4, 2) full-frame corners."""
        span = max(box[2] - box[0], box[3] - box[1], 1)  # ArUco's perimeter bounds are relative to this
        p = self._follow_params
        p.minMarkerPerimeterRate = perimeter_px * (1.0 - TRACK_PERIMETER_TOL) / span
        p.maxMarkerPerimeterRate = perimeter_px * (1.0 + TRACK_PERIMETER_TOL) / span
        self.follower.setDetectorParameters(p)
        return self._find(frame, box, self.follower)

    def _find(self, frame: np.ndarray | CroppableFrame, box: tuple[int, int, int, int],
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

    def detect(self, frame: np.ndarray | CroppableFrame) -> list[Detection]:
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
            ok, rvec, tvec = cv2.solvePnP(self.obj_pts, pts, self.K, self.dist, flags=cv2.SOLVEPNP_IPPE_SQUARE)
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
            rvec, tvec = cv2.solvePnPRefineLM(obj, img, self.K, self.dist, guess[0].reshape(3, 1).copy(),
                                              guess[1].reshape(3, 1).copy())
            proj = cv2.projectPoints(obj, rvec, tvec, self.K, self.dist)[0].reshape(-1, 2)
            if math.sqrt(((proj - img) ** 2).sum() / len(img)) <= MAX_REPROJECTION_PX:
                return rvec.ravel(), tvec.ravel()
        ok, rvecs, tvecs, reproj = cv2.solvePnPGeneric(obj, img, self.K, self.dist, flags=cv2.SOLVEPNP_IPPE)
        if ok and float(reproj[0, 0]) <= MAX_REPROJECTION_PX:
            start = (rvecs[0], tvecs[0])
        else:
            # IPPE's rotation vector degenerates for an exactly fronto-parallel layer (a rotation
            # of pi): take the globally optimal SQPnP solution instead.
            ok, rvec, tvec = cv2.solvePnP(obj, img, self.K, self.dist, flags=cv2.SOLVEPNP_SQPNP)
            if not ok:
                return None
            start = (rvec, tvec)
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, self.K, self.dist, start[0].copy(), start[1].copy())
        return rvec.ravel(), tvec.ravel()

