"""Typed records that flow device -> acquisition -> session log -> reader -> analysis.

Every record keeps the device's own timestamp and the host's receive time (monotonic ns),
never a synthetic one: clock alignment happens later, from both.
Units are in the names; array shapes are in the docstrings.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from layerskin_exp.rig import ADC_MAX, SKIN_SHAPE  # noqa: F401 - the records' shape and range, the rig's


@dataclass(frozen=True, slots=True)
class TwoLayerFrame:
    """One scan of both layers.

    superficial, deep: (16, 16) uint16 ADC counts (0..4095), [row, column]; row i is along y,
    column j along x (taxel centre x_j = (j - 7.5) * pitch_mm, y_i likewise).
    """

    superficial: np.ndarray
    deep: np.ndarray
    seq: int  # device frame counter (wraps are unwrapped by the driver)
    device_t_ns: int  # device clock
    host_t_ns: int  # host monotonic receive time


@dataclass(frozen=True, slots=True)
class Wrench:
    """One F/T sample: force (3,) in N and torque (3,) in N·m in the sensor frame."""

    force_n: np.ndarray
    torque_nm: np.ndarray
    seq: int  # RDT sequence number
    device_t_ns: int
    host_t_ns: int
    status: int = 0


@dataclass(frozen=True, slots=True)
class Pose:
    """A rigid pose: position (3,) in m, orientation quaternion (4,) as x, y, z, w."""

    position_m: np.ndarray
    orientation_xyzw: np.ndarray
    frame_id: str
    device_t_ns: int
    host_t_ns: int
    seq: int = 0


@dataclass(frozen=True, slots=True)
class StagePosition:
    """Three-axis platform position (3,) in mm (indenter tip in the skin frame)."""

    position_mm: np.ndarray
    seq: int
    device_t_ns: int
    host_t_ns: int


@dataclass(frozen=True, slots=True)
class MarkerDetection:
    """One ArUco marker seen in one camera image.

    pose: marker pose in the camera frame (from PnP). corners_px: (4, 2) image corners.
    device_t_ns is the image's capture time on the camera clock (before pipeline latency).
    """

    marker_id: int
    pose: Pose
    corners_px: np.ndarray
    frame_seq: int
    device_t_ns: int
    host_t_ns: int


@dataclass(frozen=True, slots=True)
class GripperState:
    """Robotiq Hand-E state: jaw opening in mm, speed and force in the gripper's own units (0..255)."""

    position_mm: float
    requested_mm: float
    speed: int
    force: int
    object_detected: bool
    fault: int
    device_t_ns: int
    host_t_ns: int
    seq: int = 0


@dataclass(frozen=True, slots=True)
class FrameTransform:
    """Where `child_frame_id` is in `parent_frame_id` at host time host_t_ns: translation (3,) m
    and rotation quaternion (4,) x, y, z, w, so that p_parent = R p_child + t.

    The session's frame tree: base -> tool -> skin, base -> camera, camera -> marker_<id>
    (see layerskin_exp.log.view.frame_tree). Geometry, not a device sample: it has no device clock.
    """

    parent_frame_id: str
    child_frame_id: str
    translation_m: np.ndarray
    rotation_xyzw: np.ndarray
    host_t_ns: int


@dataclass(frozen=True, slots=True)
class ProtocolEvent:
    """A protocol happening: phase change, contact detected, stop reason, safety trip.

    kind: short machine name ("phase", "contact", "stop", "safety", "error").
    detail: free-form key/value pairs (JSON-serialisable).
    """

    kind: str
    message: str
    host_t_ns: int
    device_t_ns: int = 0
    detail: dict = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class SkinEstimate:
    """A live estimate from the skin (layerskin_exp.estimation.OnlineEstimator).

    force_n: (3,) Fx, Fy, Fz in N; slip_score in MAD units of the detector's training envelope
    (None without a slip detector); slip: this frame confirms a slip event (a score peak at or
    above the fitted threshold, one frame earlier).
    frame: index of the downsampled frame; device_t_ns: its time on the skin clock (the filter's
    centre); host_t_ns: receive time of the raw frame that completed it.
    """

    force_n: np.ndarray
    slip_score: float | None
    slip: bool
    frame: int
    device_t_ns: int
    host_t_ns: int


@dataclass(slots=True)
class StreamHealth:
    """Health counters every acquired stream reports the same way."""

    received: int = 0
    lost: int = 0  # gaps in the device sequence number
    duplicate: int = 0
    out_of_order: int = 0
    corrupt: int = 0  # bytes or packets rejected by a parser (after resync)
    reconnects: int = 0

    def observe_seqs(self, last_seq: int | None, seqs: list[int]) -> int | None:
        """observe_seq for each of seqs in order; returns the last sequence number seen."""
        n = len(seqs)
        if n and last_seq is not None and seqs[0] == last_seq + 1 and seqs[-1] == last_seq + n \
                and seqs == list(range(last_seq + 1, last_seq + n + 1)):
            self.received += n  # the common case: no gap, no repeat
            return seqs[-1]
        for seq in seqs:
            self.observe_seq(last_seq, seq)
            last_seq = seq
        return last_seq

    def observe_seq(self, last_seq: int | None, seq: int) -> None:
        """Update the counters from one sequence number, given the previous one."""
        self.received += 1
        if last_seq is None:
            return
        if seq == last_seq:
            self.duplicate += 1
        elif seq < last_seq:
            self.out_of_order += 1
        elif seq > last_seq + 1:
            self.lost += seq - last_seq - 1
