"""The emulator base: one fault vocabulary for the six emulators, and no stream queued that no
emulator drains (the structural cause of a standalone emulator's memory growth); the serial line
over loopback TCP."""

from __future__ import annotations

import math
import socket
import time

import pytest

from hardware.camera.emulator import CameraEmulator
from hardware.emulation import FAULTS, Emulator, serial_link
from hardware.hande.emulator import HandEEmulator
from hardware.loopback import EMULATORS, emulator_class
from hardware.netft.emulator import NetFTEmulator
from hardware.platform.emulator import GrblEmulator
from hardware.skin_board.emulator import SkinBoardEmulator
from hardware.ur5e.emulator import UR5eEmulator
from tests.hardware.waiting import wait_for


def test_every_emulator_speaks_the_one_fault_vocabulary():
    for device in EMULATORS:
        cls = emulator_class(device)
        assert issubclass(cls, Emulator), device
        assert set(cls.FAULTS) <= set(FAULTS) and "stall" in cls.FAULTS and "disconnect" in cls.FAULTS, device
        for old in ("freeze", "unfreeze", "hang_up", "unplug", "inject", "inject_fault", "drop_connection",
                    "end_capture"):
            assert not hasattr(cls, old), f"{device}: {old}"
    assert {c: set(c.FAULTS) for c in (SkinBoardEmulator, GrblEmulator, NetFTEmulator, HandEEmulator,
                                       CameraEmulator)} == {c: set(FAULTS) for c in (
        SkinBoardEmulator, GrblEmulator, NetFTEmulator, HandEEmulator, CameraEmulator)}


def test_a_fault_a_device_cannot_show_and_bad_schedules_are_refused():
    ur = UR5eEmulator(object())  # the controller process starts only with start()
    with pytest.raises(ValueError, match=r"ur5e emulator: fault 'drop' is not modelled; this device shows \('stall', 'disconnect'\)"):
        ur.drop(1)
    skin = SkinBoardEmulator(object())
    with pytest.raises(ValueError, match="corruption 'melted'"):
        skin.corrupt(1, "melted")
    with pytest.raises(ValueError, match="schedule entry 'explode'"):
        skin.schedule("explode")
    for bad in (math.nan, -1.0, math.inf):
        with pytest.raises(ValueError, match="stall_after_s"):
            SkinBoardEmulator(object(), stall_after_s=bad)
    skin.schedule(None, "drop", ("corrupt", "drop_byte"))
    assert [skin._next_fault() for _ in range(4)] == [None, ("drop", None), ("corrupt", "drop_byte"), None]
    assert skin.fault_counts == {"drop": 1, "corrupt": 1}
    skin.stall(None)
    assert skin.stalled
    skin.resume()
    assert not skin.stalled


def test_faults_on_a_timer_from_start(realtime_world):
    rt = realtime_world("platform")
    with SkinBoardEmulator(rt, stall_after_s=0.0, disconnect_after_s=0.2) as emu:
        assert wait_for(lambda: emu.stalled)
        assert wait_for(lambda: emu.unplugged)
        assert emu.fault_counts == {"stall": 1, "disconnect": 1}


def _queued(twin) -> int:
    return len(twin.stream._queue)


def test_streams_no_emulator_serves_are_not_queued(realtime_world):
    """The standalone platform emulator serves the stage; the skin and F/T twins of the same world
    stream on. Nothing may keep their records (before, they queued for as long as it ran)."""
    rt = realtime_world("platform")
    with GrblEmulator(rt):
        time.sleep(1.0)
        with rt.lock:
            queued = {name: _queued(getattr(rt.rig, name)) for name in ("skin", "ft", "platform")}
    # what is in flight (sampled, not yet received by the host) stays: a few ms of each stream
    assert all(n <= 20 for n in queued.values()), queued
    with SkinBoardEmulator(rt) as emu:  # a served stream goes to its emulator, not to the bin
        assert wait_for(lambda: emu.counts["no_host_frames"] > 50)
    assert rt._claims == {}  # released at stop


def _read_until(sock, n: int, timeout_s: float = 5.0) -> bytes:
    sock.settimeout(timeout_s)
    got = b""
    while len(got) < n:
        chunk = sock.recv(n - len(got))
        if not chunk:
            break
        got += chunk
    return got


def _link_read(link, n: int, timeout_s: float = 5.0) -> bytes:
    got, deadline = b"", time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        got += link.read(0.05)
    return got


def test_a_serial_line_over_tcp_holds_carries_and_hands_over():
    link = serial_link("tcp", hold=True)
    try:
        host, port = link.path.removeprefix("socket://").rsplit(":", 1)
        assert host == "127.0.0.1" and not link.host_attached()
        banner = b"Grbl 1.1h ['$' for help]\r\n"
        assert link.write(banner) == len(banner)  # no host yet: held for the next one
        first = socket.create_connection((host, int(port)))
        link.read(0.05)  # the device's loop polls its line: the host is taken on
        assert _read_until(first, len(banner)) == banner
        first.sendall(b"?")
        assert _link_read(link, 1) == b"?"
        assert link.host_attached()
        second = socket.create_connection((host, int(port)))  # a second host takes the line over
        assert link.read(0.05) == b"" and link.host_attached()
        assert link.write(b"ok\r\n") == 4
        assert _read_until(second, 4) == b"ok\r\n"
        assert _read_until(first, 1, 1.0) == b""  # the first was let go
        second.close()
        assert _link_read(link, 1, 0.5) == b"" and not link.host_attached()
        third = socket.create_connection((host, int(port)))
        link.read(0.05)
        link.close()
        assert link.closed and link.write(b"x") == 0 and link.read(0.01) == b""
        assert _read_until(third, 1, 1.0) == b""  # closing is the line going away
        first.close()
        third.close()
    finally:
        link.close()


def test_an_unheld_tcp_line_drops_what_no_host_reads_and_bad_kinds_are_refused():
    link = serial_link("tcp")
    try:
        assert link.write(b"frame") == 0
    finally:
        link.close()
    with pytest.raises(ValueError, match="'usb'.*'pty'.*'tcp'"):
        serial_link("usb")
