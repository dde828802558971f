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


def sigterm_while_connecting(module: str, args: list[str], cwd: Path, job_log: Path, connected: str) -> str:
    """Run `module`, wait until its job log says `connected` (the device that connects just before
    the stalled one), send SIGTERM: the run must exit 143 within 10 s (a deadline for a loaded
    machine; the measured figures are in the commit messages). Returns its stderr."""
    import signal
    import time

    proc = popen_cli(module, args, cwd, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 200
        while proc.poll() is None and time.monotonic() < deadline and \
                connected not in (job_log.read_text() if job_log.is_file() else ""):
            time.sleep(0.01)
        assert proc.poll() is None, "the run ended before the signal could be sent"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=10) == 143
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.stderr.read()


def design_dir(protocol_root: Path) -> Path:
    """The one design folder a run without design overrides writes under <data_root>/<protocol>/."""
    dirs = [d for d in protocol_root.iterdir() if d.is_dir()]
    assert len(dirs) == 1, f"expected one design folder in {protocol_root}, found {dirs}"
    return dirs[0]
