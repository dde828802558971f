"""The shared config plumbing: range checks name the key, type errors name the key."""

from dataclasses import dataclass, field

import pytest
from omegaconf import OmegaConf

from layerskin_exp.config import ConfigError, SkinConfig, require, validate


@dataclass
class _App:
    skin: SkinConfig = field(default_factory=SkinConfig)
    depth_mm: float = 1.0

    def __post_init__(self) -> None:
        require(self.depth_mm > 0, "depth_mm", self.depth_mm, "must be > 0")


def test_valid_config_builds_typed_objects():
    obj = validate(OmegaConf.structured(_App))
    assert isinstance(obj.skin, SkinConfig)
    assert obj.skin.taxel_centres_mm()[0] == pytest.approx(-11.25)
    assert obj.skin.taxel_centres_mm()[-1] == pytest.approx(11.25)


@pytest.mark.parametrize(
    "key,value,needle",
    [("skin.pitch_mm", -1.5, "skin.pitch_mm=-1.5"), ("skin.electrode_mm", 2.0, "skin.electrode_mm=2.0"),
     ("depth_mm", -3.0, "depth_mm=-3.0")],
)
def test_out_of_range_value_names_the_key(key, value, needle):
    cfg = OmegaConf.structured(_App)
    OmegaConf.update(cfg, key, value)
    with pytest.raises(ConfigError, match=needle.replace(".", r"\.")):
        validate(cfg)


def test_wrong_type_is_refused_naming_the_key():
    cfg = OmegaConf.structured(_App)
    with pytest.raises(Exception) as ei:
        cfg.skin.pitch_mm = "wide"
    assert "skin.pitch_mm" in str(ei.value)
