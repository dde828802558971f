"""Helpers for the protocol tests that run the apps on the simulated rig."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

import protocols.config  # noqa: F401 - the apps' schemas, as the apps store them
from layerskin_exp.config import validate

REPO = Path(__file__).resolve().parents[2]

# Shortened study configs: a handful of trials, short holds and trajectories.
TINY_CALIBRATION = ["positions.count=2", "press.repeats=1", "slide.repeats=1", "press.hold_s=0.05"]
TINY_GRIP = ["trajectory.translation.waypoints_mm=[0.0,0.5,0.0]", "hold_s=0.1", "close.settle_s=0.1", "grip_depth=6"]


def compose_app(config_name: str, overrides: list[str]):
    """(DictConfig, typed config) of an app, composed as the CLI would."""
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        cfg = compose(config_name=config_name, overrides=overrides)
    return cfg, validate(cfg)


def run_cli(module: str, args: list[str], cwd: Path, **kw) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO), "HYDRA_FULL_ERROR": "0"}
    return subprocess.run([sys.executable, "-m", module, *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=240, **kw)


def popen_cli(module: str, args: list[str], cwd: Path, stdout=subprocess.DEVNULL,
              stderr=subprocess.DEVNULL) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen([sys.executable, "-m", module, *args], cwd=cwd, env=env,
                            stdout=stdout, stderr=stderr, text=True)


def design_dir(protocol_root: Path) -> Path:
    """The one design folder a run without design overrides writes under <data_root>/<protocol>/."""
    dirs = [d for d in protocol_root.iterdir() if d.is_dir()]
    assert len(dirs) == 1, f"expected one design folder in {protocol_root}, found {dirs}"
    return dirs[0]
