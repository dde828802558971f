"""`hardware=loopback` beside a CPU load of twice the core count: trials of healthy devices
complete (the watchdogs judge the devices, not the scheduler), and a device that genuinely goes
silent is still caught. One loaded run each, on the tiny configs."""

from __future__ import annotations

import pytest

from tests.hardware import test_loopback as unloaded
from tests.load import CpuLoad

# The emulators still run in the trial's interpreter: under this load they themselves are not
# scheduled for > 50 ms (the board's newest frame is that old even after the driver drained the
# port), which a real device never is. Expected to pass once each emulator has its own process.
IN_PROCESS_EMULATORS = pytest.mark.xfail(
    strict=False, reason="in-process emulators starve under load (issue 30: emulators in their own processes)")



def test_calibration_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_calibration_on_loopback(tmp_path, hydra_dirs)



def test_grip_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_grip_on_loopback_with_the_ur_rtde_client(tmp_path, hydra_dirs)


def test_stalled_skin_board_is_caught_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_stalled_stream_on_loopback_stops_safely(tmp_path, hydra_dirs, "force_calibration",
                                                              "skin_board", "skin", 2.5)
