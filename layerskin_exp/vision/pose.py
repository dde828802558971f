"""Rotation conversions for marker poses."""

from __future__ import annotations

import math

import numpy as np


def quat_xyzw(rvec: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) x, y, z, w (w >= 0) of a rotation vector (3,) (angle up to pi)."""
    x, y, z = float(rvec[0]), float(rvec[1]), float(rvec[2])
    angle = math.sqrt(x * x + y * y + z * z)
    # sin(angle / 2) / angle, by its series where the angle is tiny.
    k = 0.5 - angle * angle / 48.0 if angle < 1e-4 else math.sin(0.5 * angle) / angle
    return np.array([x * k, y * k, z * k, math.cos(0.5 * angle)])
