"""Tracking references and LOTO calibration against known synthetic motions."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from analysis.tracking import (
    TrackingTrial,
    loto_calibration,
    torsion_reference_deg,
    translation_reference_mm,
    unwrap_angle,
)


def _profile(n=400, amp=5.0):
    """0 -> +amp -> 0 -> -amp -> 0 triangle."""
    s = np.linspace(0, 4, n)
    return amp * np.interp(s, [0, 1, 2, 3, 4], [0, 1, 0, -1, 0])


def test_translation_reference_projects_oblique_motion_with_positive_first_excursion():
    q = _profile()
    direction = np.array([0.6, -0.8, 0.0])
    pos_m = np.array([0.3, 0.1, 0.2]) + np.outer(q, direction) * 1e-3
    np.testing.assert_allclose(translation_reference_mm(pos_m), q, atol=1e-9)
    np.testing.assert_allclose(translation_reference_mm(pos_m[::-1] * 1 + 0), translation_reference_mm(pos_m[::-1]))


def test_torsion_reference_is_rotation_about_tool_axis():
    ang = _profile(amp=25.0)
    r0 = Rotation.from_euler("xyz", [170, 5, 30], degrees=True)
    axis = np.array([0.0, 0.0, 1.0])  # tool approach axis
    quats = (r0 * Rotation.from_rotvec(np.radians(ang)[:, None] * axis)).as_quat()
    np.testing.assert_allclose(torsion_reference_deg(quats), ang, atol=1e-6)


def test_unwrap_angle_handles_pi_period():
    th = np.linspace(1.2, 2.2, 50)
    wrapped = (th + np.pi / 2) % np.pi - np.pi / 2
    assert np.ptp(wrapped) > 3  # it did wrap
    np.testing.assert_allclose(unwrap_angle(wrapped), th, atol=1e-12)


def test_loto_recovers_scale_offset_and_pools_out_of_fold_metrics():
    rng = np.random.default_rng(0)
    trials = []
    for _ in range(6):
        ref = _profile(200)
        cop_along = ref / 1.25 + 0.3  # skin reads 1/1.25 of the motion
        readout = np.outer(cop_along, [0.0, -1.0]) + rng.normal(0, 0.01, (200, 2))  # along -y
        trials.append(TrackingTrial(readout, ref, np.arange(200) / 85.0))
    res = loto_calibration(trials)
    assert res["a"] == pytest.approx(1.25, rel=0.01)
    assert res["r2"] > 0.999
    assert res["mae"] < 0.03
    assert len(res["predictions"]) == 6


def test_a_skipped_tracking_group_reads_as_english():
    from types import SimpleNamespace

    from analysis.sections.tracking import tracking

    nan = np.full(3, np.nan)
    grip = [SimpleNamespace(motion="translation", grip_depth_mm=6.0, arm_ref=np.zeros(3), vision_ref=nan)]
    skipped = {}
    run = SimpleNamespace(camp=SimpleNamespace(grip=grip), grip_features=lambda: [None], results={}, ts5=None,
                          a=SimpleNamespace(figures=False), skip=lambda key, reason: skipped.__setitem__(key, reason))
    tracking(run)
    assert skipped["tracking.translation.deep.6"] == "1 trial with the arm reference; LOTO needs 2"
    assert skipped["tracking.translation.superficial.6"] == "0 trials with the vision reference; LOTO needs 2"
