"""Devices: the interfaces protocols use, and the backends that implement them (sim, lab, loopback).

`build_rig(cfg, setup)` is the one entry point: it reads `cfg.hardware.backend` and returns a
`Rig` for the "platform" (force calibration) or "gripper" (manipulation) setup.
"""

from __future__ import annotations

from hardware.interfaces import DeviceError, Rig


def build_rig(cfg, setup: str) -> Rig:
    """The rig for `setup` on the configured backend.

    cfg: the composed app config (DictConfig with `hardware`, `skin`, `sim` nodes) or any object
    with those attributes already typed. Config errors raise ConfigError naming the key; a
    backend whose drivers are not in this build raises DeviceError (never a silent fallback).
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
        raise DeviceError(f"hardware={backend}: the {backend} drivers (UR5e/RTDE, Hand-E, Net F/T, serial "
                          "boards, camera) are not in this build yet; run with hardware=sim")
    raise DeviceError(f"hardware.backend={backend!r}: unknown backend; choose sim, lab or loopback")
