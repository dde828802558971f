"""`hardware=loopback` beside a CPU load of twice the core count: trials of healthy devices
complete (the watchdogs judge the devices, not the scheduler), and a device that genuinely goes
silent is still caught. One loaded run each, on the tiny configs."""

from __future__ import annotations

import pytest

from tests.hardware import test_loopback as unloaded
from tests.load import CpuLoad

# slow: the loaded soak, four whole loopback trials each beside 2 x cores busy processes (~25 s each
# on 2 cores, and starving whatever else runs then); make test runs the same trials unloaded.
pytestmark = pytest.mark.slow

# Measured on a 2-core machine (issue 30; figures in the closing note of the 2026-11-27 seventh
# session), with GRBL's line on loopback TCP (hardware.emulation.TcpSerialLink): calibration 10 of
# 10 and grip 10 of 10 loaded runs passed, a stalled gripper 5 of 5 and a stalled skin board 5 of 5
# were caught within the bound. Before, with GRBL on a pty, 1 of 10 loaded calibrations aborted on
# a '?' the kernel's pty worker delivered late ("platform stalled"), which is why these were
# expected failures.


def test_calibration_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_calibration_on_loopback(tmp_path, hydra_dirs)


# The Hand-E emulator has its own process (in the trial's interpreter its socket threads starved and
# the trial aborted on "gripper stalled").
def test_grip_on_loopback_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_grip_on_loopback_with_the_ur_rtde_client(tmp_path, hydra_dirs)


# The stall is timed from the board's power-on. At the unloaded case's 2.5 s, 3 of 3 loaded runs
# (2026-11-27) stalled the board before the driver connected (the bench took 3 s to start) and
# recorded no trial; 6 s lands inside the calibration's two trials whether loaded or not.
LOADED_SKIN_STALL_S = 6.0


def test_stalled_skin_board_is_caught_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_stalled_stream_on_loopback_stops_safely(tmp_path, hydra_dirs, "force_calibration",
                                                              "skin_board", "skin", LOADED_SKIN_STALL_S)


# The Hand-E's own process answers under the load; a gripper that genuinely goes silent must still
# be caught, by the gripper's watchdog, within the bound (the unloaded case's check).
def test_stalled_gripper_is_caught_under_load(tmp_path, hydra_dirs):
    with CpuLoad() as load:
        assert load.running == load.n
        unloaded.test_stalled_stream_on_loopback_stops_safely(tmp_path, hydra_dirs, "grip_depth", "hande",
                                                              "gripper", 1.5)
