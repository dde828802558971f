"""Hard ceilings no config can raise, lower bounds that make sense for a 424 Hz rig, and paths
checked before anything connects (all refused at validation, naming the key)."""

from __future__ import annotations

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
])
def test_refused_at_validation(app, overrides, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        compose_app(app, overrides)


def test_data_root_that_is_a_file_is_refused(tmp_path):
    f = tmp_path / "not_a_folder"
    f.write_text("x")
    with pytest.raises(ConfigError, match="data_root"):
        compose_app("force_calibration", [f"data_root={f}"])


def test_defaults_and_study_settings_pass():
    for depth in (6, 9, 12, 15):
        compose_app("grip_depth", [f"grip_depth={depth}", "trajectory=torsion"])
    compose_app("force_calibration", [])
