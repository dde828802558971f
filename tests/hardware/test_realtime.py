"""The world behind the loopback emulators keeps pace with the wall clock."""

import time


def test_realtime_world_keeps_pace(realtime_world):
    rt = realtime_world("platform")
    rt.claim("this test", ("skin", "ft"))  # it drains these streams (the world discards unclaimed ones)
    frames, wrenches = [], []
    t0 = time.monotonic()
    while time.monotonic() - t0 < 0.5:
        time.sleep(0.01)
        with rt.lock:
            frames += rt.rig.skin.read_available()
            wrenches += rt.rig.ft.read_available()
    elapsed = time.monotonic() - t0
    assert rt.error is None
    # 424 frame pairs/s and 1 kHz F/T, to within a pacer period and the last drain
    assert abs(len(frames) - 424 * elapsed) < 0.1 * 424 * elapsed
    assert abs(len(wrenches) - 1000 * elapsed) < 0.1 * 1000 * elapsed
    # records come out in order, received no later than now on the host clock
    now = time.monotonic_ns()
    assert all(rt.to_monotonic_ns(f.host_t_ns) <= now for f in frames)
    assert [f.seq for f in frames] == sorted(f.seq for f in frames)
