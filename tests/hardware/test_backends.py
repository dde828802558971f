"""The hardware group: schemas validate, lab/loopback refuse clearly, unknown backends name the key."""

import pytest
from omegaconf import OmegaConf

from hardware import build_rig
from hardware.interfaces import DeviceError
from layerskin_exp.config import ConfigError, validate


@pytest.mark.parametrize("backend", ["lab", "loopback"])
def test_backends_without_drivers_refuse_clearly(make_cfg, backend):
    cfg = make_cfg(backend)
    assert validate(cfg, "hardware").backend == backend
    with pytest.raises(DeviceError, match=f"hardware={backend}.*not in this build"):
        build_rig(cfg, "platform")


def test_unknown_backend_and_bad_port_name_the_key(make_cfg):
    cfg = make_cfg("sim")
    cfg.hardware.backend = "fpga"
    with pytest.raises(ConfigError, match="hardware.backend='fpga'"):
        build_rig(cfg, "platform")
    cfg = make_cfg("lab")
    cfg.hardware.ft_port = 70000
    with pytest.raises(ConfigError, match="hardware.ft_port=70000"):
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

    from layerskin_exp.config import register_all

    register_all()
    conf = Path(__file__).resolve().parents[2] / "conf"
    with initialize_config_dir(config_dir=str(conf), version_base=None):
        for name in ("sim", "lab", "loopback"):
            cfg = compose(overrides=[f"+hardware={name}"])
            assert validate(cfg, "hardware").backend == name
