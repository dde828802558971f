"""UR5e kinematics: the flange pose of six joint angles and the joint angles of a flange pose.

Denavit-Hartenberg parameters from Universal Robots' published table for the UR5e ("DH
parameters for calculations of kinematics and dynamics"): a = (0, -0.425, -0.3922, 0, 0, 0) m,
d = (0.1625, 0, 0, 0.1333, 0.0997, 0.0996) m, alpha = (pi/2, 0, 0, pi/2, -pi/2, 0). Each joint's
transform is Rz(theta) Tz(d) Tx(a) Rx(alpha); the base frame is the robot's base frame of RTDE.

`inverse` is the closed-form solution of the UR arms (K. P. Hawkins, "Analytic Inverse Kinematics
for the Universal Robots UR-5/UR-10 Arms", 2013): up to eight solutions (shoulder left/right, wrist
up/down, elbow up/down), of which the one nearest `q_near` is returned, each joint taken in the
turn nearest q_near's, as URScript's get_inverse_kin does.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

A_M = (0.0, -0.425, -0.3922, 0.0, 0.0, 0.0)
D_M = (0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996)
ALPHA_RAD = (np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0)


class NoSolution(ValueError):
    """A pose the arm cannot reach (URScript's get_inverse_kin fails on it)."""


def joint_transform(i: int, theta: float) -> np.ndarray:
    """(4, 4) transform of joint i (0-based) at angle theta."""
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(ALPHA_RAD[i]), np.sin(ALPHA_RAD[i])
    return np.array([[ct, -st * ca, st * sa, A_M[i] * ct],
                     [st, ct * ca, -ct * sa, A_M[i] * st],
                     [0.0, sa, ca, D_M[i]],
                     [0.0, 0.0, 0.0, 1.0]])


def forward(q) -> np.ndarray:
    """(4, 4) flange transform in the base frame for joint angles q (6,) rad."""
    t = np.eye(4)
    for i, theta in enumerate(np.asarray(q, float)):
        t = t @ joint_transform(i, theta)
    return t


def pose6_to_matrix(pose6) -> np.ndarray:
    """[x, y, z, rx, ry, rz] (m, rotation vector) -> (4, 4)."""
    p = np.asarray(pose6, float)
    t = np.eye(4)
    t[:3, :3] = Rotation.from_rotvec(p[3:]).as_matrix()
    t[:3, 3] = p[:3]
    return t


def matrix_to_pose6(t: np.ndarray) -> np.ndarray:
    return np.concatenate((t[:3, 3], Rotation.from_matrix(t[:3, :3]).as_rotvec()))


def solutions(t06: np.ndarray, q6_if_singular: float = 0.0) -> list[np.ndarray]:
    """Every closed-form solution (6,) rad of flange transform t06 (4, 4); [] if unreachable.
    q6_if_singular: the last joint where the wrist is singular (sin(q5) = 0) and q6 is free."""
    a2, a3, d4, d6 = A_M[1], A_M[2], D_M[3], D_M[5]  # (d1 and d5 enter through the joint transforms)
    out: list[np.ndarray] = []
    p05 = t06 @ np.array([0.0, 0.0, -d6, 1.0])
    r = np.hypot(p05[0], p05[1])
    if r < abs(d4):
        return out
    psi, phi = np.arctan2(p05[1], p05[0]), np.arccos(d4 / r)
    t60 = np.linalg.inv(t06)
    for q1 in (psi + phi + np.pi / 2, psi - phi + np.pi / 2):
        s1, c1 = np.sin(q1), np.cos(q1)
        c5 = (t06[0, 3] * s1 - t06[1, 3] * c1 - d4) / d6
        if abs(c5) > 1.0 + 1e-12:
            continue
        for q5 in (np.arccos(np.clip(c5, -1.0, 1.0)), -np.arccos(np.clip(c5, -1.0, 1.0))):
            s5 = np.sin(q5)
            if abs(s5) < 1e-10:
                q6 = q6_if_singular
            else:
                q6 = np.arctan2((-t60[1, 0] * s1 + t60[1, 1] * c1) / s5, (t60[0, 0] * s1 - t60[0, 1] * c1) / s5)
            t14 = (np.linalg.inv(joint_transform(0, q1)) @ t06
                   @ np.linalg.inv(joint_transform(4, q5) @ joint_transform(5, q6)))
            p13 = t14 @ np.array([0.0, -d4, 0.0, 1.0]) - np.array([0.0, 0.0, 0.0, 1.0])
            n13 = float(np.linalg.norm(p13[:3]))
            c3 = (n13**2 - a2**2 - a3**2) / (2.0 * a2 * a3)
            if abs(c3) > 1.0 + 1e-12:
                continue
            for q3 in (np.arccos(np.clip(c3, -1.0, 1.0)), -np.arccos(np.clip(c3, -1.0, 1.0))):
                q2 = -np.arctan2(p13[1], -p13[0]) + np.arcsin(np.clip(a3 * np.sin(q3) / n13, -1.0, 1.0))
                t34 = np.linalg.inv(joint_transform(1, q2) @ joint_transform(2, q3)) @ t14
                q4 = np.arctan2(t34[1, 0], t34[0, 0])
                out.append(np.array([q1, q2, q3, q4, q5, q6]))
    return out


def _nearest_turn(q: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Each angle moved by whole turns to the one nearest `near`."""
    return near + (q - near + np.pi) % (2 * np.pi) - np.pi


def inverse(flange_pose6, q_near, tolerance_m: float = 1e-6) -> np.ndarray:
    """Joint angles (6,) rad putting the flange at flange_pose6, the solution nearest q_near (6,).
    Raises NoSolution where the pose is out of reach."""
    t06 = pose6_to_matrix(flange_pose6)
    near = np.asarray(q_near, float)
    best, best_cost = None, np.inf
    for q in solutions(t06, near[5]):
        q = _nearest_turn(q, near)
        t = forward(q)
        if (np.linalg.norm(t[:3, 3] - t06[:3, 3]) > tolerance_m
                or np.linalg.norm(t[:3, :3] - t06[:3, :3]) > tolerance_m):
            continue  # a branch of the closed form that does not close here (numerical edge)
        cost = float(np.sum((q - near) ** 2))
        if cost < best_cost:
            best, best_cost = q, cost
    if best is None:
        raise NoSolution(f"no joint solution reaches the flange pose {np.round(flange_pose6, 5).tolist()}")
    return best
