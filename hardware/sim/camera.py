"""Simulated D435 + ArUco pipeline: 30 fps images of the markers, detections out after the pipeline latency."""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from hardware.interfaces import MarkerCamera
from hardware.sim.stream_device import SimStreamMixin
from layerskin_exp.sim import mechanics as mk
from layerskin_exp.sim.camera import MarkerImager, SensorFrame
from layerskin_exp.sim.grip_scene import GripScene
from layerskin_exp.sim.rig_config import CameraConfig
from layerskin_exp.sim.world import World
from layerskin_exp.types import MarkerDetection, Pose
from layerskin_exp.vision import quat_xyzw

# Camera axes in the skin frame at the home pose: looking down the skin normal onto the cover,
# image x along skin x, image y along -skin y.
R_SKIN_CAMERA = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
# Frames kept for take_images() when images are kept: half a second at 30 fps. A consumer that
# falls further behind loses the oldest (counted in images_overrun), as a capture ring does.
KEPT_FRAMES = 16


class SimMarkerCamera(SimStreamMixin, MarkerCamera):
    """Renders and detects each frame; a detection reaches the host latency_ms after exposure.

    The camera is fixed in the base frame, placed at `distance_mm` along the skin normal from
    the markers' midpoint with the arm at home and the jaws at contact_opening_mm.
    """

    def __init__(self, world: World, scene: GripScene, cfg: CameraConfig, contact_opening_mm: float) -> None:
        super().__init__()
        self.world, self.scene, self.cfg = world, scene, cfg
        self.imager = MarkerImager(cfg)
        self.stream = world.new_stream("camera", cfg.clock, 1.0 / cfg.fps)
        self._img_rng = np.random.default_rng(self.stream.rng.integers(2**63))
        o, R_s = scene.skin_pose(scene.home_p_m, scene.R_ref, contact_opening_mm)
        centre_mm = np.array([np.mean(cfg.marker_x_mm), np.mean(cfg.marker_y_mm), cfg.distance_mm])
        self.R_base_cam = R_s @ R_SKIN_CAMERA
        self.t_base_cam_m = o + R_s @ centre_mm * 1e-3
        self.marker_xy_mm = np.stack([cfg.marker_x_mm, cfg.marker_y_mm], axis=1)  # (M, 2)
        self._marker_xy = self.marker_xy_mm.tolist()
        self._R_cam_base = np.ascontiguousarray(self.R_base_cam.T)
        self._marker_ids = [int(m) for m in cfg.marker_ids]
        self._latest: tuple[SensorFrame | np.ndarray, int, int] | None = None
        self._kept: deque[tuple[SensorFrame, int, int]] = deque(maxlen=KEPT_FRAMES)
        self.images_overrun = 0  # kept frames pushed out before take_images() took them
        self._last_host_ns = -1
        world.add_producer(self.stream, self._produce)
        world.on_trial(self._reseed)

    def _reseed(self, world: World) -> None:
        self._img_rng = world.rng("camera.image")
        self.imager.reset_tracking()  # each trial's detections depend on its own frames only

    def marker_poses(self, snap: np.ndarray, rec: np.ndarray) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Marker id -> (R (3, 3), t (3,) mm): marker frames in the camera frame for one scene snapshot
        (13+ values, see GripScene.snapshot_names) and the skin's step record of the same step
        (mechanics.S_* columns: contact point, surface shift and turn)."""
        o, R_s = self.scene.skin_pose(snap[:3], snap[3:12].reshape(3, 3), snap[12])
        # The superficial layer is shifted by u and turned by phi about the contact point a
        # (skin model's convention): x_deep = a + u + R(phi) (x_s - a), written as
        # x_s + u + (R(phi) - I) (x_s - a) so that an unturned layer's markers do not take on
        # rounding from a moving contact point (a still layer keeps its poses: its render is reused).
        phi = float(rec[mk.S_THETA])
        c, s = math.cos(phi), math.sin(phi)
        ax, ay, ux, uy = float(rec[mk.S_CX]), float(rec[mk.S_CY]), float(rec[mk.S_UX]), float(rec[mk.S_UY])
        xyz = np.array([[x + ux + (c - 1.0) * (x - ax) - s * (y - ay), y + uy + s * (x - ax) + (c - 1.0) * (y - ay), 0.0]
                        for x, y in self._marker_xy])  # (M, 3) mm on the layer
        R_cs = self._R_cam_base @ R_s
        R_cm = R_cs @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        # t_cam = R_cb (o + R_s xyz 1e-3 - t_base_cam) 1e3, all markers at once.
        t_mm = xyz @ R_cs.T + self._R_cam_base @ (o - self.t_base_cam_m) * 1e3
        return {mid: (R_cm, t_mm[k]) for k, mid in enumerate(self._marker_ids)}

    def _produce(self, world: World, t_s: np.ndarray, idx: np.ndarray) -> None:
        snaps = world.snapshots(idx)
        recs = world.records(idx)
        seq, dev_ns, _ = self.stream.stamp(t_s)
        cfg = self.cfg
        lat = cfg.latency_ms * 1e6 + self._img_rng.normal(0.0, cfg.latency_jitter_ms * 1e6, len(t_s))
        host = (world.host_start_ns + t_s * 1e9 + np.maximum(lat, 0.0)).astype(np.int64).tolist()
        seq, dev_ns = seq.tolist(), dev_ns.tolist()
        for i in range(len(t_s)):
            h = max(host[i], self._last_host_ns)  # the pipeline delivers in order
            self._last_host_ns = h
            frame = self.imager.render(self.marker_poses(snaps[i], recs[i]), self._img_rng)
            if cfg.keep_images:
                self._latest = (frame, dev_ns[i], h)  # composed into a full image when asked for
                if len(self._kept) == KEPT_FRAMES:
                    self.images_overrun += 1
                self._kept.append((frame, dev_ns[i], h))
            for d in self.imager.detect(frame):
                pose = Pose(d.tvec_mm * 1e-3, quat_xyzw(d.rvec), "camera", dev_ns[i], h, seq[i])
                self.stream.push(h, MarkerDetection(d.marker_id, pose, d.corners_px, seq[i], dev_ns[i], h))

    def read_available(self) -> list[MarkerDetection]:
        self._require_connected()
        out = self.stream.pop_received(self.world.host_now_ns())
        for det in out:
            if det.frame_seq != self._last_seq:
                self.health.observe_seq(self._last_seq, det.frame_seq)
                self._last_seq = det.frame_seq
        return out

    def latest_image(self) -> np.ndarray | None:
        """The most recent full grey frame (H, W) uint8, when sim.rig.camera.keep_images is set."""
        stamped = self.latest_image_stamped()
        return None if stamped is None else stamped[0]

    def latest_image_stamped(self) -> tuple[np.ndarray, int, int] | None:
        """(image (H, W) uint8, device_t_ns, host_t_ns) of the most recent frame, when images are kept."""
        if self._latest is not None and isinstance(self._latest[0], SensorFrame):
            self._latest = (self._latest[0].full(), *self._latest[1:])
        return self._latest

    def take_images(self) -> list[tuple[SensorFrame, int, int]]:
        """Every frame made since the last call (at most KEPT_FRAMES), oldest first, when images are
        kept: (frame, device_t_ns, host_t_ns); `frame.full()` is the (H, W) uint8 image. For a
        consumer that must see each frame (the loopback camera), where latest_image_stamped()
        would skip those made between two looks. Safe without the world's lock (each deque
        operation is atomic), so a consumer need not wait out a world catching up under it."""
        out = []
        while True:
            try:
                out.append(self._kept.popleft())
            except IndexError:
                return out

    def calibration(self) -> dict:
        """Intrinsics and the camera's pose in the arm base frame (for the session metadata)."""
        return {"K": self.imager.K.tolist(), "dist": [0.0] * 5, "width_px": self.cfg.width_px,
                "height_px": self.cfg.height_px, "marker_size_mm": self.cfg.marker_size_mm,
                "marker_ids": list(self.cfg.marker_ids), "dictionary": self.cfg.dictionary,
                "R_base_camera": self.R_base_cam.tolist(), "t_base_camera_m": self.t_base_cam_m.tolist()}
