"""`hardware=loopback`: the real drivers against emulators that speak each device's wire protocol.

The emulators share one simulated world advanced at wall-clock pace in this process
(`hardware.sim.realtime.RealtimeWorld`), so a loopback session carries the simulator's physics
through the real drivers, the real serial framing, UDP and TCP protocols and the `ur_rtde`
client. The devices that serve a link (skin board, GRBL, Net F/T, UR5e controller, Hand-E URCap
socket) run in processes of their own, as the real ones are other machines, and their log lines
come into this process's log; each emulator object here starts its process and bridges it to the
world. The camera's frames reach the driver through a capture object in this process (see
`hardware.camera.emulator`). They listen on loopback addresses and pseudo-terminals only. The
bench is powered on when the rig is built and off when it disconnects.
"""

from __future__ import annotations

import dataclasses
import importlib
import logging
import socket
import threading
from dataclasses import dataclass, field

from hardware.emulation import free_loopback_host
from hardware.interfaces import DeviceError
from hardware.lab import MonotonicClock, attach_devices
from hardware.rig import Rig

log = logging.getLogger(__name__)

# device -> (emulator module, emulator class); the module's EMULATOR_SETUP names its simulated setup
EMULATORS = {
    "skin_board": ("hardware.skin_board.emulator", "SkinBoardEmulator"),
    "platform": ("hardware.platform.emulator", "GrblEmulator"),
    "netft": ("hardware.netft.emulator", "NetFTEmulator"),
    "ur5e": ("hardware.ur5e.emulator", "UR5eEmulator"),
    "hande": ("hardware.hande.emulator", "HandEEmulator"),
    "camera": ("hardware.camera.emulator", "CameraEmulator"),
}
SETUP_DEVICES = {"platform": ("skin_board", "platform", "netft"),
                 "gripper": ("skin_board", "ur5e", "hande", "camera")}
UR_PORTS = (29999, 30001, 30002, 30003, 30004)  # fixed on a UR controller; ur_rtde dials them
# Emulator arguments a loopback bench always uses: the Net F/T box serves its calibration page, so
# the driver reads counts-per-unit over HTTP as it does from a real box; the serial lines (GRBL's,
# the skin board's) are carried over loopback TCP (socket://, as through a serial device server),
# which a busy host does not delay as it delays a pty's kernel worker (hardware.emulation.
# TcpSerialLink says how much: a loaded suite run caught a "skin stalled" 112 ms on a pty).
BENCH_DEFAULTS = {"netft": {"http_port": 0}, "platform": {"link": "tcp"}, "skin_board": {"link": "tcp"}}


def free_ur_host(first: int = 2, last: int = 254) -> str:
    """A loopback address 127.0.0.N on which none of the UR controller's fixed ports is taken
    (so two loopback benches, or a test and a standalone emulator, never collide)."""
    try:
        return free_loopback_host({port: socket.SOCK_STREAM for port in UR_PORTS}, first, last)
    except OSError:
        raise DeviceError("loopback: no free 127.0.0.N address for the UR5e emulator's fixed ports "
                          f"{UR_PORTS}; stop other UR emulators") from None


def emulator_class(device: str):
    module, name = EMULATORS[device]
    return getattr(importlib.import_module(module), name)


class LoopbackBench:
    """The emulators of one setup, on one realtime simulated world.

    faults: device -> keyword arguments for its emulator (fault injection, see each emulator),
    among them `stall_after_s` / `disconnect_after_s` for any device (hardware.emulation): it
    stops delivering / loses its link that long after power-on.
    """

    def __init__(self, sim_cfg, skin_cfg, setup: str, host: str = "127.0.0.1", ur_host: str = "auto",
                 faults: dict | None = None, period_s: float = 0.002) -> None:
        from hardware.sim.realtime import RealtimeWorld

        if setup not in SETUP_DEVICES:
            raise DeviceError(f"loopback: unknown setup {setup!r}; choose one of {tuple(SETUP_DEVICES)}")
        unknown = set(faults or {}) - set(SETUP_DEVICES[setup])
        if unknown:
            raise DeviceError(f"hardware.faults: no emulator {sorted(unknown)} on the {setup} setup; "
                              f"choose among {list(SETUP_DEVICES[setup])}")
        self.setup = setup
        self.host = host
        self.ur_host = ur_host
        self.faults = {k: dict(v) for k, v in (faults or {}).items()}
        self.rt = RealtimeWorld.from_config(sim_cfg, skin_cfg, setup, period_s)
        self.emulators: dict[str, object] = {}
        self.addresses: dict[str, str] = {}

    def start(self) -> dict[str, str]:
        """Start the world and every emulator; returns device -> where it serves."""
        self.rt.start()
        try:
            for device in SETUP_DEVICES[self.setup]:
                cls = emulator_class(device)
                host = (free_ur_host() if self.ur_host == "auto" else self.ur_host) if device == "ur5e" else self.host
                kwargs = {**BENCH_DEFAULTS.get(device, {}), **self.faults.get(device, {})}
                emu = cls(self.rt, host=host, **kwargs)
                self.addresses[device] = emu.start()
                self.emulators[device] = emu
                log.info("loopback: %s emulator at %s", device, self.addresses[device])
        except BaseException:
            self.stop()
            raise
        return dict(self.addresses)

    def stop(self) -> None:
        """Power every emulator off at once (each waits on its own process or threads, none on
        another's: one after another they took 0.25 s of the second SIGTERM allows), then the world."""
        def stop(device: str, emu) -> None:
            try:
                emu.stop()
            except Exception as exc:  # noqa: BLE001 - stop the others
                log.warning("loopback: stopping the %s emulator failed: %s", device, exc)

        self.rt.halt()  # no further advance: an emulator's release of the world waits on none
        stopping = [threading.Thread(target=stop, args=item, name=f"stop-{item[0]}", daemon=True)
                    for item in self.emulators.items()]
        for t in stopping:
            t.start()
        for t in stopping:
            t.join()
        self.emulators.clear()
        self.rt.stop()


def _host_port(address: str) -> tuple[str, int]:
    host, _, port = address.rpartition(":")
    return host, int(port)


def pointed_at(hw, bench: LoopbackBench):
    """The device configs of `hw` with their addresses replaced by the bench's emulators'."""
    changes = {}
    for device, address in bench.addresses.items():
        cfg = getattr(hw, device)
        if device in ("skin_board", "platform"):
            changes[device] = dataclasses.replace(cfg, port=address)
        elif device == "netft":
            host, port = _host_port(address)
            http = bench.emulators[device].http_port
            changes[device] = dataclasses.replace(cfg, host=host, port=port, http_port=http,
                                                  fetch_calibration=http is not None)
        elif device == "hande":
            host, port = _host_port(address)
            changes[device] = dataclasses.replace(cfg, host=host, port=port)
        elif device == "ur5e":
            changes[device] = dataclasses.replace(cfg, host=bench.emulators[device].host)
        elif device == "camera":  # frames come through the emulator's capture_factory
            changes[device] = dataclasses.replace(cfg, source=address)
    return dataclasses.replace(hw, **changes)


@dataclass
class LoopbackRig(Rig):
    """The real drivers on a loopback bench. begin_trial reaches the simulated world (the trial's
    noise and bench variation, as on `sim`); disconnect powers the bench off."""

    bench: LoopbackBench | None = field(default=None, repr=False)

    def begin_trial(self, labels: dict, slot_s: float = 0.0) -> None:
        if self.bench is not None:
            self.bench.rt.begin_trial(labels)

    def disconnect(self) -> None:
        try:
            super().disconnect()
        finally:
            if self.bench is not None:
                self.bench.stop()
                self.bench = None


def build_loopback_rig(hw, sim_cfg, skin_cfg, setup: str) -> LoopbackRig:
    """Power on the emulators of `setup` and build the real drivers pointed at them.

    hw: LoopbackHardwareConfig (device driver settings, loopback host, faults).
    """
    bench = LoopbackBench(sim_cfg, skin_cfg, setup, hw.host, hw.ur_host, hw.faults, hw.world_period_s)
    bench.start()
    try:
        rig = LoopbackRig(backend="loopback", clock=MonotonicClock(), skin=None, bench=bench)
        camera = bench.emulators.get("camera")
        return attach_devices(rig, pointed_at(hw, bench), skin_cfg, setup,
                              capture_factory=None if camera is None else camera.capture_factory)
    except BaseException:
        bench.stop()
        raise
