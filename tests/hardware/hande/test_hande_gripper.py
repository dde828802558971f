"""HandEGripper driver against the URCap socket emulator, backed by the simulated gripper and rod."""

import logging
import os
import socket
import threading
import time

import pytest

from hardware.hande import HandEConfig, HandEGripper, wire
from hardware.hande.emulator import HandEEmulator
from hardware.interfaces import DeviceError
from tests.hardware.waiting import healthy, wait_for

CONTACT_MM = 36.0  # opening at which the skin cover meets the rod (sim.rig.gripper.contact_opening_mm)
COUNT_MM = 50.0 / 255


@pytest.fixture
def bench(realtime_world):
    """(driver, emulator, world). A rigid rod stand (support_stiffness null) lets the jaws reach
    the Hand-E's minimum grip force on the rod, so a closing move stops on it."""
    made = []

    def make(connect=True, cfg_kw=None, **emu_kw):
        rt = realtime_world("gripper", gripper__support_stiffness_n_per_mm=None)
        emu = HandEEmulator(rt, **emu_kw)
        host, port = emu.start().split(":")
        drv = HandEGripper(HandEConfig(host=host, port=int(port), **(cfg_kw or {})))
        made.append((drv, emu))
        if connect:
            drv.connect()
        return drv, emu, rt

    yield make
    for drv, emu in made:
        drv.disconnect()
        emu.stop()


def exchange(sock, request: bytes) -> bytes:
    sock.sendall(request)
    reply = b""
    while not (reply.endswith(b"\n") or reply == b"ack"):
        reply += sock.recv(1024)
    return reply


def test_captured_exchanges_with_the_emulator(bench):
    drv, emu, rt = bench(connect=False, activation_time_s=0.05)
    with socket.create_connection(("127.0.0.1", emu.port), timeout=1.0) as s:
        assert exchange(s, b"GET STA\n") == b"STA 0\n"
        assert exchange(s, b"SET POS 100 GTO 1\n") == b"ack"  # before activation...
        assert exchange(s, b"GET FLT\n") == b"FLT 7\n"  # ...the activation bit must be set first
        assert exchange(s, b"SET ACT 1\n") == b"ack"
        assert exchange(s, b"GET STA\n") == b"STA 1\n"  # activating
        time.sleep(0.06)
        assert exchange(s, b"GET STA\n") == b"STA 3\n"
        assert exchange(s, b"GET FOO\n") == b"?\n"
        assert exchange(s, b"GET POS\n") == b"POS 0\n"  # fully open
        assert exchange(s, b"GET PRE\n") == b"PRE 0\n"


def test_activation_then_move_to_an_opening(bench):
    drv, emu, rt = bench()
    assert emu.regs["ACT"] == 1 and emu.regs["STA"] == wire.STA_ACTIVE
    assert healthy(drv)
    drv.read_available()
    drv.move(40.0, 150.0, 50.0)
    assert drv.is_moving()
    assert wait_for(lambda: not drv.is_moving())
    recs = drv.read_available()
    assert abs(recs[-1].position_mm - 40.0) <= COUNT_MM
    assert abs(recs[-1].requested_mm - 40.0) <= COUNT_MM
    assert not recs[-1].object_detected and recs[-1].fault == 0
    assert recs[-1].speed == 255 and recs[-1].force == 128
    assert any(40.0 + COUNT_MM < r.position_mm < 50.0 - COUNT_MM for r in recs)  # seen on the way
    seqs = [r.seq for r in recs]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
    assert all(r.device_t_ns == r.host_t_ns for r in recs)  # no device clock: host receive time
    assert emu.bad_requests == 0 and drv.health.corrupt == 0


def test_closing_on_the_rod_stops_with_an_object(bench):
    drv, emu, rt = bench()
    drv.move(0.0, 150.0, 0.0)
    assert wait_for(lambda: not drv.is_moving())
    rec = drv.read_available()[-1]
    assert rec.object_detected
    assert rec.requested_mm == 0.0
    assert 12.0 < rec.position_mm < CONTACT_MM  # pressed into the skin, short of the request
    assert drv._snapshot["OBJ"] == wire.OBJ_CLOSING_CONTACT
    drv.move(50.0, 150.0, 0.0)  # release
    assert wait_for(lambda: not drv.is_moving())
    assert not drv.read_available()[-1].object_detected


def test_stop_from_another_thread_halts_the_jaws(bench):
    drv, emu, rt = bench()
    drv.move(40.0, 20.0, 0.0)  # 10 mm at 20 mm/s: half a second
    assert wait_for(lambda: any(r.position_mm < 48.0 for r in drv.read_available()))
    t = threading.Thread(target=drv.stop)
    t.start()
    t.join(1.0)
    assert not t.is_alive()
    assert not drv.is_moving()
    assert emu.regs["GTO"] == 0
    time.sleep(0.1)
    recs = drv.read_available()
    assert recs and all(r.position_mm > 40.0 + 2 * COUNT_MM for r in recs)
    assert max(r.position_mm for r in recs[-3:]) - min(r.position_mm for r in recs[-3:]) == 0.0


def test_bad_moves_are_refused_before_anything_is_sent(bench):
    drv, emu, rt = bench()
    for args in ((60.0, 50.0, 0.0), (20.0, 10.0, 0.0), (20.0, 50.0, 120.0)):
        with pytest.raises(DeviceError, match="gripper"):
            drv.move(*args)
    assert emu.regs["GTO"] == 0 and emu.regs["POS"] == 0 and not drv.is_moving()


def test_device_fault_stall_and_link_loss(bench):
    drv, emu, rt = bench()
    emu.set_fault(0x0E)
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is not None, 1.0)
    assert "0x0E" in drv.fault(time.monotonic_ns()) and "overcurrent" in drv.fault(time.monotonic_ns())
    with pytest.raises(DeviceError, match="0x0E"):
        drv.move(30.0, 100.0, 0.0)
    emu.set_fault(0)
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is None, 1.0)
    emu.stall()
    assert wait_for(lambda: "stalled" in (drv.fault(time.monotonic_ns()) or ""), 1.0)
    emu.resume()
    assert wait_for(lambda: drv.fault(time.monotonic_ns()) is None, 1.0)
    emu.disconnect()
    assert wait_for(lambda: "link lost" in (drv.fault(time.monotonic_ns()) or ""), 2.0)
    with pytest.raises(DeviceError, match="link lost"):
        drv.move(30.0, 100.0, 0.0)


def test_several_clients_at_once_and_an_idle_one_blocks_nobody(realtime_world):
    """The URCap serves a UR program's rq_* socket and a remote client together, on one gripper."""
    rt = realtime_world("gripper")
    with HandEEmulator(rt, start_active=True) as emu:
        idle = [socket.create_connection(("127.0.0.1", emu.port), timeout=2.0) for _ in range(3)]  # connected, silent
        try:
            a = socket.create_connection(("127.0.0.1", emu.port), timeout=2.0)
            b = socket.create_connection(("127.0.0.1", emu.port), timeout=2.0)
            with a, b:
                assert exchange(a, b"SET POS 100\n") == wire.ACK
                assert exchange(b, b"GET POS\n").startswith(b"POS ")  # answered while a stays open
                assert exchange(b, b"SET SPE 200\n") == wire.ACK
                assert exchange(a, b"GET SPE\n") == b"SPE 200\n"  # one gripper: b's write seen by a
                drv = HandEGripper(HandEConfig(host="127.0.0.1", port=emu.port, connect_timeout_s=2.0))
                drv.connect()  # a driver alongside them
                try:
                    assert healthy(drv)
                    assert exchange(a, b"GET STA\n") == b"STA 3\n"
                finally:
                    drv.disconnect()
            assert emu.connections == 6
        finally:
            for s in idle:
                s.close()


def test_connect_and_activation_errors(bench):
    with socket.socket() as s:  # a free port with nothing listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(DeviceError, match=f"127.0.0.1:{port}"):
        HandEGripper(HandEConfig(host="127.0.0.1", port=port, connect_timeout_s=0.5)).connect()
    drv, emu, rt = bench(connect=False, activation_time_s=10.0, cfg_kw={"activation_timeout_s": 0.2})
    with pytest.raises(DeviceError, match="did not activate"):
        drv.connect()
    assert not drv.is_connected


def test_a_poll_thread_not_run_or_a_reply_left_unread_is_no_stall(bench, monkeypatch):
    drv, emu, rt = bench()
    assert healthy(drv)
    bound_ns = int(drv.cfg.stall_timeout_s * 1e9)
    run_poll = threading.Event()
    run_poll.set()
    real_get = drv._get

    def gated(var):  # the poll thread held back between requests, as a thread the scheduler does not run
        run_poll.wait()
        return real_get(var)

    monkeypatch.setattr(drv, "_get", gated)
    run_poll.clear()
    with drv._io_lock:  # no exchange under way: the poll thread waits at the gate from now on
        pass
    assert drv.fault(time.monotonic_ns() + 10 * bound_ns) is None  # nothing asked: nothing unanswered
    with drv._io_lock:  # a request whose reply the host has not read yet
        sent_ns = time.monotonic_ns()
        drv._replies.asked(sent_ns)
        drv._sock.sendall(wire.encode_get("POS"))
        assert wait_for(drv._reply_waiting, 1.0)
        assert drv.fault(sent_ns + 10 * bound_ns) is None  # the gripper answered; the reply sits in the socket
        reply = b""
        while not reply.endswith(b"\n"):
            reply += drv._sock.recv(1024)
        drv._replies.answered(time.monotonic_ns())
    assert reply.startswith(b"POS ")
    # the gripper goes silent: a request unanswered past the bound is reported
    emu.stall()
    run_poll.set()
    assert wait_for(lambda: "gripper stalled" in (drv.fault(time.monotonic_ns()) or ""), 1.0)


def test_the_gripper_answers_while_the_world_is_held_and_logs_into_the_run(bench, caplog):
    """The URCap's socket runs in a process of its own: it answers from the jaws' latest state
    while the world's process holds the world (as a busy host does), and its log lines come here."""
    drv, emu, rt = bench(connect=False, start_active=True)
    assert emu._urcap.proc.pid != os.getpid()
    with socket.create_connection(("127.0.0.1", emu.port), timeout=1.0) as s:
        assert exchange(s, b"GET POS\n") == b"POS 0\n"
        with rt.lock:  # the world held: no pacer, no bridge
            s.settimeout(1.0)
            assert exchange(s, b"GET STA\n") == b"STA 3\n"
            assert exchange(s, b"SET POS 100 GTO 1\n") == wire.ACK
            assert exchange(s, b"GET OBJ\n") == b"OBJ 0\n"  # moving: the move not yet applied to the world
        assert wait_for(lambda: exchange(s, b"GET POS\n") != b"POS 0\n")  # applied once the world runs on
        with caplog.at_level(logging.WARNING, logger="hardware.hande.emulator"):
            assert exchange(s, b"BOGUS\n") == b"?\n"
            assert wait_for(lambda: any("hande (emulated): Hand-E emulator:" in r.getMessage() for r in caplog.records))


def test_the_read_out_is_read_only_and_a_bad_fault_code_is_refused(bench):
    drv, emu, rt = bench(connect=False)
    with pytest.raises(TypeError):
        emu.regs["FLT"] = 0  # a copy of the gripper's registers: set_fault() changes them
    with pytest.raises(ValueError, match="fault code 256 .* use 0..255"):
        emu.set_fault(256)
    emu.set_fault(0x0E)
    assert emu.regs["FLT"] == 0x0E
