"""Repeated trials are distinct realisations of the same bench; a trial replays from its labels."""

import math

import numpy as np
import pytest

from hardware import build_rig
from tests.hardware.conftest import app_config


def _frames(rig, labels, seconds=0.3):
    """Skin frames (superficial, deep stacked) of `seconds` at rest after begin_trial(labels)."""
    rig.begin_trial(labels)
    rig.skin.read_available()
    rig.clock.sleep(seconds)
    frames = rig.skin.read_available()
    return np.stack([np.stack([f.superficial, f.deep]) for f in frames]).astype(np.int32)


def _connected(setup="gripper", **rig_overrides):
    rig = build_rig(app_config(**rig_overrides), setup)
    rig.connect()
    return rig


def test_same_labels_replay_identically_and_other_labels_draw_new_noise():
    a = _frames(_connected(), {"trial": 0, "grip_depth_mm": 6.0})
    b = _frames(_connected(), {"trial": 0, "grip_depth_mm": 6.0})
    c = _frames(_connected(), {"trial": 1, "grip_depth_mm": 6.0})
    n = min(len(a), len(b), len(c))
    assert np.array_equal(a[:n], b[:n])
    assert not np.array_equal(a[:n], c[:n])
    # Only the noise differs: the sheet (gains, baselines) is the same, so the mean at rest agrees
    # to within the readout noise averaged over the frames.
    noise = app_config().sim.readout.noise_counts
    assert np.abs(a[:n].mean(axis=0) - c[:n].mean(axis=0)).max() < 6 * noise / math.sqrt(n) + 1


def test_the_sensor_itself_does_not_change_between_trials():
    rig = _connected()
    model = rig.extras["world"].skin_model
    gains = [layer.gain.copy() for layer in model.fsr]
    baseline = model.baseline_counts.copy()
    rig.begin_trial({"trial": 3})
    assert all(np.array_equal(g, layer.gain) for g, layer in zip(gains, model.fsr, strict=True))
    assert np.array_equal(baseline, model.baseline_counts)


def test_rod_placement_and_friction_are_drawn_per_trial_from_the_configured_spread():
    rig = _connected()
    world = rig.extras["world"]
    var = world.rig.variation
    mu0 = world.skin_model.friction.mu_s_nominal
    xs, yaws, mus = [], [], []
    for k in range(200):
        rig.begin_trial({"trial": k})
        (x, _, _), yaw = world.scene.indenter_pose()
        xs.append(x)
        yaws.append(math.degrees(yaw) - 90.0)  # the rod lies along skin y at the nominal placement
        mus.append(world.skin_model.friction.mu_s / mu0)
        ratio = world.skin_model.friction.mu_k / world.skin_model.friction.mu_s
        assert ratio == pytest.approx(world.skin_model.friction.mu_k_nominal / mu0)
    # 200 draws: sample sd within ~25 % of the configured one, means near zero / one.
    assert np.std(xs) == pytest.approx(var.rod_offset_sd_mm, rel=0.25)
    assert np.std(yaws) == pytest.approx(var.rod_yaw_sd_deg, rel=0.25)
    assert np.std(mus) == pytest.approx(var.friction_cv, rel=0.25)
    assert abs(np.mean(mus) - 1.0) < 0.02


def test_zero_variation_keeps_the_nominal_bench():
    rig = _connected(variation__friction_cv=0.0, variation__rod_offset_sd_mm=0.0, variation__rod_yaw_sd_deg=0.0)
    world = rig.extras["world"]
    before = world.scene.indenter_pose()
    rig.begin_trial({"trial": 5})
    (x, y, z), yaw = world.scene.indenter_pose()
    assert (x, y, z) == pytest.approx(before[0], abs=1e-12)
    assert yaw == pytest.approx(before[1], abs=1e-12)
    assert world.skin_model.friction.mu_s == world.skin_model.friction.mu_s_nominal


def test_a_turned_rod_lies_across_the_skin_at_that_angle():
    rig = _connected()
    scene = rig.extras["world"].scene
    scene.place_rod(1.0, 5.0)
    (x, _, _), yaw = scene.indenter_pose()
    # Axis point nearest the skin origin: the 1 mm offset, seen perpendicular to the turned axis.
    assert x == pytest.approx(1.0 * math.cos(math.radians(5.0)) ** 2, abs=1e-9)
    # Turning the axis (TCP z) about the skin normal (TCP y) by +5 deg tilts it toward +x_s, away
    # from -y_s: measured from skin x on the branch through +90 deg, that is 95 deg.
    assert math.degrees(yaw) == pytest.approx(95.0, abs=1e-9)
