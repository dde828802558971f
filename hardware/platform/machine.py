"""The emulated GRBL controller's own process: its serial line, its protocol loop, its faults.

Run as `python -m hardware.platform.machine FD OPTIONS_JSON`, started by `GrblEmulator`, for the
reason a real GRBL board is another machine: it answers `?` whatever the host is doing (in the
trial's interpreter its thread starved on a busy host and left polls unanswered past the bound).
The GRBL logic is `hardware.platform.emulator.GrblMachine`, unchanged, driving a `BridgedStage`:
the parent (which keeps the one simulated world) pushes the stage's position and motion every
millisecond over the pipe (FD, a multiprocessing Connection) and applies the moves and stops sent
back, as the UR5e controller's BridgedArm does. The machine's read-out (state, counters) goes to
the parent every 10 ms and when the parent asks (so what it reads after a reply is at least the
state that produced it); log lines go to the parent's log (the run's log).
"""

from __future__ import annotations

import json
import logging
import os
import sys
import threading
from types import SimpleNamespace

import numpy as np

from hardware.emulation import PipeLog, run_as_a_device
from hardware.interfaces import DeviceError


class BridgedStage:
    """The simulated stage as this process sees it. A command counts as moving until the parent
    reports it applied. move_to refuses what the twin would (its travel and speed limits)."""

    def __init__(self, send, cfg: dict, position) -> None:
        self.cfg = SimpleNamespace(**cfg)
        self._send = send
        self.pos = np.asarray(position, float)
        self.moving = False
        self.sent_id = self.applied_id = 0

    def _command(self, *msg) -> None:
        self.sent_id += 1
        self._send((msg[0], self.sent_id, *msg[1:]))

    def move_to(self, target_mm, speed_mm_s: float) -> None:
        target = np.asarray(target_mm, float).reshape(-1)
        lo, hi = np.asarray(self.cfg.workspace_min_mm, float), np.asarray(self.cfg.workspace_max_mm, float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise DeviceError(f"platform: target {target_mm!r} must be three finite values (x, y, z mm)")
        if np.any(target < lo) or np.any(target > hi):
            raise DeviceError(f"platform: target {np.round(target, 4).tolist()} mm is outside the stage's travel "
                              f"{lo.tolist()}..{hi.tolist()} mm")
        self._command("move", target.tolist(), float(speed_mm_s))

    def stop(self) -> None:
        self._command("stop")

    def is_moving(self) -> bool:
        return self.moving or self.applied_id < self.sent_id

    def position_mm(self) -> np.ndarray:
        return self.pos.copy()


def main(argv: list[str]) -> int:
    from multiprocessing.connection import Connection

    from hardware.platform.emulator import GrblMachine

    conn = Connection(int(argv[0]))
    conn.send(("log", logging.INFO, f"device process {os.getpid()}: {run_as_a_device()}"))
    opts = json.loads(argv[1])
    lock = threading.Lock()

    def send(msg) -> None:
        with lock:
            conn.send(msg)

    stage = BridgedStage(send, opts.pop("stage"), opts.pop("position"))
    world = SimpleNamespace(lock=threading.RLock(), rig=SimpleNamespace(platform=stage))
    logging.getLogger("hardware.platform.emulator").addHandler(PipeLog(send))
    logging.getLogger("hardware.platform.emulator").propagate = False
    machine = GrblMachine(world, **opts)

    def readout(ack=None) -> None:
        send(("info", {"state": machine._state, "feed_override": machine._feed_ovr,
                       "rx_overflow_bytes": machine.rx_overflow_bytes, "tx_dropped_bytes": machine.tx_dropped_bytes,
                       "lines_received": machine.lines_received, "status_reports": machine.status_reports,
                       "resets": machine.resets, "fault_counts": dict(machine.fault_counts),
                       "scheduled": machine.scheduled, "stalled": machine.stalled,
                       "error": None if machine.error is None else repr(machine.error)}, ack))

    try:
        send(("ready", machine.start()))
        while True:
            if not conn.poll(0.01):
                readout()
                continue
            msg = conn.recv()
            kind = msg[0]
            if kind == "state":
                stage.pos, stage.moving, stage.applied_id = np.asarray(msg[1], float), msg[2], msg[3]
            elif kind == "stall":
                machine.stall(msg[1])
                readout(("stall", True))
            elif kind == "resume":
                machine.resume()
                readout(("stall", False))
            elif kind == "plan":
                machine.schedule(*[tuple(e) if isinstance(e, list) else e for e in msg[1]])
                readout(("plan", True))
            elif kind == "readout":
                readout(("readout", True))
            elif kind == "disconnect":
                machine.disconnect()
            elif kind == "quit":
                break
    except (EOFError, BrokenPipeError, ConnectionResetError):  # the parent went away: GRBL powers off
        return 0
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which raises it
        try:
            send(("error", f"{type(exc).__name__}: {exc}"))
        except OSError:
            pass
        raise
    finally:
        machine.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
