"""Hard ceilings no config can raise, lower bounds that make sense for a 424 Hz rig, and paths
checked before anything connects (all refused at validation, naming the key)."""

from __future__ import annotations

import os

import pytest

from layerskin_exp.config import ConfigError
from tests.protocols.conftest import compose_app


@pytest.mark.parametrize("app, overrides, key", [
    ("grip_depth", ["safety.max_grip_depth_mm=1000", "grip_depth=500"], "safety.max_grip_depth_mm"),
    ("grip_depth", ["grip_depth=45"], "grip_depth"),  # beyond what the jaws can close from 40 mm
    ("grip_depth", ["safety.max_arm_speed_mm_s=1000"], "safety.max_arm_speed_mm_s"),
    ("grip_depth", ["safety.max_gripper_speed_mm_s=500"], "safety.max_gripper_speed_mm_s"),
    ("force_calibration", ["safety.max_platform_speed_mm_s=1000"], "safety.max_platform_speed_mm_s"),
    ("force_calibration", ["safety.platform_min_mm=[-1000,-13,-2.5]"], "safety.platform_min_mm"),
    ("force_calibration", ["safety.platform_max_mm=[13,13,1000]"], "safety.platform_max_mm"),
    ("force_calibration", ["safety.max_normal_force_n=50"], "safety.max_normal_force_n"),
    ("force_calibration", ["control_period_s=1e-7"], "control_period_s"),
    ("grip_depth", ["control_period_s=1e-7"], "control_period_s"),
    ("force_calibration", ["trial_timeout_s=0.01"], "trial_timeout_s"),
    ("grip_depth", ["+grip_dept=15"], "grip_dept"),
    # issue 20: values that used to get past validation (each one line naming key, value, range)
    ("grip_depth", ["release.opening_mm=1000"], r"release\.opening_mm=1000\.0: must be in \[.*, 50\.0\] mm"),
    ("grip_depth", ["release.opening_mm=nan"], r"release\.opening_mm=nan: must be in"),
    ("grip_depth", ["release.opening_mm=-10"], r"release\.opening_mm=-10\.0: must be in"),
    ("grip_depth", ["hardware=loopback", "+hardware.faults.skin_board.p_bit_flip=2"],
     r"hardware\.faults\.skin_board\.p_bit_flip=2: must be a probability in \[0, 1\]"),
    ("grip_depth", ["hardware=loopback", "+hardware.faults.skin_board.typo=1"],
     r"hardware\.faults\.skin_board\.typo=1: .*choose among \[.*'p_bit_flip'"),
    ("grip_depth", ["hardware=loopback", "+hardware.faults.ur5e.stall_after_s=nan"],
     r"hardware\.faults\.ur5e\.stall_after_s=nan: must be a number >= 0"),
    ("grip_depth", ["hardware=loopback", "+hardware.faults.netft.drop_every=2"],
     r"hardware\.faults\.netft=.*no netft emulator on the gripper setup"),
    ("grip_depth", ["trajectory.translation.accel_mm_s2=1e12"],
     r"trajectory\.translation\.accel_mm_s2=1000000000000\.0: must be > 0 and at most .*1500 mm/s\^2"),
    ("grip_depth", ["trajectory=torsion", "trajectory.torsion.accel_rad_s2=1e12"], r"trajectory\.torsion\.accel_rad_s2"),
    ("grip_depth", ["hold_s=inf"], r"hold_s=inf: must be in \[0, trial_timeout_s=300\.0\] s"),
    ("grip_depth", ["close.settle_s=1e9"], r"close\.settle_s"),
    ("grip_depth", ["approach.baseline_s=nan"], r"approach\.baseline_s"),
    ("force_calibration", ["press.hold_s=inf"], r"press\.hold_s"),
    ("force_calibration", ["slide.z_ramp_mm=inf"], r"slide\.z_ramp_mm=inf: must be a finite number"),
    ("force_calibration", ["approach.contact_force_n=inf"], r"approach\.contact_force_n=inf"),
    ("force_calibration", ["hardware=loopback", "+hardware.faults.skin_board.stalls=[[1.0,nan]]"],
     r"hardware\.faults\.skin_board\.stalls"),
    # issue 31: counts that planned a campaign of years (1.4 GB of plan before the first trial)
    ("force_calibration", ["positions.count=1000000000"], r"positions\.count=1000000000: must be in \[1, 1000\]"),
    ("force_calibration", ["positions.count=0"], r"positions\.count=0: must be in \[1, 1000\]"),
    ("force_calibration", ["press.repeats=100000000"], r"press\.repeats=100000000: must be in \[0, 100\]"),
    ("force_calibration", ["slide.repeats=100000000"], r"slide\.repeats=100000000: must be in \[0, 100\]"),
    ("force_calibration", ["press.repeats=-1"], r"press\.repeats=-1: must be in \[0, 100\]"),
    ("grip_depth", ["approach.consecutive_frames=1000000000"], r"approach\.consecutive_frames=1000000000: must be in"),
    ("grip_depth", ["approach.threshold_counts=1000000000"],
     r"approach\.threshold_counts=1000000000: must be in \[1, 2096640\]"),
    # issue 31: values that passed validation and failed later or gave wrong data
    ("grip_depth", ["live_port=99999"], r"live_port=99999: must be a TCP port in \[1024, 65535\]"),
    ("grip_depth", ["live_port=-1"], r"live_port=-1: must be a TCP port"),
    ("force_calibration", ["live_port=99999"], r"live_port=99999: must be a TCP port"),
    ("grip_depth", ["live_host=0.0.0.0"], r"live_host='0\.0\.0\.0': serves the run beyond this machine: set live_token"),
    ("grip_depth", ["live_host='evil host'"], r"live_host='evil host': must be an IP address"),
    ("force_calibration", ["live_allowed_hosts=[x/y]"], r"live_allowed_hosts='x/y': must be an IP address"),
    ("force_calibration", ["live_token=short"], r"live_token='<hidden>': must be at least 8 characters"),
    ("grip_depth", ["trajectory.translation.speed_mm_s=1e-300"],
     r"trajectory\.translation\.speed_mm_s=1e-300: 20 mm of waypoints at this speed take 2e\+301 s"),
    ("grip_depth", ["trajectory=torsion", "trajectory.torsion.speed_deg_s=0.1"],
     r"trajectory\.torsion\.speed_deg_s=0\.1: 100 deg"),
    ("grip_depth", ["approach.baseline_s=0"], r"approach\.baseline_s=0\.0: must be >= 0\.0118 s \(5 skin frames"),
    ("grip_depth", ["seed=-1"], r"seed=-1: must be an integer in \[0, 4294967295\]"),
    ("grip_depth", ["seed=99999999999999999999"], r"seed=99999999999999999999: must be an integer in"),
    ("force_calibration", ["seed=-1"], r"seed=-1: must be an integer in \[0, 4294967295\]"),
    ("force_calibration", ["sim.seed=4294967296"], r"sim\.seed=4294967296: must be an integer in"),
    ("grip_depth", ["trial=99999999999999999999"], r"trial=99999999999999999999: must be a trial index in \[0, 999\]"),
    # issue 31: how many lost skin frames a trial may have and still be complete
    ("grip_depth", ["max_lost_skin_frames=-1"], r"max_lost_skin_frames=-1: must be in \[0, 1000000\] \(skin frames"),
    ("force_calibration", ["max_lost_skin_frames=10000000"], r"max_lost_skin_frames=10000000: must be in \[0, 1000000\]"),
])
def test_refused_at_validation(app, overrides, key):
    with pytest.raises(ConfigError, match=key if "\\" in key else key.replace(".", r"\.")):
        compose_app(app, overrides)


@pytest.mark.parametrize("data_root", ["/proc/layerskin", "/proc/self/status/sub"])
def test_data_root_where_nothing_can_be_written_is_refused(data_root):
    with pytest.raises(ConfigError, match=r"data_root=.*(cannot write|not a folder)"):
        compose_app("grip_depth", [f"data_root={data_root}"])


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder anyway")
def test_read_only_data_root_is_refused(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(ConfigError, match="data_root=.*cannot write"):
            compose_app("force_calibration", [f"data_root={ro}/data"])
    finally:
        ro.chmod(0o755)


def test_fault_settings_are_the_ones_the_emulators_declare():
    from hardware.config import fault_parameters
    from hardware.loopback import EMULATORS, emulator_class

    for device in EMULATORS:
        declared = fault_parameters(device)
        assert "stall_after_s" in declared and not {"rt", "host", "port", "self"} & set(declared)
        init = emulator_class(device).__init__.__code__.co_varnames
        assert all(name in init or name == "stall_after_s" for name in declared)
    cfg, typed = compose_app("grip_depth", ["hardware=loopback", "+hardware.faults.skin_board.p_bit_flip=0.01",
                                            "+hardware.faults.skin_board.stalls=[[1.0,200]]",
                                            "+hardware.faults.hande.stall_after_s=2.5"])
    assert typed.hardware.faults["skin_board"]["p_bit_flip"] == 0.01


def test_data_root_that_is_a_file_is_refused(tmp_path):
    f = tmp_path / "not_a_folder"
    f.write_text("x")
    with pytest.raises(ConfigError, match="data_root"):
        compose_app("force_calibration", [f"data_root={f}"])


def test_defaults_and_study_settings_pass():
    for depth in (6, 9, 12, 15):
        compose_app("grip_depth", [f"grip_depth={depth}", "trajectory=torsion"])
    compose_app("force_calibration", [])
    # the edges of the ranges above are accepted
    compose_app("grip_depth", ["live_port=0", "seed=4294967295", "trial=999", "approach.baseline_s=0.0118"])
    compose_app("grip_depth", ["trial_timeout_s=30"])  # translation in 10 s; torsion would need 67 s
    compose_app("force_calibration", ["live_port=65535", "positions.count=1000", "press.repeats=100"])
