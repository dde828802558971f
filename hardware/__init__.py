"""Devices: the interfaces protocols use, and the backends that implement them (sim, lab, loopback).

`build_rig(cfg, setup)` is the one entry point: it reads `cfg.hardware.backend` and returns a
`Rig` for the "platform" (force calibration) or "gripper" (manipulation) setup.
"""

from __future__ import annotations

from hardware.interfaces import DeviceError
from hardware.rig import Rig


def build_rig(cfg, setup: str) -> Rig:
    """The rig for `setup` on the configured backend.

    cfg: the composed app config (DictConfig with `hardware`, `skin`, `sim` nodes) or any object
    with those attributes already typed. Config errors raise ConfigError naming the key. On
    `loopback` this powers on the emulators (they stop when the rig disconnects); on `lab` it only
    builds the drivers (nothing is opened before `rig.connect()`). On both, this process runs at
    `hardware.nice` from here until the rig disconnects, its heap held out of the cycle collector's
    scans (hardware.priority).
    """
    from omegaconf import DictConfig

    from layerskin_exp.config import validate

    def typed(key):
        node = cfg[key] if isinstance(cfg, DictConfig) else getattr(cfg, key)
        return validate(node) if isinstance(node, DictConfig) else node

    hw = typed("hardware")
    backend = getattr(hw, "backend", None)
    if backend == "sim":
        from hardware.sim import build_sim_rig

        return build_sim_rig(typed("sim"), typed("skin"), setup)
    if backend in ("lab", "loopback"):
        from hardware.priority import hold_heap, raise_priority

        # Raised before anything starts, so every driver thread (and on loopback every emulator
        # process) takes the bench's priority from this thread; put back when the rig disconnects.
        undo = [u for u in (raise_priority(hw.nice),) if u is not None]
        try:
            if backend == "lab":
                from hardware.lab import build_lab_rig

                rig = build_lab_rig(hw, typed("skin"), setup)
            else:
                from hardware.loopback import build_loopback_rig

                rig = build_loopback_rig(hw, typed("sim"), typed("skin"), setup)
            # what the process holds now stays out of the collector's scans during the trial
            undo.extend(u for u in (hold_heap(),) if u is not None)
        except BaseException:
            for u in reversed(undo):
                u()
            raise

        def release() -> None:
            for u in reversed(undo):
                u()

        rig.release = release if undo else None
        return rig
    raise DeviceError(f"hardware.backend={backend!r}: unknown backend; choose sim, lab or loopback")
