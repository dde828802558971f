"""Structured-config plumbing shared by every Hydra app.

Each package keeps its schemas next to its code (`<package>/config.py`) and stores them in
Hydra's ConfigStore when imported: an application imports its own config module, which imports
the schemas it builds on, so the core never names an application. `compose(config_name,
overrides)` composes one of the configs under `conf/` (shipped inside the package when installed)
and validates it. `validate(cfg)` turns a composed DictConfig into the typed dataclass tree, which
runs every schema's range checks, and turns any failure into one `ConfigError` naming the key,
the value and what to do — before any device is touched.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import yaml
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from layerskin_exp import rig


def _conf_dir() -> Path:
    """The Hydra configs: `conf/` beside the package in a checkout, `layerskin_exp/conf` in an
    installed distribution (setup.py ships conf/ there)."""
    here = Path(__file__).resolve().parent
    for candidate in (here.parent / "conf", here / "conf"):
        if (candidate / "grip_depth.yaml").is_file():
            return candidate
    return here.parent / "conf"


CONF_DIR = _conf_dir()


# The Hydra behaviour every composition of the project asks for: the apps (layerskin_exp.cli.hydra_main),
# `compose` and `--help`.
VERSION_BASE = "1.3"


class ConfigError(ValueError):
    """A configuration value is wrong. The message names the key, the value and the fix."""


def require(ok: bool, key: str, value, what: str) -> None:
    """Range check for schema __post_init__: raise a ConfigError naming key and value."""
    if not ok:
        raise ConfigError(f"{key}={value!r}: {what}")


_HOST_LABEL = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def host_problem(value) -> str | None:
    """What is wrong with `value` as an address to listen on or connect to (an IPv4 or IPv6
    address, or a host name of letters, digits and hyphens in dot-separated labels), or None."""
    import ipaddress

    if not isinstance(value, str) or not value:
        return "must be an IP address or a host name"
    try:
        ipaddress.ip_address(value)
        return None
    except ValueError:
        pass
    if value.startswith("[") and value.endswith("]"):
        return "must be an IPv6 address without brackets, e.g. ::1"
    labels = value.removesuffix(".").split(".")
    if len(value) > 253 or not all(_HOST_LABEL.match(label) for label in labels):
        return ("must be an IP address (127.0.0.1, ::1) or a host name of letters, digits and hyphens "
                "(localhost, lab-pc.local)")
    if all(label.isdigit() for label in labels):
        return "is not a valid IPv4 address"
    return None


def require_host(key: str, value) -> None:
    """An address setting: an IP address or a host name (host_problem)."""
    problem = host_problem(value)
    require(problem is None, key, value, problem or "")


# Seeds reach numpy's generators 32 bits wide (`seed & 0xFFFFFFFF`): a larger seed would silently
# repeat the draws of a smaller one.
SEED_MAX = 2**32 - 1


def require_seed(key: str, seed) -> None:
    """Range check of a seed setting: an integer in [0, SEED_MAX]."""
    require(isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed <= SEED_MAX, key, seed,
            f"must be an integer in [0, {SEED_MAX}] (the random generators take 32 bits of a seed; a larger one "
            "would repeat a smaller one's draws)")


# Keys that once repeated a fact of the rig or moved: key -> what to do instead. Each schema
# module retires its own keys (`retire`); `compose` and the command lines refuse them up front.
RETIRED_KEYS: dict[str, str] = {}


def retire(key: str, instead: str) -> None:
    """Refuse the dotted config `key` from now on, with `instead` saying what to use."""
    RETIRED_KEYS[key] = instead


def retired_message(key: str) -> str | None:
    """The one-line refusal of a retired dotted key, or None if `key` is a current one."""
    return f"{key}: no longer a setting; {RETIRED_KEYS[key]}" if key in RETIRED_KEYS else None


def check_retired(overrides: Sequence[str]) -> None:
    """ConfigError for the first override that sets a retired key."""
    for o in overrides:
        msg = retired_message(o.split("=", 1)[0].lstrip("+~"))
        if msg:
            raise ConfigError(msg)


def check_group_options(overrides: Sequence[str]) -> None:
    """ConfigError for the first override whose config-group option (`trajectory=NAME`: the file
    conf/trajectory/NAME.yaml) names a file outside its group's folder (`../../elsewhere/x`):
    a group option is one of the files there, never a path that leads out of conf/."""
    for o in overrides:
        key, sep, value = o.partition("=")
        key = key.lstrip("+~")
        group = CONF_DIR / key
        if not sep or "." in key or not value or not group.is_dir():
            continue
        base = group.resolve()
        for option in value.split(","):  # a sweep's options
            option = option.strip().strip("'\"")
            if option and base not in (group / option).resolve().parents:
                names = sorted(p.stem for p in group.glob("*.yaml") if not p.stem.endswith("_schema"))
                raise ConfigError(f"{key}={option}: a {key} option is a file in conf/{key}/ "
                                  f"({', '.join(names) or 'none there'}); it may not lead out of that folder")


def yaml_error_line(err) -> str | None:
    """One line for a YAML syntax error: the file (under conf/ as conf/...), line, column and
    the problem; None if err is not one."""
    import yaml

    if not isinstance(err, yaml.YAMLError):
        return None
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    if mark is None:
        return f"YAML syntax error: {problem}"
    name = Path(mark.name)
    try:
        name = Path("conf") / name.resolve().relative_to(CONF_DIR.resolve())
    except (ValueError, OSError):
        pass
    return f"{name}: YAML syntax error at line {mark.line + 1}, column {mark.column + 1}: {problem}"


@dataclass
class SkinConfig:
    """The two-layer skin as the backends read it: its frame timing, and the rig's geometry.

    The geometry (array size, pitch, electrode width, ADC depth, layer names) is a fact of the
    sensor, defined once in `layerskin_exp.rig`; it is read here, never set.
    """

    frame_period_ms: float = 2.36  # one frame pair (both layers), mean

    def __post_init__(self) -> None:
        require(self.frame_period_ms > 0, "skin.frame_period_ms", self.frame_period_ms, "must be > 0")

    @property
    def n_taxels(self) -> int:
        return rig.N_TAXELS

    @property
    def pitch_mm(self) -> float:
        return rig.PITCH_MM

    @property
    def electrode_mm(self) -> float:
        return rig.ELECTRODE_MM

    @property
    def adc_bits(self) -> int:
        return rig.ADC_BITS

    @property
    def layers(self) -> tuple[str, str]:
        return rig.LAYERS

    def taxel_centres_mm(self):
        """(n,) taxel centre coordinates along one axis, origin at the array centre."""
        return rig.taxel_centres_mm()


for _key, _fact in (("n_taxels", f"the array is {rig.N_TAXELS} x {rig.N_TAXELS} taxels per layer"),
                    ("pitch_mm", f"the taxel pitch is {rig.PITCH_MM} mm"),
                    ("electrode_mm", f"the electrodes are {rig.ELECTRODE_MM} mm wide"),
                    ("adc_bits", f"the readout is {rig.ADC_BITS}-bit"),
                    ("layers", f"the layers are {list(rig.LAYERS)}")):
    retire(f"skin.{_key}", f"{_fact} on every backend, a fact of the sensor defined once in layerskin_exp/rig.py "
                           "(the readout board, the session log, the protocols and the simulator all read it)")


def _store() -> None:
    cs = ConfigStore.instance()
    cs.store(group="skin", name="skin_schema", node=SkinConfig)


_store()


def one_line(err: Exception) -> str:
    """One readable line: the error's first line and, for Hydra's override errors, the first
    line of its cause (the explanation: "Key 'x' not in 'Schema'", "could not be converted")."""
    from hydra.errors import HydraException

    for e in (err, err.__cause__):  # a YAML file with a syntax error, however Hydra passed it on
        if yaml_error_line(e):
            return yaml_error_line(e)
    lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
    text = lines[0] if lines else type(err).__name__
    # A retired key set in a yaml file (a user's design, material or lattice file): Hydra names the
    # key as `full_key: ...` below its first line.
    key = next((ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("full_key:")), None)
    if key and retired_message(key):
        where = re.match(r"In '([^']+)'", text)
        return retired_message(key) + (f" (set in '{where.group(1)}')" if where else "")
    cause = err.__cause__
    if isinstance(err, HydraException) and cause is not None:
        cause_lines = [ln.strip() for ln in str(cause).splitlines() if ln.strip()]
        if cause_lines and cause_lines[0] not in text:
            text = f"{text.rstrip('.')}: {cause_lines[0]}"
    options = getattr(err, "options", None)  # hydra's MissingConfigException: the group's choices
    if options:
        text = f"{text} (available: {', '.join(o for o in options if not o.endswith('_schema'))})"
    return text


def compose(config_name: str, overrides: Sequence[str] = ()):
    """The typed, validated config of `conf/<config_name>.yaml` with Hydra `overrides`.

    Works from a checkout and from an installed wheel (CONF_DIR). The caller registers the
    schemas the config names first, by importing their modules (`protocols.config` for the
    protocols; the core's own `skin`, `sim` and `world` schemas register with
    `layerskin_exp.sim.config`). Raises ConfigError (one line: key, value, what to do) for a
    retired key, an unknown option or key, a type error or a range error.
    """
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.errors import HydraException

    check_retired(overrides)
    check_group_options(overrides)
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base=VERSION_BASE):
            cfg = hydra_compose(config_name=config_name, overrides=list(overrides))
    except (HydraException, yaml.YAMLError) as e:
        raise ConfigError(one_line(e)) from None
    finally:
        GlobalHydra.instance().clear()
    return validate(cfg)


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
            if retired_message(k):
                raise ConfigError(retired_message(k))
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
