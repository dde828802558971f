"""The emulator base: one fault vocabulary for the six emulators, and no stream queued that no
emulator drains (the structural cause of a standalone emulator's memory growth)."""

from __future__ import annotations

import math
import time

import pytest

from hardware.camera.emulator import CameraEmulator
from hardware.emulation import FAULTS, Emulator
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
