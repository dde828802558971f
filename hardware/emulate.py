"""`python -m hardware.emulate DEVICE [--host H] [--port N] [sim.key=value ...]`: one device's
emulator, standalone, for developing against the wire protocol without the bench.

DEVICE is one of skin_board, platform, netft, ur5e, hande, camera. The emulator is backed by a
simulated rig (the platform setup for skin_board/platform/netft, the gripper setup for
ur5e/hande/camera) advanced at wall-clock pace; `sim.*` and `skin.*` overrides shape it as on
`hardware=sim`. Once it is ready it prints one line saying where it listens (host:port, or the
pty path to open as a serial port), then serves until Ctrl-C or SIGTERM. It binds loopback
unless --host says otherwise.

Network devices listen on their usual ports, so a client that hard-codes them finds the
emulator: Net F/T RDT on UDP 49152 and its calibration page (netftapi2.xml) on HTTP 80 (8080
where binding port 80 is not allowed: the line printed says which), the Hand-E URCap socket on
TCP 63352, the UR5e controller on its fixed ports. --port moves the main one.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import signal
import sys
import threading

from hardware.interfaces import DeviceError
from hardware.loopback import EMULATORS, emulator_class


def _setup_of(device: str) -> str:
    return importlib.import_module(EMULATORS[device][0]).EMULATOR_SETUP


def _compose(setup: str, overrides: list[str]):
    import layerskin_exp.sim.config  # noqa: F401 - stores the sim, skin and world schemas
    from layerskin_exp.cli import refuse
    from layerskin_exp.config import ConfigError, compose

    bad = [o for o in overrides if not o.lstrip("+~").startswith(("sim.", "skin."))]
    if bad:
        refuse(ConfigError(f"{bad[0]}: only sim.* and skin.* overrides shape an emulator's world"))
    try:
        world = compose("world", overrides)
    except ConfigError as e:
        refuse(e)
    return world.sim, world.skin


def _start(emulator, cls) -> str:
    """Start the emulator; where a usual port below 1024 is not allowed, its documented fallback."""
    try:
        where = emulator.start()
    except PermissionError:
        fallback = getattr(sys.modules[cls.__module__], "HTTP_FALLBACK_PORT", None)
        if fallback is None or getattr(emulator, "http_port", None) != 80:
            raise
        emulator.http_port = fallback
        where = emulator.start()
    http = getattr(emulator, "http_address", None)
    return where if http is None else f"{where} (calibration page http://{http}/netftapi2.xml)"


def _host(value: str) -> str:
    from layerskin_exp.config import host_problem

    problem = host_problem(value)
    if problem is not None:
        raise argparse.ArgumentTypeError(f"{value!r} {problem}")
    return value


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m hardware.emulate", description=__doc__.split("\n\n")[0])
    parser.add_argument("device", choices=sorted(EMULATORS))
    parser.add_argument("--host", default="127.0.0.1", type=_host,
                        help="address to listen on: an IP address or a host name (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=None,
                        help="port for TCP/UDP emulators (default: the device's usual port: netft 49152 with "
                             "its calibration page on HTTP 80, hande 63352; ur5e uses the controller's fixed ports)")
    parser.add_argument("overrides", nargs="*", help="sim.* / skin.* overrides for the simulated rig")
    args = parser.parse_args(argv)

    from hardware.sim.realtime import RealtimeWorld

    setup = _setup_of(args.device)
    sim_cfg, skin_cfg = _compose(setup, args.overrides)
    rt = RealtimeWorld.from_config(sim_cfg, skin_cfg, setup)
    cls = emulator_class(args.device)
    kwargs = {"host": args.host, **getattr(cls, "USUAL_PORTS", {})}
    if args.port is not None:
        kwargs["port"] = args.port
    emulator = cls(rt, **kwargs)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    rt.start()
    try:
        try:
            where = _start(emulator, cls)
        except (OSError, DeviceError) as e:  # an address this machine has not, a port in use
            print(f"error: {args.device} emulator cannot listen on --host {args.host}: {e}", file=sys.stderr)
            return 1
        gc.freeze()  # keep full collections (which stop every thread) short while serving
        print(f"{args.device} emulator listening on {where} (simulated {setup} rig, seed {sim_cfg.seed}); "
              "Ctrl-C to stop", flush=True)
        while not done.wait(0.2):
            if rt.error is not None:
                print(f"error: the simulated world stopped: {rt.error!r}", file=sys.stderr)
                return 1
    except KeyboardInterrupt:
        pass
    finally:
        emulator.stop()
        rt.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
