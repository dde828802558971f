"""The rig of the study, described once: what the bench is, on every backend.

These are facts of the hardware, not settings: the readout board sends 16 x 16 12-bit counts per
layer, the session log stores them as such, the protocols plan contacts inside the 24 x 24 mm
sensing area, the simulator presses the same indenter and rod, the camera looks for the same
printed markers. Every layer reads them from here, so no two parts can disagree; the config
keys that once repeated them are refused with a message pointing here
(`layerskin_exp.config.RETIRED_KEYS`).

Frames: the skin frame has its origin at the centre of the array, x along the columns, y along
the rows, z out of the superficial layer (towards the contact).
"""

from __future__ import annotations

import numpy as np

# --- the sensor (two stacked FSR arrays, one readout board) ---------------------------------
LAYERS = ("superficial", "deep")  # the superficial layer faces the contact
N_TAXELS = 16  # taxels per side of each layer's square array
SKIN_SHAPE = (N_TAXELS, N_TAXELS)  # one layer's map, [row (y), column (x)]
ADC_BITS = 12  # MAX11632
ADC_MAX = 2**ADC_BITS - 1  # full-scale count
PITCH_MM = 1.5  # taxel pitch: 1.2 mm electrodes and 0.3 mm gaps
ELECTRODE_MM = 1.2
SENSING_HALF_WIDTH_MM = N_TAXELS * PITCH_MM / 2  # the 24 x 24 mm sensing area, centred on the origin


def taxel_centres_mm() -> np.ndarray:
    """(16,) taxel centre coordinates along one axis (x for columns, y for rows), mm."""
    return (np.arange(N_TAXELS) - (N_TAXELS - 1) / 2) * PITCH_MM


# --- what touches it ------------------------------------------------------------------------
INDENTER_RADIUS_MM = 2.5  # the calibration platform's hemispherical tip
ROD_DIAMETER_MM = 12.0  # the fixed rod the gripper rig presses

# --- the skin on the gripper (manipulation rig) ---------------------------------------------
# Skin axes expressed in the tool (TCP) frame, as columns: x_s = x_t, y_s = -z_t, z_s = y_t.
R_TCP_SKIN = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

# --- the markers and the camera that sees them ----------------------------------------------
# Two printed ArUco markers on the superficial layer, outside the sensing area (skin frame, mm).
MARKER_DICTIONARY = "DICT_4X4_50"
MARKER_IDS = (0, 1)
MARKER_SIZE_MM = 5.0
MARKER_X_MM = (-8.0, 8.0)
MARKER_Y_MM = (16.0, 16.0)

# The fixed RealSense D435 colour stream at 1280 x 720 (69 deg horizontal field of view), at its
# working distance from the skin plane. A lab calibration replaces the intrinsics in its config.
CAMERA_WIDTH_PX = 1280
CAMERA_HEIGHT_PX = 720
CAMERA_FX_PX = 920.0
CAMERA_FY_PX = 920.0
CAMERA_CX_PX = 640.0
CAMERA_CY_PX = 360.0
CAMERA_DISTANCE_MM = 120.0  # camera centre to the skin plane, along the optical axis


class MarkerLayout:
    """The printed markers as the camera configs and the tracker read them (read-only)."""

    @property
    def dictionary(self) -> str:
        return MARKER_DICTIONARY

    @property
    def marker_ids(self) -> tuple[int, ...]:
        return MARKER_IDS

    @property
    def marker_size_mm(self) -> float:
        return MARKER_SIZE_MM

    @property
    def marker_x_mm(self) -> tuple[float, ...]:
        return MARKER_X_MM

    @property
    def marker_y_mm(self) -> tuple[float, ...]:
        return MARKER_Y_MM
