"""What makes two trials the same trial, and where a trial's file goes.

A trial's *identity* is a stable hash of the resolved config less the keys that only say how the
run goes (RUN_ONLY_KEYS: where files go, progress bars, device addresses and timeouts, the live
view, and the switches that add a view of the same data: camera images, live estimates), plus
the trial's labels. It is stored in each session's metadata.

A *design* is the same hash less the keys whose values are in the trial's file name
(TRIAL_SELECTOR_KEYS: grip depth, motion, trial index; a calibration trial's name is its
position index, kind and repeat, which the rest of the config plans). So every key that shapes
the data, protocol or simulator, is either in the design folder's name or in the file name:

    <data_root>/<protocol>/<design>/<trial name>.mcap

and two configs that differ in any such key never share a file. Simulated data also records
the simulator's code (`simulator_code`, its modules' hash): a changed simulator writes a new
design folder. A sweep over any key writes one design folder per value; rerunning it finds every
trial where the first run put it. Each design folder holds `design.yaml`, the configuration it
stands for (`python -m protocols.sessions` lists the designs under a data_root and what tells
them apart).
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import tempfile
from pathlib import Path

import yaml

# Keys that never shape the data (dotted paths into the resolved config).
RUN_ONLY_KEYS = ("data_root", "progress", "trial_timeout_s", "hydra", "live", "live_port", "live_hold",
                 # how many lost skin frames a trial may have and still be complete: judges the data
                 "max_lost_skin_frames",
                 # add a view of the same trial: images from the camera, estimates from a model
                 "save_images", "sim.rig.camera.keep_images", "estimator")
# Keys whose values are written in the trial's file name (protocols/grip.py trial_name).
TRIAL_SELECTOR_KEYS = ("grip_depth", "trial", "trajectory.motion")
# Hardware settings that shape the data (the rest say where the bench is: addresses, ports, timeouts).
HARDWARE_SHAPING_KEYS = ("backend", "faults")
DESIGN_ID_LENGTH = 10
MANIFEST = "design.yaml"


def _drop(cfg: dict, dotted: str) -> None:
    node = cfg
    *parents, last = dotted.split(".")
    for p in parents:
        node = node.get(p) if isinstance(node, dict) else None
        if node is None:
            return
    if isinstance(node, dict):
        node.pop(last, None)


def shaping_config(config: dict) -> dict:
    """The part of a resolved config (plain dict) that shapes a trial's data."""
    cfg = copy.deepcopy(config)
    for key in RUN_ONLY_KEYS:
        _drop(cfg, key)
    hw = cfg.get("hardware")
    if isinstance(hw, dict):
        cfg["hardware"] = {k: hw[k] for k in HARDWARE_SHAPING_KEYS if hw.get(k)}
        if hw.get("backend") == "lab":
            cfg.pop("sim", None)  # the simulator's parameters play no part on the real bench
    if not (isinstance(hw, dict) and hw.get("backend") == "lab"):
        # simulated data (sim, and loopback's emulators over the simulated world) is shaped by the
        # simulator's code too: a change to it is a new design, so a rerun simulates it afresh
        # beside the old sessions instead of resuming from data the old code made
        from layerskin_exp.sim.table_cache import simulator_version  # the simulator: not for --help

        cfg["simulator_code"] = simulator_version()
    positions = cfg.get("positions")
    if isinstance(positions, dict) and positions.get("layout") == "random":
        positions.pop("count", None)  # each random position has its own generator: a longer campaign extends it
    return cfg


def _digest(obj) -> str:
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def design_config(config: dict) -> dict:
    """What a design folder stands for: the shaping config less the trial selectors."""
    cfg = shaping_config(config)
    for key in TRIAL_SELECTOR_KEYS:
        _drop(cfg, key)
    return cfg


def design_id(config: dict) -> str:
    """Short stable id of the design a resolved config describes (the design folder's name)."""
    return _digest(design_config(config))[:DESIGN_ID_LENGTH]


def trial_identity(config: dict, labels: dict) -> str:
    """Stable hash of everything that shapes one trial's data: its shaping config and labels."""
    return _digest({"config": shaping_config(config), "labels": labels})


def exact_number(x: float) -> str:
    """A number as written in a file name, in full: 9.0 -> "9", 9.5 -> "9.5", 9.0000001 -> "9.0000001"."""
    text = repr(float(x))
    return text[:-2] if text.endswith(".0") else text


def write_manifest(folder: Path, config: dict) -> Path:
    """Write `<folder>/design.yaml` (the design_config) once; concurrent jobs write the same text,
    each through its own temporary file renamed into place."""
    path = Path(folder) / MANIFEST
    if path.is_file():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    text = ("# The configuration every session in this folder shares (less run-only keys and the trial\n"
            "# labels in the file names). Written by the protocol; see protocols/identity.py.\n"
            + yaml.safe_dump(json.loads(json.dumps(design_config(config), default=str)), sort_keys=True))
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".design-", suffix=".yaml")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
