"""GrblPlatform driver against the GRBL emulator, backed by the simulated stage: every case on
both serial links, a pty (a port path) and loopback TCP (a socket:// URL, as the loopback bench
serves GRBL)."""

import os
import socket
import threading
import time

import numpy as np
import pytest

from hardware.interfaces import DeviceError
from hardware.platform import GrblPlatform, GrblPlatformConfig, wire
from hardware.platform.emulator import GrblEmulator
from tests.hardware.waiting import healthy, wait_for

HOME = np.array([0.0, 0.0, 5.0])  # the simulated stage's home (sim.rig.platform.home_mm)


@pytest.fixture(params=["pty", "tcp"])
def bench(realtime_world, request):
    """(driver, emulator, world); the driver connected. Keyword args go to the emulator."""
    made = []

    def make(connect=True, cfg_kw=None, **emu_kw):
        rt = realtime_world("platform")
        emu = GrblEmulator(rt, link=request.param, **emu_kw)
        path = emu.start()
        assert path.startswith("socket://127.0.0.1:") == (request.param == "tcp")
        drv = GrblPlatform(GrblPlatformConfig(port=path, connect_timeout_s=2.0, **(cfg_kw or {})))
        made.append((drv, emu))
        if connect:
            drv.connect()
        return drv, emu, rt

    yield make
    for drv, emu in made:
        drv.disconnect()
        emu.stop()


def positions(recs):
    return np.array([r.position_mm for r in recs])


def test_move_reaches_target_and_position_stream_follows(bench):
    drv, emu, rt = bench()
    first = drv.read_available()
    assert first and np.allclose(first[-1].position_mm, HOME)
    target = np.array([1.0, -0.5, 6.0])
    drv.move_to(target, 20.0)
    assert drv.is_moving()  # at once, before any status shows Run
    assert wait_for(lambda: not drv.is_moving())
    recs = drv.read_available()
    pos = positions(recs)
    assert np.allclose(pos[-1], target, atol=0.002)
    with rt.lock:
        assert np.allclose(rt.rig.platform.position_mm(), target, atol=0.002)
    # the stream follows the straight line: intermediate samples between start and target
    x = pos[:, 0]
    inner = (x > 0.05) & (x < 0.95)
    assert inner.sum() >= 3
    assert np.all(np.diff(x) >= -1e-9)
    assert np.allclose(pos[inner, 1], -0.5 * pos[inner, 0], atol=0.01)
    seqs = [r.seq for r in recs]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert all(r.device_t_ns == r.host_t_ns for r in recs)  # GRBL has no clock: host receive time
    assert all(b.host_t_ns >= a.host_t_ns for a, b in zip(recs, recs[1:], strict=False))
    assert healthy(drv)
    assert emu.rx_overflow_bytes == 0 and drv.health.corrupt == 0


def test_stop_mid_move_holds_then_resets_without_alarm(bench):
    drv, emu, rt = bench()
    resets = emu.resets
    drv.move_to(np.array([0.0, 0.0, 25.0]), 20.0)  # 20 mm: about a second
    assert wait_for(lambda: any(r.position_mm[2] > 6.0 for r in drv.read_available()))
    drv.stop()
    assert drv.is_moving()
    assert wait_for(lambda: not drv.is_moving())
    assert emu.resets == resets + 1 and emu.state == "Idle"  # reset from Hold:0: no ALARM:3
    with rt.lock:
        z_stop = rt.rig.platform.position_mm()[2]
    assert 6.0 < z_stop < 20.0
    time.sleep(0.1)  # the planner was flushed: nothing resumes
    with rt.lock:
        assert abs(rt.rig.platform.position_mm()[2] - z_stop) < 1e-9
    assert healthy(drv)
    drv.move_to(HOME, 20.0)  # the machine takes moves again
    assert wait_for(lambda: not drv.is_moving())
    assert np.allclose(drv.read_available()[-1].position_mm, HOME, atol=0.002)


def test_stop_from_another_thread_while_idle_leaves_no_alarm(bench):
    drv, emu, rt = bench()
    t = threading.Thread(target=drv.stop)
    t.start()
    t.join(1.0)
    assert not t.is_alive()
    assert wait_for(lambda: not drv.is_moving())
    assert emu.state == "Idle" and healthy(drv)


def test_move_beyond_soft_limits_raises_a_clear_alarm(bench):
    drv, emu, rt = bench()
    drv.move_to(np.array([0.0, 0.0, 40.0]), 20.0)  # z travel ends at 30 mm
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is not None)
    reason = drv.fault(time.monotonic_ns())
    assert "ALARM:2" in reason and "soft limit" in reason
    assert not drv.is_moving()
    with pytest.raises(DeviceError, match="ALARM:2"):
        drv.move_to(HOME, 10.0)
    with rt.lock:
        assert np.allclose(rt.rig.platform.position_mm(), HOME)  # nothing moved
    drv.recover(unlock=True)
    assert healthy(drv)
    drv.move_to(np.array([0.0, 0.0, 5.5]), 20.0)
    assert wait_for(lambda: not drv.is_moving())
    assert np.allclose(drv.read_available()[-1].position_mm, [0.0, 0.0, 5.5], atol=0.002)


def test_error_response_becomes_a_fault_naming_the_code(bench):
    drv, emu, rt = bench()
    drv._send_line(wire.encode_line("G1X1"), move_id=99)  # no feed rate in a fresh parser: error:22
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is not None)
    assert "error:22" in drv.fault(time.monotonic_ns()) and "feed rate" in drv.fault(time.monotonic_ns())


def test_alarm_at_power_up_needs_permission_to_unlock(bench):
    drv, emu, rt = bench(connect=False, start_in_alarm=True)
    with pytest.raises(DeviceError, match="alarm"):
        drv.connect()
    drv2 = GrblPlatform(GrblPlatformConfig(port=emu.path, unlock_alarm=True))
    drv2.connect()
    try:
        assert emu.state == "Idle"
        assert healthy(drv2)
    finally:
        drv2.disconnect()


def test_character_counting_never_overflows_the_receive_buffer(bench):
    # a 1-block planner makes GRBL hold lines in its receive buffer while it moves
    drv, emu, rt = bench(planner_blocks=1)
    targets = [np.array([0.0, 0.0, 5.0 + 0.1 * k]) for k in range(1, 11)]
    peak = 0
    for t in targets:
        drv.move_to(t, 20.0)
        peak = max(peak, drv.in_flight_bytes)
    assert peak > 64  # several lines were in flight at once...
    assert peak <= 128  # ...never more than the buffer
    drv.wait_acknowledged(timeout_s=3.0)
    assert wait_for(lambda: not drv.is_moving())
    assert emu.rx_overflow_bytes == 0
    assert np.allclose(drv.read_available()[-1].position_mm, targets[-1], atol=0.002)
    # the same lines written without counting overflow GRBL's buffer
    emu.stall()
    raw = b"".join(wire.encode_move(t, 1200.0) for t in targets)
    drv._write(raw)  # the port's raw write, past the counter
    emu.resume()
    assert wait_for(lambda: emu.rx_overflow_bytes > 0)


def test_stall_and_link_loss_become_faults(bench):
    drv, emu, rt = bench()
    assert healthy(drv)
    emu.stall()
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is not None, 1.0)
    assert "stalled" in drv.fault(time.monotonic_ns())
    emu.resume()
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is None, 1.0)
    emu.disconnect()
    assert wait_for(lambda: "link lost" in (drv.fault(time.monotonic_ns()) or ""), 1.0)
    with pytest.raises(DeviceError, match="link lost"):
        drv.move_to(HOME, 10.0)


def test_noise_is_counted_and_the_stream_goes_on(bench):
    drv, emu, rt = bench()
    emu.corrupt(1, "noise")  # line noise before the next message
    emu.corrupt(1, "garbled")  # a byte of the one after changed
    assert wait_for(lambda: drv.health.corrupt >= 2)
    drv.read_available()
    assert wait_for(lambda: len(drv.read_available()) > 0)
    assert healthy(drv)


def test_connect_errors_name_the_port(tmp_path):
    with pytest.raises(DeviceError, match="nonexistent"):
        GrblPlatform(GrblPlatformConfig(port=str(tmp_path / "nonexistent"))).connect()
    with socket.socket() as unused:  # a serial device server that is not there
        unused.bind(("127.0.0.1", 0))
        url = f"socket://127.0.0.1:{unused.getsockname()[1]}"
    with pytest.raises(DeviceError, match=f"cannot open the GRBL serial port '{url}'"):
        GrblPlatform(GrblPlatformConfig(port=url)).connect()
    master, slave = os.openpty()  # a port where nothing answers
    try:
        drv = GrblPlatform(GrblPlatformConfig(port=os.ttyname(slave), connect_timeout_s=0.2))
        with pytest.raises(DeviceError, match="no GRBL welcome banner"):
            drv.connect()
        assert not drv.is_connected
    finally:
        os.close(master)
        os.close(slave)


def test_status_reports_held_in_the_os_or_a_poller_not_run_are_no_stall(bench, monkeypatch):
    drv, emu, rt = bench()
    assert healthy(drv)
    bound_ns = drv.cfg.stall_timeout_s * 1e9
    run_rx = threading.Event()
    run_rx.set()
    real = drv._wait_readable

    def gated(ser):  # the reader held back before it waits for bytes, as a thread the scheduler does not run
        run_rx.wait()
        return real(ser)

    monkeypatch.setattr(drv, "_wait_readable", gated)
    run_rx.clear()
    time.sleep(0.02)  # a select already under way returns
    drv.read_available()
    t0 = time.monotonic_ns()
    while time.monotonic_ns() - t0 <= 1.5 * bound_ns:  # GRBL answers the poller's '?' on, into the OS buffer
        time.sleep(0.005)
    assert drv.fault(time.monotonic_ns()) is None  # what sat unread was drained: GRBL answered
    assert len(drv.read_available()) >= 3
    run_rx.set()
    # a poller the host does not run asks nothing: no query unanswered is no stall, however late
    asked = drv._replies.asked
    monkeypatch.setattr(drv._replies, "asked", lambda *args: None)
    time.sleep(0.02)
    assert drv.fault(time.monotonic_ns() + int(10 * bound_ns)) is None
    monkeypatch.setattr(drv._replies, "asked", asked)
    # GRBL goes silent: a '?' unanswered past the bound is reported
    emu.stall()
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is not None, 1.0)
    assert drv.fault(time.monotonic_ns()).startswith("platform stalled: no status report for")
