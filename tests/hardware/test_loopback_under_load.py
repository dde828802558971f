"""`hardware=loopback` beside a CPU load of twice the core count: trials of healthy devices
complete (the watchdogs judge the devices, not the scheduler), and a device that genuinely goes
silent is still caught. One loaded run each, on the tiny configs."""

from __future__ import annotations

import pytest

from tests.hardware import test_loopback as unloaded
from tests.load import CpuLoad

# The skin board, Net F/T and UR5e emulators run in processes of their own, on their own clocks;
# the GRBL and Hand-E emulators still run in the trial's interpreter and, under this load, are
# not scheduled to answer a poll within the bound (calibration: 'platform stalled: a ? unanswered
# for 94 ms'; grip: 'gripper stalled ... 64 ms'), which a real device never is. Expected to pass
# once they have their own processes too (issue 30, part 2).
IN_PROCESS_EMULATORS = "GRBL and Hand-E emulators still in the trial's interpreter (issue 30: own processes)"


@pytest.mark.xfail(strict=False, reason=IN_PROCESS_EMULATORS)
def test_calibration_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_calibration_on_loopback(tmp_path, hydra_dirs)


# not run in the suite while it is expected to fail: a loaded grip trial costs ~2 min
@pytest.mark.xfail(strict=False, run=False, reason=IN_PROCESS_EMULATORS)
def test_grip_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_grip_on_loopback_with_the_ur_rtde_client(tmp_path, hydra_dirs)


def test_stalled_skin_board_is_caught_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_stalled_stream_on_loopback_stops_safely(tmp_path, hydra_dirs, "force_calibration",
                                                              "skin_board", "skin", 2.5)
