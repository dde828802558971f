"""The rig under threads: guards and stops from driver threads, one trip, any-thread stop."""

from __future__ import annotations

import threading

import numpy as np

from tests.protocols.fake_rig import platform_rig


def _wrench(fz):
    from layerskin_exp.types import Wrench

    return Wrench(np.array([0.0, 0.0, fz]), np.zeros(3), 0, 0, 0)


def test_concurrent_guard_checks_trip_once_and_stop_motion():
    rig = platform_rig()
    rig.connect()
    stops = []
    real_stop = rig.platform.stop
    rig.platform.stop = lambda: (stops.append(threading.get_ident()), real_stop())
    rig.add_guard(lambda w: f"over {w.force_n[2]}" if w.force_n[2] > 6 else None)
    rig.platform.move_to(np.array([0.0, 0.0, -5.0]), 1.0)
    barrier = threading.Barrier(8)
    reasons = []

    def worker(k):
        barrier.wait()
        for i in range(200):
            r = rig.check_guards(_wrench(5.0 + (i + k) * 0.01))
            if r:
                reasons.append(r)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert rig.tripped is not None and set(reasons) == {rig.tripped}  # one trip, everyone sees it
    assert len(stops) == 1 and not rig.platform.is_moving()


def test_guard_registry_is_safe_to_change_while_checked():
    rig = platform_rig()
    rig.connect()
    stop = threading.Event()

    def checker():
        while not stop.is_set():
            rig.check_guards(_wrench(1.0))

    t = threading.Thread(target=checker)
    t.start()
    try:
        for _ in range(2000):
            g = lambda w: None  # noqa: E731
            rig.add_guard(g)
            rig.remove_guard(g)
    finally:
        stop.set()
        t.join()
    assert rig.tripped is None and rig.guards() == ()


def test_stop_motion_from_any_thread_never_raises():
    rig = platform_rig()
    rig.connect()

    def broken():
        raise OSError("port gone")

    rig.platform.stop = broken
    t = threading.Thread(target=rig.stop_motion)
    t.start()
    t.join()  # no exception escaped the thread
    rig.report_fault("platform: link lost")
    assert rig.fault() == "platform: link lost"
