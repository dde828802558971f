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


def start_realtime_world(setup: str = "platform", seed: int = 0, period_s: float = 0.002, **rig_overrides):
    """A started RealtimeWorld for "platform" or "gripper": what the loopback emulators run on.
    rt.rig holds the simulated twins; use `with rt.lock:`. The caller stops it."""
    from hardware.sim.realtime import RealtimeWorld
    from layerskin_exp.config import validate

    cfg = app_config("sim", seed, **rig_overrides)
    rt = RealtimeWorld.from_config(validate(cfg.sim), validate(cfg.skin), setup, period_s)
    rt.start()
    return rt


@pytest.fixture
def realtime_world():
    """Factory: start_realtime_world(...) per call, each stopped at teardown."""
    started = []

    def make(*args, **kwargs):
        started.append(start_realtime_world(*args, **kwargs))
        return started[-1]

    yield make
    for rt in started:
        rt.stop()
