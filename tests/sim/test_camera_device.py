"""The simulated camera device: kept images are complete frames; trials start their tracks afresh."""

import numpy as np

from hardware import build_rig
from tests.hardware.conftest import app_config


def test_kept_images_are_complete_frames_holding_what_was_detected():
    rig = build_rig(app_config(seed=3, camera__keep_images=True), "gripper")
    rig.connect()
    rig.clock.sleep(0.3)
    dets = rig.camera.read_available()
    assert dets
    img, device_t_ns, _ = rig.camera.latest_image_stamped()
    cfg = rig.extras["world"].rig.camera
    assert img.shape == (cfg.height_px, cfg.width_px) and img.dtype == np.uint8
    assert img is rig.camera.latest_image()  # composed once
    assert device_t_ns >= dets[-1].device_t_ns
    # The markers are in the frame where they were detected: black borders inside their corners.
    for d in dets[-2:]:
        x0, y0 = np.floor(d.corners_px.min(axis=0)).astype(int)
        x1, y1 = np.ceil(d.corners_px.max(axis=0)).astype(int)
        assert img[y0:y1, x0:x1].min() < 40 and img[y0:y1, x0:x1].max() > 200
    # Far from the markers: the silicone background.
    assert np.all(img[:40, :40] == rig.camera.imager.background_gray)


def test_every_kept_frame_is_handed_out_once_in_order():
    # A consumer that must see each frame (the loopback camera) takes them all, not the newest only.
    rig = build_rig(app_config(seed=3, camera__keep_images=True), "gripper")
    rig.connect()
    rig.camera.take_images()
    rig.clock.sleep(0.3)
    dets = rig.camera.read_available()
    made = rig.camera.take_images()
    dev = np.array([d for _, d, _ in made])
    assert len(made) >= 8 and np.all(np.diff(dev) > 0)
    period_ns = 1e9 / rig.extras["world"].rig.camera.fps
    assert np.all(np.round(np.diff(dev) / period_ns) == 1)  # no frame left out
    assert {d.device_t_ns for d in dets} <= set(dev.tolist())  # every detected frame among them
    assert made[-1][1] == rig.camera.latest_image_stamped()[1]
    assert rig.camera.take_images() == []  # handed out once
    assert rig.camera.images_overrun == 0


def test_images_are_not_kept_by_default():
    rig = build_rig(app_config(seed=3), "gripper")
    rig.connect()
    rig.clock.sleep(0.2)
    assert rig.camera.read_available()
    assert rig.camera.latest_image() is None


def test_each_trial_starts_with_a_full_frame_search():
    rig = build_rig(app_config(seed=3), "gripper")
    rig.connect()
    world, tracker = rig.extras["world"], rig.camera.imager.tracker
    rig.clock.sleep(0.5)
    assert len(rig.camera.read_available()) >= 2 * 10  # both markers, every frame
    assert tracker.full_searches == 1  # then tracked
    world.begin_trial({"trial": 1})
    rig.clock.sleep(0.2)
    assert rig.camera.read_available()
    assert tracker.full_searches == 2  # the new trial acquired the markers afresh, then tracked them


def test_detection_quaternions_are_the_rotation_vectors():
    """quat_xyzw against scipy's conversion: random rotations, tiny angles (series branch) and
    the half turn a marker facing the camera sits near."""
    from scipy.spatial.transform import Rotation

    from hardware.sim.camera import quat_xyzw

    rng = np.random.default_rng(0)
    rvecs = np.concatenate([Rotation.random(50, rng=rng).as_rotvec(), rng.normal(0.0, 1e-6, (10, 3)),
                            [[np.pi, 0.0, 0.0], [0.0, 0.0, 0.0], [3.1, 0.05, -0.02]]])
    for rv in rvecs:
        q = quat_xyzw(rv)
        assert np.allclose(q, Rotation.from_rotvec(rv).as_quat(), atol=1e-15, rtol=0.0)
        assert q[3] >= 0 and abs(np.linalg.norm(q) - 1.0) < 1e-15
