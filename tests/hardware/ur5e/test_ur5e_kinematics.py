"""UR5e closed-form inverse kinematics against the forward DH chain (Universal Robots' UR5e table)."""

import numpy as np
import pytest

from hardware.ur5e import kinematics


def test_every_closed_form_solution_puts_the_flange_on_the_pose():
    rng = np.random.default_rng(7)
    for _ in range(200):
        q = rng.uniform(-np.pi, np.pi, 6)
        t = kinematics.forward(q)
        sols = kinematics.solutions(t)
        assert 1 <= len(sols) <= 8
        for s in sols:
            np.testing.assert_allclose(kinematics.forward(s), t, atol=1e-9)
        # the solution nearest a joint vector close to q is q itself (in q's own turn of each joint)
        np.testing.assert_allclose(kinematics.inverse(kinematics.matrix_to_pose6(t), q + 0.02), q, atol=1e-7)


def test_forward_kinematics_matches_the_published_geometry():
    # q = 0: the arm stretched along -x: x = a2 + a3, y = -(d4 + d6), z = d1 - d5 (UR's zero pose)
    t = kinematics.forward(np.zeros(6))
    np.testing.assert_allclose(t[:3, 3], [-0.425 - 0.3922, -0.1333 - 0.0996, 0.1625 - 0.0997], atol=1e-12)


def test_a_pose_out_of_reach_has_no_solution():
    with pytest.raises(kinematics.NoSolution, match="no joint solution"):
        kinematics.inverse([2.0, 0.0, 0.3, 0.0, np.pi, 0.0], np.zeros(6))
