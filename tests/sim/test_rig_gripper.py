"""The simulated manipulation rig: Hand-E closure -> preload, arm trajectories -> slip, camera reference."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hardware import build_rig
from hardware.interfaces import DeviceError
from tests.hardware.conftest import app_config


def _grip(g_mm: float, seed: int = 0):
    """Approach until the skin feels the rod, then close a further g_mm; returns (rig, world)."""
    rig = build_rig(app_config(seed=seed), "gripper")
    rig.connect()
    world = rig.extras["world"]
    rig.gripper.move(40.0, 20.0, 0.0)
    rig.clock.sleep(0.5)
    rig.gripper.move(0.0, 20.0, 0.0)
    while world.state.force_n[2] < 0.05:
        rig.clock.sleep(0.002)
    rig.gripper.stop()
    rig.clock.sleep(0.1)
    opening = rig.gripper.read_available()[-1].position_mm
    z_contact = world.scene.indenter_pose()[0][2]
    rig.gripper.move(opening - g_mm, 20.0, 0.0)
    rig.clock.sleep(1.0)
    return rig, world, z_contact


def test_preload_rises_with_grip_depth_through_the_series_compliance():
    k = app_config().sim.rig.gripper.support_stiffness_n_per_mm
    fz = []
    for g in (6.0, 12.0):
        rig, world, z_contact = _grip(g)
        st = world.state
        z = world.scene.indenter_pose()[0][2]
        # Symmetric jaws: the skin finger travels g/2 past contact (to the 8-bit position resolution).
        assert z_contact - z == pytest.approx(g / 2, abs=0.25)
        # Series balance: the support spring carries the grip force, k (commanded - realised indentation).
        assert st.force_n[2] == pytest.approx(k * (-z - st.indentation_mm), rel=0.02)
        assert not world.scene.stalled  # far below the Hand-E's 20 N minimum force
        fz.append(st.force_n[2])
    assert fz[1] > fz[0] > 0.5


# Travels several times the contact's elastic reach (mu F_z over its tangential or torsional
# stiffness), so that stick-slip repeats whatever share of that reach the cover takes.
TRAVEL_MM = 6.0
TWIST_DEG = 32.0


def _run(rig, world, target6, speed, angular=None):
    """Run one arm move; returns the number of slip events (control ticks in which the cumulative
    slip of the cover on the rod grew; a slip itself lasts only milliseconds)."""
    rig.arm.move_linear(target6, speed, 0.5, angular)
    events = 0
    last = (float(np.linalg.norm(world.state.slip_mm)), abs(world.state.slip_rad))
    while rig.arm.is_moving():
        rig.clock.sleep(0.01)
        now = (float(np.linalg.norm(world.state.slip_mm)), abs(world.state.slip_rad))
        events += int(now[0] > last[0] + 1e-6 or now[1] > last[1] + 1e-9)
        last = now
    return events


def test_translation_slips_and_the_camera_sees_the_superficial_layer_move():
    rig, world, _ = _grip(6.0)
    p0 = rig.arm.tcp_pose6()
    rig.camera.read_available()
    s0 = world.state.surface_shift_mm.copy()
    rig.clock.sleep(0.2)
    m0 = {d.marker_id: d.pose.position_m for d in rig.camera.read_available()}
    target = p0.copy()
    target[0] += TRAVEL_MM * 1e-3  # along X0 at 2 mm/s
    onsets = _run(rig, world, target, 0.002)
    assert onsets >= 2  # stick-slip: the contact cannot hold this much shear travel at this preload
    # Deep layer follows the arm; rod moves along skin x by -TRAVEL_MM.
    assert world.scene.indenter_pose()[0][0] == pytest.approx(-TRAVEL_MM, abs=1e-6)
    rig.clock.sleep(0.3)  # let the camera pipeline deliver the frames of the hold
    dets = rig.camera.read_available()
    m1 = {d.marker_id: d.pose.position_m for d in dets[-2:]}
    expected_dx_mm = TRAVEL_MM + world.state.surface_shift_mm[0] - s0[0]  # finger motion + superficial shift
    for mid in m0:
        assert (m1[mid][0] - m0[mid][0]) * 1e3 == pytest.approx(expected_dx_mm, abs=0.1)
    # Camera timing: each detection reaches the host the pipeline latency after its exposure.
    cam = world.streams["camera"].clock
    exposure_host_ns = world.host_start_ns + cam.true_s_of_device([d.device_t_ns for d in dets]) * 1e9
    lat_ms = (np.array([d.host_t_ns for d in dets]) - exposure_host_ns) / 1e6
    cfg = world.rig.camera
    assert np.median(lat_ms) == pytest.approx(cfg.latency_ms, abs=cfg.latency_jitter_ms)
    assert lat_ms.std() > 0.3 * cfg.latency_jitter_ms


def test_torsion_slips_and_rotates_the_rod_in_the_skin_frame():
    """At g = 6 mm the cover sticks until the spacer's torsion reaches mu Fz r (about 6 deg of
    twist here), then slips and sticks again: TWIST_DEG of rotation give several slips."""
    rig, world, _ = _grip(6.0)
    p0 = rig.arm.tcp_pose6()
    yaw0 = world.state.indenter_yaw_rad
    target = p0.copy()
    target[3:] = (Rotation.from_rotvec(p0[3:]) * Rotation.from_rotvec([0.0, np.radians(TWIST_DEG), 0.0])).as_rotvec()
    onsets = _run(rig, world, target, 0.01, np.radians(4.0))
    assert onsets >= 2
    assert abs(world.state.indenter_yaw_rad - yaw0) == pytest.approx(np.radians(TWIST_DEG), abs=1e-6)
    assert np.allclose(world.scene.indenter_pose()[0][:2], 0.0, atol=1e-6)  # turning about the skin normal


def test_arm_and_gripper_refuse_out_of_range_commands():
    rig = build_rig(app_config(), "gripper")
    rig.connect()
    p = rig.arm.tcp_pose6()
    with pytest.raises(DeviceError, match="speed 2.0"):
        rig.arm.move_linear(p, 2.0, 0.5)
    far = p.copy()
    far[0] = 3.0
    with pytest.raises(DeviceError, match="outside the reachable"):
        rig.arm.move_linear(far, 0.01, 0.5)
    with pytest.raises(DeviceError, match="opening 55"):
        rig.gripper.move(55.0, 20.0, 0.0)
    with pytest.raises(DeviceError, match="speed 5"):
        rig.gripper.move(20.0, 5.0, 0.0)
