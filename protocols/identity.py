"""What makes two trials the same trial: the configuration that shapes their data, and their labels.

A trial's *identity* is a stable hash of the resolved config less the keys that only say how the
run goes (where files go, progress bars, device addresses and timeouts, Hydra's own settings),
plus the trial's labels. It is stored in each session's metadata; resume skips a trial only when
a complete file with the same identity exists, so a design sweep (`sim.spacer.modulus=20,60`)
never mistakes one design's trials for another's.

A *design* is the same hash less the keys that select a trial within a campaign (grip depth,
trajectory, trial index; the number of positions of a random layout, whose positions do not
depend on it). Each design's trials go to their own folder `<data_root>/<protocol>/<design>/`,
so a sweep over anything but the trial labels writes one set of files per value without the
user choosing a data_root per job.
"""

from __future__ import annotations

import copy
import hashlib
import json

# Keys that never shape the data (dotted paths into the resolved config).
RUN_ONLY_KEYS = ("data_root", "progress", "trial_timeout_s", "hydra", "live", "live_port", "live_hold",
                 "save_images")
# Keys that select a trial within a design (their values are in the trial labels).
TRIAL_SELECTOR_KEYS = ("grip_depth", "trial", "trajectory")
DESIGN_ID_LENGTH = 10


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
    if isinstance(hw, dict):  # addresses, ports and timeouts say where the bench is, not what it does
        backend = hw.get("backend")
        cfg["hardware"] = {"backend": backend}
        if backend == "lab":
            cfg.pop("sim", None)  # the simulator's parameters play no part on the real bench
    return cfg


def _digest(obj) -> str:
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def design_id(config: dict) -> str:
    """Short stable id of the design a resolved config describes (trial selectors left out)."""
    cfg = shaping_config(config)
    for key in TRIAL_SELECTOR_KEYS:
        _drop(cfg, key)
    positions = cfg.get("positions")
    if isinstance(positions, dict) and positions.get("layout") == "random":
        positions.pop("count", None)  # each random position has its own generator
    return _digest(cfg)[:DESIGN_ID_LENGTH]


def trial_identity(config: dict, labels: dict) -> str:
    """Stable hash of everything that shapes one trial's data: its shaping config and labels."""
    cfg = shaping_config(config)
    positions = cfg.get("positions")
    if isinstance(positions, dict) and positions.get("layout") == "random":
        positions.pop("count", None)
    return _digest({"config": cfg, "labels": labels})
