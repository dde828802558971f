"""The hardware group: schemas validate, the lab rig builds without touching anything and fails to
connect clearly, unknown backends and bad device settings name the key."""

import pytest
from omegaconf import OmegaConf

from hardware import build_rig
from hardware.interfaces import DeviceError
from layerskin_exp.config import ConfigError, validate


def test_lab_rig_builds_without_io_and_connect_names_the_missing_port(make_cfg, tmp_path):
    cfg = make_cfg("lab")
    cfg.hardware.skin_board.port = str(tmp_path / "ttyACM-missing")
    cfg.hardware.skin_board.connect_timeout_s = 0.2
    rig = build_rig(cfg, "platform")  # building opens nothing
    assert rig.backend == "lab" and not any(d.is_connected for d in rig.devices())
    with pytest.raises(DeviceError, match="ttyACM-missing"):
        rig.connect()
    assert not any(d.is_connected for d in rig.devices())


def test_unknown_backend_and_bad_port_name_the_key(make_cfg):
    cfg = make_cfg("sim")
    cfg.hardware.backend = "fpga"
    with pytest.raises(ConfigError, match="hardware.backend='fpga'"):
        build_rig(cfg, "platform")
    cfg = make_cfg("lab")
    cfg.hardware.netft.port = 70000
    with pytest.raises(ConfigError, match="hardware.netft.port=70000"):
        validate(cfg, "hardware")


def test_rig_parameter_out_of_range_names_the_key(make_cfg):
    cfg = make_cfg("sim")
    OmegaConf.update(cfg, "sim.rig.platform.max_speed_mm_s", -1.0)
    with pytest.raises(ConfigError, match="sim.rig.platform.max_speed_mm_s"):
        build_rig(cfg, "platform")


def test_unknown_setup_is_refused(make_cfg):
    with pytest.raises(DeviceError, match="setup"):
        build_rig(make_cfg(), "treadmill")


def test_yaml_files_compose_and_validate():
    from pathlib import Path

    from hydra import compose, initialize_config_dir

    import hardware.config  # noqa: F401 - the hardware group's schemas

    conf = Path(__file__).resolve().parents[2] / "conf"
    with initialize_config_dir(config_dir=str(conf), version_base=None):
        for name in ("sim", "lab", "loopback"):
            cfg = compose(overrides=[f"+hardware={name}"])
            assert validate(cfg, "hardware").backend == name
