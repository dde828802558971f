"""`hardware=loopback` beside a CPU load of twice the core count: trials of healthy devices
complete (the watchdogs judge the devices, not the scheduler), and a device that genuinely goes
silent is still caught. One loaded run each, on the tiny configs."""

from __future__ import annotations

import pytest

from tests.hardware import test_loopback as unloaded
from tests.load import CpuLoad

# The skin board, Net F/T, GRBL, UR5e and Hand-E emulators run in processes of their own, on their
# own clocks. Under this load the calibration's trials run to the end; the reader used to mark their
# files damaged (host-side records all had sequence 0, so two /tf messages from one GRBL batch at
# an unchanged position were byte-identical); since the writer numbers them per channel (issue 31)
# the loaded calibration passed in the merge's run, but some loaded runs still fail to connect
# (skin board: no valid frame within 2 s), so it stays an expected failure until that is explained.
# Two loaded runs once the Hand-E had its own process (2-core machine shared with other work): the
# calibration aborted both times, once on "skin stalled: no frame for 65 ms (board time ...)",
# once on "platform stalled: no status report for 51 ms (a '?' unanswered)".
LOADED_CONNECT = "some loaded runs fail to connect (skin board: no valid frame within 2 s), not yet explained"
GRIP_UNDER_LOAD = ("the grip trial passed 1 of 2 loaded runs; the other aborted on the skin board's watchdog "
                   "('skin stalled: no frame for 52 ms', skin frames received after the detection), not the gripper's")
GRIPPER_STALL_MARGIN = ("passed 2 of 2 loaded runs (the gripper's own stall caught 54 and 79 ms after its last "
                        "sample, bound 80-82 ms): too thin a margin under load to call it settled")


@pytest.mark.xfail(strict=False, reason=LOADED_CONNECT)
def test_calibration_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_calibration_on_loopback(tmp_path, hydra_dirs)


# Runs again now that the Hand-E emulator has its own process (it used to abort on "gripper stalled":
# its socket threads starved in the trial's interpreter); still expected to fail: see the reason.
@pytest.mark.xfail(strict=False, reason=GRIP_UNDER_LOAD)
def test_grip_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_grip_on_loopback_with_the_ur_rtde_client(tmp_path, hydra_dirs)


# Passed under load before the emulators moved (the stall was caught within the bound); at the
# end of this session's work, on this shared 2-core machine at load 4-7 plus the generator, the
# loaded rig failed to connect (skin board: no valid frame within the 2 s connect timeout, though
# the same bench started under the same load without the CLI streams) or GRBL left a '?'
# unanswered 58 ms before the stall came. Not yet explained: issue 30.
@pytest.mark.xfail(strict=False, reason="the loaded rig's connect is not yet reliable (see the comment)")
def test_stalled_skin_board_is_caught_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_stalled_stream_on_loopback_stops_safely(tmp_path, hydra_dirs, "force_calibration",
                                                              "skin_board", "skin", 2.5)


# The Hand-E's own process answers under the load; a gripper that genuinely goes silent must still
# be caught, by the gripper's watchdog, within the bound (the unloaded case's check).
@pytest.mark.xfail(strict=False, reason=GRIPPER_STALL_MARGIN)
def test_stalled_gripper_is_caught_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_stalled_stream_on_loopback_stops_safely(tmp_path, hydra_dirs, "grip_depth", "hande",
                                                              "gripper", 1.5)
