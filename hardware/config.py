"""The `hardware` config group: which backend runs the devices, and where the real ones are.

`hardware=sim` (default) runs the simulated twins; its device parameters live with the
simulator under `sim.rig`. `hardware=lab` points the real drivers at the bench (IP addresses,
serial ports); `hardware=loopback` points the same drivers at local emulators (ports).
"""

from __future__ import annotations

from dataclasses import dataclass

from hydra.core.config_store import ConfigStore

from layerskin_exp.config import require

BACKENDS = ("sim", "lab", "loopback")


def _check_backend(backend: str, expected: str) -> None:
    require(backend in BACKENDS, "hardware.backend", backend, f"unknown backend; choose one of {list(BACKENDS)}")
    require(backend == expected, "hardware.backend", backend,
            f"this is the {expected!r} schema; select the backend with hardware={backend}, not by overriding the key")


def _check_port(key: str, port: int) -> None:
    require(isinstance(port, int) and 1 <= port <= 65535, key, port, "must be a TCP/UDP port 1..65535")


def _check_host(key: str, host: str) -> None:
    require(isinstance(host, str) and host.strip() != "", key, host, "must be a host name or IP address")


@dataclass
class SimHardwareConfig:
    """Simulated devices on a virtual clock (parameters under `sim.rig`)."""

    backend: str = "sim"

    def __post_init__(self) -> None:
        _check_backend(self.backend, "sim")


@dataclass
class LabHardwareConfig:
    """The bench: UR5e over RTDE, Hand-E over the URCap socket, Mini40 over Net F/T UDP, serial boards."""

    backend: str = "lab"
    ur_host: str = "192.168.1.10"
    gripper_host: str = "192.168.1.10"  # the URCap socket runs on the robot controller
    gripper_port: int = 63352
    ft_host: str = "192.168.1.1"
    ft_port: int = 49152  # Net F/T RDT
    ft_rate_hz: int = 1000
    skin_serial_port: str = "/dev/ttyACM0"
    skin_baud: int = 2000000
    platform_serial_port: str = "/dev/ttyUSB0"
    platform_baud: int = 115200
    camera_index: int = 0
    connect_timeout_s: float = 5.0

    def __post_init__(self) -> None:
        _check_backend(self.backend, "lab")
        for k in ("ur_host", "gripper_host", "ft_host"):
            _check_host(f"hardware.{k}", getattr(self, k))
        for k in ("gripper_port", "ft_port"):
            _check_port(f"hardware.{k}", getattr(self, k))
        for k in ("skin_serial_port", "platform_serial_port"):
            require(getattr(self, k).strip() != "", f"hardware.{k}", getattr(self, k), "must name a serial device")
        for k in ("skin_baud", "platform_baud"):
            require(getattr(self, k) > 0, f"hardware.{k}", getattr(self, k), "must be > 0 baud")
        require(1 <= self.ft_rate_hz <= 7000, "hardware.ft_rate_hz", self.ft_rate_hz, "Net F/T streams 1..7000 Hz")
        require(self.camera_index >= 0, "hardware.camera_index", self.camera_index, "must be >= 0")
        require(self.connect_timeout_s > 0, "hardware.connect_timeout_s", self.connect_timeout_s, "must be > 0 s")


@dataclass
class LoopbackHardwareConfig:
    """The real drivers against emulators on this machine, backed by the simulated world."""

    backend: str = "loopback"
    host: str = "127.0.0.1"
    rtde_port: int = 30004
    ur_script_port: int = 30002
    gripper_port: int = 63352
    ft_port: int = 49152
    camera_port: int = 50010
    connect_timeout_s: float = 2.0

    def __post_init__(self) -> None:
        _check_backend(self.backend, "loopback")
        _check_host("hardware.host", self.host)
        ports = ("rtde_port", "ur_script_port", "gripper_port", "ft_port", "camera_port")
        for k in ports:
            _check_port(f"hardware.{k}", getattr(self, k))
        values = [getattr(self, k) for k in ports]
        require(len(set(values)) == len(values), "hardware.*_port", values, "each emulator needs its own port")
        require(self.connect_timeout_s > 0, "hardware.connect_timeout_s", self.connect_timeout_s, "must be > 0 s")


HardwareConfig = SimHardwareConfig | LabHardwareConfig | LoopbackHardwareConfig


def _store() -> None:
    cs = ConfigStore.instance()
    cs.store(group="hardware", name="sim_schema", node=SimHardwareConfig)
    cs.store(group="hardware", name="lab_schema", node=LabHardwareConfig)
    cs.store(group="hardware", name="loopback_schema", node=LoopbackHardwareConfig)


_store()
