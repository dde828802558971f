import pytest
from omegaconf import OmegaConf

from hardware.config import LabHardwareConfig, LoopbackHardwareConfig, SimHardwareConfig
from layerskin_exp.config import SkinConfig
from layerskin_exp.sim.config import SimConfig

HW = {"sim": SimHardwareConfig, "lab": LabHardwareConfig, "loopback": LoopbackHardwareConfig}


def app_config(backend: str = "sim", seed: int = 0, **rig_overrides):
    """A composed-app-like config: hardware, skin and sim nodes (dotted rig overrides allowed)."""
    cfg = OmegaConf.create({"hardware": OmegaConf.structured(HW[backend]), "skin": OmegaConf.structured(SkinConfig),
                            "sim": OmegaConf.structured(SimConfig)})
    cfg.sim.seed = seed
    for k, v in rig_overrides.items():
        OmegaConf.update(cfg, "sim.rig." + k.replace("__", "."), v)
    return cfg


@pytest.fixture
def make_cfg():
    return app_config
