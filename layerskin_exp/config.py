"""Structured-config plumbing shared by every Hydra app.

Each package keeps its schemas next to its code (`<package>/config.py`) and stores them in
Hydra's ConfigStore when imported; `register_all()` imports them all. `validate(cfg)` turns a
composed DictConfig into the typed dataclass tree, which runs every schema's range checks, and
turns any failure into one `ConfigError` naming the key, the value and what to do — before any
device is touched.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

# Every module that stores schemas in the ConfigStore; each owns its groups.
SCHEMA_MODULES = (
    "layerskin_exp.config",
    "layerskin_exp.sim.config",
    "hardware.config",
    "protocols.config",
    "analysis.config",
)


class ConfigError(ValueError):
    """A configuration value is wrong. The message names the key, the value and the fix."""


def require(ok: bool, key: str, value, what: str) -> None:
    """Range check for schema __post_init__: raise a ConfigError naming key and value."""
    if not ok:
        raise ConfigError(f"{key}={value!r}: {what}")


@dataclass
class SkinConfig:
    """Geometry and readout of the two-layer skin (the same for every backend)."""

    n_taxels: int = 16
    pitch_mm: float = 1.5
    electrode_mm: float = 1.2
    adc_bits: int = 12
    frame_period_ms: float = 2.36  # one frame pair (both layers), mean
    layers: tuple[str, str] = ("superficial", "deep")

    def __post_init__(self) -> None:
        require(self.n_taxels > 0, "skin.n_taxels", self.n_taxels, "must be a positive taxel count")
        require(self.pitch_mm > 0, "skin.pitch_mm", self.pitch_mm, "pitch must be > 0 mm")
        require(0 < self.electrode_mm <= self.pitch_mm, "skin.electrode_mm", self.electrode_mm,
                "electrode width must be > 0 and not exceed the pitch")
        require(1 <= self.adc_bits <= 16, "skin.adc_bits", self.adc_bits, "must be 1..16")
        require(self.frame_period_ms > 0, "skin.frame_period_ms", self.frame_period_ms, "must be > 0")

    def taxel_centres_mm(self):
        """(n,) taxel centre coordinates along one axis, origin at the array centre."""
        import numpy as np

        return (np.arange(self.n_taxels) - (self.n_taxels - 1) / 2) * self.pitch_mm


def _store() -> None:
    cs = ConfigStore.instance()
    cs.store(group="skin", name="skin_schema", node=SkinConfig)


_store()


def register_all() -> None:
    """Import every schema module so the ConfigStore knows all groups."""
    for mod in SCHEMA_MODULES:
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as e:  # a package not written yet
            if e.name != mod and not mod.startswith(str(e.name)):
                raise


def unknown_keys(node: DictConfig, prefix: str = "") -> list[tuple[str, str]]:
    """(dotted key, schema name) of every key in `node` that its structured schema does not have.

    Hydra's `+key=value` adds keys even to a structured config; to_object then drops them
    silently, so a misspelled `+grip_dept=15` would run at the default. Values are not resolved.
    """
    out: list[tuple[str, str]] = []
    schema = OmegaConf.get_type(node)
    names = {f.name for f in dataclasses.fields(schema)} if dataclasses.is_dataclass(schema) else None
    for k in node.keys():
        if names is not None and k not in names:
            out.append((f"{prefix}{k}", schema.__name__))
            continue
        child = node._get_node(k)
        if isinstance(child, DictConfig) and not child._is_missing() and not child._is_none():
            out += unknown_keys(child, f"{prefix}{k}.")
    return out


def validate(cfg: DictConfig, key: str | None = None):
    """Build the typed object tree from cfg (or cfg[key]); every schema's checks run.

    Raises ConfigError with the offending key and value; nothing else escapes. Keys the schema
    does not have (added with `+`) are refused.
    """
    node = cfg if key is None else cfg[key]
    if isinstance(node, DictConfig):
        extra = unknown_keys(node)
        if extra:
            k, schema = extra[0]
            raise ConfigError(f"{k}: Key '{k.rsplit('.', 1)[-1]}' not in '{schema}' (check the spelling; "
                              "'+' cannot add a setting the schema does not have)")
    try:
        return OmegaConf.to_object(node)
    except ConfigError:
        raise
    except OmegaConfBaseException as e:
        cause = e.__cause__ if isinstance(e.__cause__, ConfigError) else None
        if cause is not None:
            raise cause from None
        full_key = getattr(e, "full_key", None) or ""
        msg = getattr(e, "msg", None) or str(e).splitlines()[0]
        raise ConfigError(f"{full_key}: {msg} (check the override or the yaml under conf/)") from None


def format_config_error(err: Exception) -> str:
    return f"configuration error: {err}"
