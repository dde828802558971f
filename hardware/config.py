"""The `hardware` config group: which backend runs the devices, and where the real ones are.

`hardware=sim` (default) runs the simulated twins; its device parameters live with the
simulator under `sim.rig`. `hardware=lab` points the real drivers at the bench (IP addresses,
serial ports); `hardware=loopback` points the same drivers at local emulators (ports).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

from hydra.core.config_store import ConfigStore

from layerskin_exp.config import require

BACKENDS = ("sim", "lab", "loopback")


def _check_backend(backend: str, expected: str) -> None:
    require(backend in BACKENDS, "hardware.backend", backend, f"unknown backend; choose one of {list(BACKENDS)}")
    require(backend == expected, "hardware.backend", backend,
            f"this is the {expected!r} schema; select the backend with hardware={backend}, not by overriding the key")


def _check_host(key: str, host: str) -> None:
    require(isinstance(host, str) and host.strip() != "", key, host, "must be a host name or IP address")


def _check_nice(nice) -> None:
    from hardware.priority import NICE_RANGE

    lo, hi = NICE_RANGE
    require(nice is None or (isinstance(nice, int) and lo <= nice <= hi), "hardware.nice", nice,
            f"must be a niceness {lo}..{hi} (lower runs first) or null to leave the priority as started")


@dataclass
class SimHardwareConfig:
    """Simulated devices on a virtual clock (parameters under `sim.rig`)."""

    backend: str = "sim"

    def __post_init__(self) -> None:
        _check_backend(self.backend, "sim")


def _device_configs():
    from hardware.camera.config import CameraConfig
    from hardware.hande.config import HandEConfig
    from hardware.netft.config import NetFTConfig
    from hardware.platform.config import GrblPlatformConfig
    from hardware.skin_board.config import SkinBoardConfig
    from hardware.ur5e.config import UR5eConfig

    return SkinBoardConfig, GrblPlatformConfig, NetFTConfig, UR5eConfig, HandEConfig, CameraConfig


(_Skin, _Platform, _NetFT, _UR5e, _HandE, _Camera) = _device_configs()


@dataclass
class LabHardwareConfig:
    """The bench: one node per device, each the config of its driver (`hardware/<device>/config.py`).

    skin_board: readout board on a serial port; platform: GRBL stage on a serial port; netft:
    the Mini40's Net F/T box (UDP RDT); ur5e: the arm's controller (ur_rtde); hande: the Hand-E
    through the URCap socket; camera: the D435 (OpenCV capture) with its intrinsics.
    nice: the niceness the bench's process (drivers, watchdog, protocol loop) runs at, raised
    where the OS allows it (hardware.priority); null leaves it as started.
    """

    backend: str = "lab"
    nice: Optional[int] = -10  # noqa: UP045 - OmegaConf reads typing.Optional, not `int | None`
    skin_board: _Skin = field(default_factory=_Skin)
    platform: _Platform = field(default_factory=_Platform)
    netft: _NetFT = field(default_factory=_NetFT)
    ur5e: _UR5e = field(default_factory=_UR5e)
    hande: _HandE = field(default_factory=_HandE)
    camera: _Camera = field(default_factory=_Camera)

    def __post_init__(self) -> None:
        _check_backend(self.backend, "lab")
        _check_nice(self.nice)


@dataclass
class LoopbackHardwareConfig(LabHardwareConfig):
    """The real drivers against local emulators of the devices, backed by the simulated world.

    The device nodes configure the drivers as on the bench; their addresses are replaced by the
    emulators' (pty paths, loopback ports). host: where the TCP/UDP emulators listen. ur_host:
    the UR5e emulator's address ("auto": the first 127.0.0.N whose controller ports are free; a
    UR controller's ports are fixed). faults: device -> emulator fault-injection arguments, e.g.
    `+hardware.faults.skin_board.stalls=[[1.0,200]]`. world_period_s: how often the world is
    advanced to wall time. Fault names and values are checked against what each emulator
    declares (`fault_parameters`, `check_faults`) when the config is validated.
    """

    backend: str = "loopback"
    host: str = "127.0.0.1"
    ur_host: str = "auto"
    faults: dict[str, Any] = field(default_factory=dict)
    world_period_s: float = 0.002

    def __post_init__(self) -> None:
        _check_backend(self.backend, "loopback")
        _check_nice(self.nice)
        _check_host("hardware.host", self.host)
        require(self.host.startswith("127.") or self.host in ("localhost", "::1"), "hardware.host", self.host,
                "emulators listen on loopback addresses only (127.x.y.z)")
        require(self.ur_host == "auto" or self.ur_host.startswith("127."), "hardware.ur_host", self.ur_host,
                "must be 'auto' or a loopback address 127.x.y.z")
        require(0 < self.world_period_s <= 0.01, "hardware.world_period_s", self.world_period_s,
                "must be in (0, 0.01] s")
        check_faults(self.faults)


# Emulator constructor arguments the bench sets itself, never a fault to inject.
_BENCH_ARGS = ("self", "rt", "host", "port")
# A bench-level fault any device takes: it stops delivering this many seconds after power-on.
BENCH_FAULTS = {"stall_after_s": None}


def fault_parameters(device: str) -> dict:
    """name -> default of the fault-injection arguments the `device` emulator declares (its
    constructor's keyword arguments, as each emulator documents them), plus BENCH_FAULTS."""
    import inspect

    from hardware.loopback import emulator_class

    params = inspect.signature(emulator_class(device).__init__).parameters.values()
    declared = {p.name: p.default for p in params
                if p.name not in _BENCH_ARGS and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    return {**declared, **BENCH_FAULTS}


def _check_fault_value(key: str, name: str, value, default) -> None:
    """The value's type follows the declared default; numbers are finite and >= 0 (> 0 where the
    default is > 0: periods, rates, sizes), `p_*` are probabilities, `stalls` are [at_s, ms] pairs."""
    import math

    if isinstance(default, bool):
        require(isinstance(value, bool), key, value, "must be true or false")
        return
    if isinstance(default, tuple | list):
        ok = isinstance(value, list | tuple) and all(
            isinstance(item, list | tuple) and len(item) == 2 and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v >= 0 for v in item)
            for item in value)
        require(ok, key, value, "must be a list of [at_s, duration_ms] pairs of finite numbers >= 0")
        return
    kind = "an integer" if isinstance(default, int) and not isinstance(default, float) else "a number"
    ok = isinstance(value, int) if kind == "an integer" else isinstance(value, int | float)
    ok = ok and not isinstance(value, bool) and math.isfinite(value)
    if name.startswith("p_"):
        require(ok and 0.0 <= value <= 1.0, key, value, "must be a probability in [0, 1]")
    elif isinstance(default, int | float) and default > 0:
        require(ok and value > 0, key, value, f"must be {kind} > 0")
    else:
        require(ok and value >= 0, key, value, f"must be {kind} >= 0 (finite)")


def check_faults(faults: dict) -> None:
    """Refuse a fault-injection setting the emulators do not declare, or a value out of range
    (ConfigError naming hardware.faults.<device>.<name>), before any emulator starts."""
    from hardware.loopback import EMULATORS

    for device, args in faults.items():
        require(device in EMULATORS, f"hardware.faults.{device}", args,
                f"no such emulator; choose among {list(EMULATORS)}")
        require(isinstance(args, dict), f"hardware.faults.{device}", args,
                "must map fault names to values, e.g. +hardware.faults.skin_board.p_bit_flip=0.001")
        declared = fault_parameters(device)
        for name, value in args.items():
            key = f"hardware.faults.{device}.{name}"
            require(name in declared, key, value, f"the {device} emulator has no such setting; choose among "
                    f"{sorted(declared)}")
            _check_fault_value(key, name, value, declared[name])


def _store() -> None:
    cs = ConfigStore.instance()
    cs.store(group="hardware", name="sim_schema", node=SimHardwareConfig)
    cs.store(group="hardware", name="lab_schema", node=LabHardwareConfig)
    cs.store(group="hardware", name="loopback_schema", node=LoopbackHardwareConfig)


_store()
