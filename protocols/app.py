"""What both Hydra apps share: config checks before anything moves, the rig's life cycle, exit codes.

Exit codes: 0 done; 2 configuration refused (nothing connected, nothing written); 1 a device
error, a refused motion or a timeout stopped the run (motion stopped, trial file closed
"aborted: ..."); 130 Ctrl-C, 143 SIGTERM (same; SIGTERM is what SLURM and process managers
send). Rerunning the same command resumes.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from omegaconf import DictConfig, OmegaConf

from hardware.interfaces import DeviceError
from layerskin_exp.config import ConfigError, format_config_error, validate
from protocols.runner import Terminated

log = logging.getLogger(__name__)

CONF_DIR = Path(__file__).resolve().parent.parent / "conf"
EXIT_CONFIG = 2
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


def _on_sigterm(signum, frame) -> None:
    raise Terminated()


@contextlib.contextmanager
def _sigterm_as_exception():
    """Turn SIGTERM into `Terminated` in the main thread while the rig runs (Hydra runs jobs in
    the main thread; elsewhere the default handling stays)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _refuse(err: Exception) -> None:
    print(format_config_error(err), file=sys.stderr)
    sys.exit(EXIT_CONFIG)


def _one_line(err: Exception) -> str:
    lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
    text = lines[0] if lines else type(err).__name__
    options = getattr(err, "options", None)  # hydra's MissingConfigException: the group's choices
    if options:
        text = f"{text} (available: {', '.join(o for o in options if not o.endswith('_schema'))})"
    return text


def expand_sweep(overrides: list[str]) -> list[list[str]]:
    """The override lists of every job a basic-sweeper multirun would launch (cartesian product)."""
    parsed = OverridesParser.create().parse_overrides(overrides)
    choices = []
    for o in parsed:
        key = o.get_key_element()
        values = list(o.sweep_string_iterator()) if o.is_sweep_override() else [o.get_value_element_as_str()]
        choices.append([f"{key}={v}" for v in values])
    return [list(combo) for combo in itertools.product(*choices)]


def preflight(config_name: str, argv: list[str]) -> None:
    """Compose and validate the config of every job the command line asks for, before Hydra runs.

    Catches unknown group options (`hardware=foo`), type errors and range errors as one line and
    exit code 2, so a sweep is refused as a whole rather than failing at job 37.
    """
    if any(a in ("--help", "-h", "--hydra-help", "--info", "-i", "--cfg", "-c", "--shell-completion", "-sc",
                 "--config-path", "-cp", "--config-name", "-cn", "--config-dir", "-cd") for a in argv):
        return  # Hydra's own modes and alternative configs: let Hydra handle them
    overrides = [a for a in argv if not a.startswith("-") and not a.split("=", 1)[0].lstrip("+~").startswith("hydra")]
    multirun = "-m" in argv or "--multirun" in argv
    try:
        jobs = expand_sweep(overrides) if multirun else [overrides]
    except HydraException as e:
        _refuse(ConfigError(f"override: {_one_line(e)}"))
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        for job in jobs:
            try:
                cfg = compose(config_name=config_name, overrides=job)
                validate(cfg)
            except ConfigError as e:
                _refuse(e)
            except HydraException as e:
                _refuse(ConfigError(_one_line(e)))
    GlobalHydra.instance().clear()


def run_app(cfg: DictConfig, setup: str, body: Callable[[object, object, dict], object]):
    """Validate, build and connect the rig, run body(typed_cfg, rig, metadata), always stop and disconnect.

    Nothing moves before every device is connected and the config validated.
    """
    from hardware import build_rig  # the backends import heavy optional drivers

    try:
        typed = validate(cfg)
        rig = build_rig(cfg, setup)
    except ConfigError as e:
        _refuse(e)
    except DeviceError as e:
        print(f"error: {_one_line(e)}", file=sys.stderr)
        sys.exit(EXIT_FAILED)
    with _sigterm_as_exception():
        return _run_connected(cfg, rig, typed, body)


def _run_connected(cfg: DictConfig, rig, typed, body):
    try:
        rig.connect()
    except Exception as e:  # noqa: BLE001 - any failure to connect ends the run before motion
        rig.disconnect()
        print(f"error: could not connect the {rig.backend} rig: {_one_line(e)}", file=sys.stderr)
        sys.exit(EXIT_FAILED)
    except Terminated:
        rig.disconnect()
        print("terminated (SIGTERM) while connecting; nothing moved", file=sys.stderr)
        sys.exit(EXIT_TERMINATED)
    metadata = {"config": OmegaConf.to_container(cfg, resolve=True), "backend": rig.backend,
                "calibration": rig.skin.calibration()}
    try:
        return body(typed, rig, metadata)
    except KeyboardInterrupt:
        rig.stop_motion()
        print("interrupted: motion stopped, the current trial is marked aborted; rerun the same command "
              "to resume", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    except Terminated:
        rig.stop_motion()
        print("terminated (SIGTERM): motion stopped, the current trial is marked aborted; rerun the same "
              "command to resume", file=sys.stderr)
        sys.exit(EXIT_TERMINATED)
    except ConfigError as e:
        rig.stop_motion()
        _refuse(e)
    except Exception as e:
        rig.stop_motion()
        print(f"error: {type(e).__name__}: {_one_line(e)} (motion stopped, the trial file is marked aborted; "
              "rerun the same command to resume)", file=sys.stderr)
        sys.exit(EXIT_FAILED)
    finally:
        rig.stop_motion()
        rig.disconnect()
