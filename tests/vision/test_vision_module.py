"""The shared vision module: stands alone, and uses the calibration's lens distortion in PnP."""

import subprocess
import sys
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from layerskin_exp.vision import MarkerTracker, marker_object_points


def test_vision_imports_neither_the_simulator_nor_hardware():
    code = ("import sys, layerskin_exp.vision; "
            "bad = [m for m in sys.modules if m == 'hardware' or m.startswith(('hardware.', 'layerskin_exp.sim'))]; "
            "print(bad); sys.exit(1 if bad else 0)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stdout + res.stderr


@dataclass
class Cam:
    """A camera config as the tracker reads it (neither the lab's nor the simulator's class)."""

    fx_px: float = 900.0
    fy_px: float = 905.0
    cx_px: float = 650.0
    cy_px: float = 350.0
    distance_mm: float = 120.0
    marker_size_mm: float = 5.0
    marker_ids: tuple = (0, 1)
    dictionary: str = "DICT_4X4_50"
    marker_x_mm: tuple = (-8.0, 8.0)
    marker_y_mm: tuple = (16.0, 16.0)


def test_layer_pose_undoes_lens_distortion():
    """Corners projected through a distorting lens (cv2.projectPoints, independent of the tracker):
    with the coefficients the layer pose is exact; an ideal pinhole is off by far more."""
    cam = Cam()
    dist = (-0.25, 0.1, 0.001, -0.002, 0.0)
    K = np.array([[cam.fx_px, 0, cam.cx_px], [0, cam.fy_px, cam.cy_px], [0, 0, 1.0]])
    R = Rotation.from_rotvec([np.pi + 0.05, -0.03, 0.2])
    t = np.array([20.0, -15.0, 118.0])  # off-centre, where distortion bites
    centre = np.array([0.0, 16.0, 0.0])
    corners = {}
    for mid, x, y in zip(cam.marker_ids, cam.marker_x_mm, cam.marker_y_mm, strict=True):
        obj = marker_object_points(cam.marker_size_mm) + [x, y, 0.0] - centre
        corners[mid] = cv2.projectPoints(obj, R.as_rotvec(), t, K, np.array(dist))[0].reshape(4, 2)
    rvec, tvec = MarkerTracker(cam, dist_coeffs=dist).layer_pose(corners)
    assert np.abs(tvec - t).max() < 1e-6
    assert (Rotation.from_rotvec(rvec).inv() * R).magnitude() < 1e-8
    _, tvec_pinhole = MarkerTracker(cam).layer_pose(corners)
    assert np.abs(tvec_pinhole - t).max() > 0.5  # mm: why the lab camera passes its calibration's coefficients
    # All-zero coefficients are the ideal pinhole (what the simulated camera uses).
    assert MarkerTracker(cam, dist_coeffs=(0.0,) * 5).dist is None
