"""The simulated force-calibration rig: platform kinematics, F/T statistics, guards, clocks, determinism."""

import numpy as np
import pytest

from hardware import build_rig
from hardware.interfaces import DeviceError, DeviceNotConnectedError

SPEED = 4.0  # mm/s


@pytest.fixture
def rig(make_cfg):
    r = build_rig(make_cfg(seed=3), "platform")
    r.connect()
    yield r
    r.disconnect()


def test_platform_move_respects_speed_and_accel_limits_and_arrives(rig):
    world = rig.extras["world"]
    a_max = world.rig.platform.max_accel_mm_s2
    start = np.asarray(rig.platform.position_mm())
    target = start + np.array([6.0, -3.0, 0.0])
    rig.platform.move_to(target, SPEED)
    dt = world.mech_dt_s
    pos = [start]
    for _ in range(3000):
        rig.clock.sleep(dt)
        pos.append(rig.platform.position_mm())
        if not rig.platform.is_moving():
            break
    pos = np.asarray(pos)
    v = np.diff(pos, axis=0) / dt
    speed = np.linalg.norm(v, axis=1)
    acc = np.linalg.norm(np.diff(v, axis=0), axis=1) / dt
    assert speed.max() <= SPEED * (1 + 1e-9)
    assert speed.max() > 0.99 * SPEED  # it does reach cruise speed
    assert acc.max() <= a_max * 1.001
    np.testing.assert_allclose(pos[-1], target, atol=1e-9)
    # Trapezoid from rest to rest: T = d / v + v / a (closed form), within two steps.
    d = np.linalg.norm(target - start)
    assert abs((len(pos) - 1) * dt - (d / SPEED + SPEED / a_max)) <= 2 * dt
    # The position stream reports the same motion.
    stream = np.array([s.position_mm for s in rig.platform.read_available()])
    assert np.abs(np.diff(stream, axis=0)).max() < SPEED / world.rig.platform.rate_hz * 1.5 + 1e-3


def test_commands_outside_the_devices_range_raise_with_the_value(rig):
    with pytest.raises(DeviceError, match="99"):
        rig.platform.move_to(np.array([99.0, 0.0, 1.0]), 1.0)
    with pytest.raises(DeviceError, match="500"):
        rig.platform.move_to(np.array([0.0, 0.0, 1.0]), 500.0)
    rig.platform.disconnect()
    with pytest.raises(DeviceNotConnectedError):
        rig.platform.move_to(np.array([0.0, 0.0, 1.0]), 1.0)


def test_ft_noise_and_bias_statistics_then_tare(rig):
    cfg = rig.extras["world"].rig.ft
    rig.clock.sleep(2.0)  # unloaded: indenter at home, above the skin
    w = rig.ft.read_available()
    f = np.array([s.force_n for s in w])
    assert len(w) == pytest.approx(2.0 * cfg.rate_hz, rel=0.01)
    np.testing.assert_allclose(f.std(axis=0), cfg.force_noise_n, rtol=0.1)
    bias = f.mean(axis=0)
    assert np.all(np.abs(bias) <= cfg.bias_force_max_n + 0.01)
    assert np.linalg.norm(bias) > 5 * max(cfg.force_noise_n)  # an untared sensor reads a real offset
    rig.ft.tare()
    rig.clock.sleep(1.0)
    f = np.array([s.force_n for s in rig.ft.read_available()])
    # After tare: zero within the tare's own noise (mean of 32 samples) and the slow drift.
    assert np.all(np.abs(f.mean(axis=0)) < 4 * np.asarray(cfg.force_noise_n) / np.sqrt(32) + 0.005)


def test_guard_trips_at_the_sample_and_motion_stops(rig):
    limit = 1.0
    rig.add_guard(lambda w: f"Fz {w.force_n[2]:.3f}" if w.force_n[2] > limit else None)
    rig.ft.tare()
    world = rig.extras["world"]
    p = rig.platform.position_mm()
    rig.platform.move_to(np.array([p[0], p[1], -2.5]), SPEED)
    for _ in range(500):
        rig.clock.sleep(0.05)  # a coarse control loop: the guard must not wait for it
        if rig.tripped:
            break
    assert rig.tripped
    samples = rig.ft.read_available()
    fz = np.array([s.force_n[2] for s in samples])
    k = int(np.argmax(fz > limit))
    assert k > 0 and np.all(fz[:k] <= limit)  # the first sample over the limit tripped it
    rig.clock.sleep(0.5)
    stage = rig.platform.read_available()
    z = np.array([s.position_mm[2] for s in stage])
    assert not rig.platform.is_moving()
    # It stopped within the braking distance (plus one step) of where the trip happened,
    # long before the 50 ms control tick would have noticed.
    a = world.rig.platform.max_accel_mm_s2
    stop_travel = SPEED**2 / (2 * a) + SPEED * world.mech_dt_s * 2
    host_trip = samples[k].host_t_ns
    z_at_trip = z[np.searchsorted([s.host_t_ns for s in stage], host_trip) - 1]
    assert z_at_trip - z[-1] <= stop_travel + 0.02  # + one stage period at speed (stream lag)
    assert z[-1] > -2.4  # far short of the commanded depth


def test_every_device_has_its_own_clock_offset_drift_and_jitter(rig):
    world = rig.extras["world"]
    rig.clock.sleep(20.0)  # long enough that the random transport delay averages out of the slope
    clocks = {n: s.clock for n, s in world.streams.items()}
    offsets = [c.offset_ns for c in clocks.values()]
    drifts = [c.drift for c in clocks.values()]
    assert len(set(offsets)) == len(offsets) and len(set(drifts)) == len(drifts)
    assert all(1e-7 < abs(d) < 3e-4 for d in drifts)  # tens of ppm
    frames = rig.skin.read_available()
    dev = np.array([f.device_t_ns for f in frames], dtype=float)
    host = np.array([f.host_t_ns for f in frames], dtype=float)
    # Device clock rate: slope of device vs host time is 1 + drift (host delays are small and bounded).
    slope = np.polyfit(host - host[0], dev - dev[0], 1)[0]
    assert slope - 1 == pytest.approx(clocks["skin"].drift, abs=5e-6)
    d = np.diff(dev) / 1e6
    assert d.mean() == pytest.approx(2.36, rel=0.01)
    assert d.std() > 0.02  # scan-period jitter is there
    # Host receive time is never earlier than the device sent it (one-sided delay), and FIFO.
    assert np.all(np.diff(host) >= 0)
    seq = [f.seq for f in frames]
    assert seq == list(range(seq[0], seq[0] + len(seq))) and rig.skin.health.lost == 0


def _record(make_cfg, seed):
    r = build_rig(make_cfg(seed=seed), "platform")
    r.connect()
    r.platform.move_to(np.array([1.0, 2.0, -1.0]), SPEED)
    r.clock.sleep(2.0)
    fr = r.skin.read_available()
    return (np.stack([f.superficial for f in fr]), np.array([f.device_t_ns for f in fr]),
            np.stack([w.force_n for w in r.ft.read_available()]))


def test_same_seed_gives_identical_streams_and_another_seed_does_not(make_cfg):
    a, b, c = _record(make_cfg, 5), _record(make_cfg, 5), _record(make_cfg, 6)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert a[2].shape != c[2].shape or not np.array_equal(a[2], c[2])
    assert not np.array_equal(a[1][:10], c[1][:10])
    assert a[0].max() > 150  # the press was seen by the skin (unloaded taxels read ~12 counts)
