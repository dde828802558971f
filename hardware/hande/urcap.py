"""The emulated Robotiq URCap's gripper socket in its own process: its socket server, registers, faults.

Run as `python -m hardware.hande.urcap FD OPTIONS_JSON`, started by `HandEEmulator`, for the
reason a real gripper and the controller that serves its socket are another machine: they answer
whatever the host is doing. In the trial's interpreter the socket's threads starved on a busy
host (load 4-7 on 2 cores plus a load generator) and the driver rightly saw a request unanswered
past the bound ("gripper stalled"). The URCap's logic is `hardware.hande.emulator.HandEURCap`,
unchanged, driving a `BridgedGripper`.

World state: the parent keeps the one simulated world (the jaws, the rod, the skin they press),
as the GRBL and UR5e controllers' parents do, and this process holds the state it needs of it:
the parent's bridge sends the jaws' state (the twin's latest reported opening and object flag,
whether the jaws move, the last command applied) when it changes and at least every 10 ms, and
applies the moves and stops sent back. Not the other way (the process asking the world): contact
and grip force come from the world's physics, which advances with the skin and the arm in the
parent; a request answered here must not wait for the parent to be scheduled, so the registers
answer from the latest state received. The gripper's registers, activation clock and faults are
its own and live only here. The read-out (registers, counters, faults) goes to the parent every
10 ms and when it asks; log lines go to the parent's log (the run's log).
"""

from __future__ import annotations

import logging
import sys
import threading
from types import SimpleNamespace

from hardware.emulation import PipeLog, serve_device

READOUT_S = 0.01


class BridgedGripper:
    """The simulated jaws as this process sees them. A command counts as moving until the parent
    reports it applied; the twin's limits are checked where it is (the parent logs a refusal)."""

    def __init__(self, send, cfg: dict, opening_mm: float) -> None:
        self.cfg = SimpleNamespace(**cfg)
        self._send = send
        self.opening_mm = float(opening_mm)
        self.object_detected = False
        self.moving = False
        self.sent_id = self.applied_id = 0

    def _command(self, *msg) -> None:
        self.sent_id += 1
        self._send((msg[0], self.sent_id, *msg[1:]))

    def move(self, opening_mm: float, speed_mm_s: float, force_pct: float) -> None:
        self._command("move", float(opening_mm), float(speed_mm_s), float(force_pct))

    def stop(self) -> None:
        self._command("stop")

    def is_moving(self) -> bool:
        return self.moving or self.applied_id < self.sent_id


class URCapProcess:
    """The URCap's socket server (HandEURCap) on a BridgedGripper, and the pipe to the parent."""

    def __init__(self, conn, *, gripper: dict, opening_mm: float, **options) -> None:
        from hardware.hande.emulator import HandEURCap

        self.conn = conn
        self._send_lock = threading.Lock()  # the serving threads send commands, this loop read-outs
        self.jaws = BridgedGripper(self.send, gripper, opening_mm)
        self.world = SimpleNamespace(lock=threading.RLock(), rig=SimpleNamespace(gripper=self.jaws))
        emu_log = logging.getLogger("hardware.hande.emulator")
        emu_log.addHandler(PipeLog(self.send))
        emu_log.propagate = False
        self.urcap = HandEURCap(self.world, **options)

    def send(self, msg: tuple) -> None:
        with self._send_lock:
            self.conn.send(msg)

    def readout(self, ack=None) -> None:
        u = self.urcap
        with u._regs_lock:
            regs = dict(u.regs)
        self.send(("info", {"regs": regs, "requests": u.requests, "bad_requests": u.bad_requests,
                            "connections": u.connections, "fault_counts": dict(u.fault_counts),
                            "scheduled": u.scheduled, "stalled": u.stalled,
                            "error": None if u.error is None else repr(u.error)}, ack))

    def handle(self, msg: tuple) -> bool:
        """Apply one message from the parent; False once it says quit."""
        kind, u = msg[0], self.urcap
        if kind == "state":
            with self.world.lock:
                j = self.jaws
                j.opening_mm, j.object_detected, j.moving, j.applied_id = float(msg[1]), bool(msg[2]), bool(msg[3]), msg[4]
        elif kind == "stall":
            u.stall(msg[1])
            self.readout(("stall", True))
        elif kind == "resume":
            u.resume()
            self.readout(("stall", False))
        elif kind == "plan":
            u.schedule(*[tuple(e) if isinstance(e, list) else e for e in msg[1]])
            self.readout(("plan", True))
        elif kind == "disconnect":
            u.disconnect()
            self.readout(("disconnect", True))
        elif kind == "set_fault":
            u.set_fault(msg[1])
            self.readout(("set_fault", msg[1]))
        elif kind == "readout":
            self.readout(("readout", True))
        elif kind == "quit":
            return False
        return True

    def run(self) -> None:
        try:
            self.send(("ready", self.urcap.start()))
            while True:
                if not self.conn.poll(READOUT_S):
                    self.readout()
                    continue
                if not self.handle(self.conn.recv()):
                    break
        finally:
            self.urcap.stop()


def main(argv: list[str]) -> int:
    return serve_device(URCapProcess, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
