"""The emulated skin readout board's own process: its scan clock, its serial line, its faults.

Run as `python -m hardware.skin_board.board FD OPTIONS_JSON`, started by `SkinBoardEmulator`,
for the reason a real board is another machine: a board never waits for the host. In the trial's
interpreter the board's stream thread, and the world that makes its frames, starved on a busy
host (50-880 ms behind wall time at load 4-7 on 2 cores), and the driver rightly saw a silent
board. Here the board scans on its own clock: frame k is made at t0 + k * frame_period (board
time, wire sequence k + seq_offset), whatever the host or the world does.

The world stays in the parent (one simulated world for every emulator, at wall-clock pace): its
bridge thread drains the skin twin and sends each twin frame over the pipe (FD, a
multiprocessing Connection). At every scan the board takes the oldest twin frame not yet sent
(dropping older ones when more than MAX_BEHIND are waiting, so the board stays on time); when
none has come yet, it sends the newest one again, as a board rescans a sensor whose pressure has
not changed (counted "held"). Faults (the schedule and the random draws) are applied here, per
frame written. The parent gets a read-out (counts, which twin frame each intact board frame
carried) every READOUT_S and its log lines go over the pipe into the run's log.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from collections import Counter, deque
from multiprocessing.connection import Connection

import numpy as np

from hardware.emulation import Pty, TcpSerialLink, serial_link, serve_device
from hardware.skin_board.wire import FRAME_LEN, encode_frame

CORRUPTIONS = ("bit_flip", "drop_byte", "insert_garbage")
MAX_PENDING_BYTES = 512 * FRAME_LEN  # beyond this (the host not reading) whole frames are dropped
MAX_BEHIND = 4  # twin frames waiting beyond this are skipped: the board samples the present
READOUT_S = 0.01


class Board:
    def __init__(self, conn: Connection, *, frame_period_s: float, seq_offset: int, seed: int, p: dict,
                 p_drop_frame: float, garbage_max: int, stalls: list, t0_us: int, link: str = "pty") -> None:
        self.conn = conn
        self.link = link  # "pty" | "tcp" (hardware.emulation.serial_link; frames are never held for a host)
        self.period_s = float(frame_period_s)
        self.seq_offset = int(seq_offset)
        self.rng = np.random.default_rng(seed)
        self.p = p
        self.p_drop_frame = float(p_drop_frame)
        self.garbage_max = int(garbage_max)
        self.stalls = sorted((float(a), float(ms)) for a, ms in stalls)
        self.t0_us = int(t0_us)  # board time of frame 0: the world's time when the board powered on
        self.counts: Counter = Counter()
        self.fault_counts: Counter = Counter()
        self.planned: deque = deque()
        self.waiting: deque = deque()  # (twin seq, superficial, deep) not yet sent
        self.newest = None  # the twin frame sent last (rescanned while none is waiting)
        self.sent: list = []  # (board seq, board µs, twin seq) written intact since the last read-out
        self.stall_until = 0.0
        self.disconnected = False
        self.quit = False
        self.pending = bytearray()

    def log(self, level: int, text: str) -> None:
        self.conn.send(("log", level, text))

    # ---- messages from the parent ----------------------------------------------------------------
    def handle(self, msg: tuple) -> None:
        kind = msg[0]
        if kind == "frames":
            self.waiting.extend(msg[1])
        elif kind == "stall":
            until = math.inf if msg[1] is None else time.monotonic() + msg[1]
            self.stall_until = max(self.stall_until, until)
            self.readout(ack=("stall", True))
        elif kind == "resume":
            self.stall_until = 0.0
            self.readout(ack=("stall", False))
        elif kind == "plan":
            self.planned.extend(msg[1])
            self.readout(ack=("plan", len(self.planned)))
        elif kind == "disconnect":
            self.disconnected = True
        elif kind == "quit":
            self.quit = True

    def readout(self, ack=None) -> None:
        self.conn.send(("info", dict(self.counts), dict(self.fault_counts), len(self.planned), self.sent,
                        time.monotonic() < self.stall_until, self.disconnected, ack))
        self.sent = []

    # ---- the scan loop ------------------------------------------------------------------------------
    def run(self) -> None:
        pty = serial_link(self.link)
        self.conn.send(("ready", pty.path))
        t0 = time.monotonic()
        k, attached, next_readout = 0, False, t0
        while not self.quit:
            while self.conn.poll():
                self.handle(self.conn.recv())
            if self.quit:
                break
            now = time.monotonic()
            if self.disconnected:
                k = int((now - t0) / self.period_s) + 1  # no scans now; the wait below stays a period
                if not pty.closed:
                    self.counts["unplug"] += 1
                    pty.close()
                    self.log(logging.INFO, "the port vanished (disconnect)")
            else:
                while self.stalls and now - t0 >= self.stalls[0][0]:
                    self.stall_until = max(self.stall_until, now + self.stalls.pop(0)[1] * 1e-3)
                due = int((now - t0) / self.period_s)  # scans due by now (a late wake-up catches up)
                while k <= due:
                    attached = self.scan(pty, k, attached)
                    k += 1
                if self.sent:  # the parent learns what a frame carried before the host can read it
                    self.readout()
                    next_readout = now + READOUT_S
                if self.pending:
                    del self.pending[:pty.write(self.pending)]
            if now >= next_readout:
                self.readout()
                next_readout = now + READOUT_S
            wait = t0 + k * self.period_s - time.monotonic()
            self.conn.poll(max(0.0, min(wait, READOUT_S)))
        pty.close()
        self.readout()

    def scan(self, pty: Pty | TcpSerialLink, k: int, attached: bool) -> bool:
        """Scan k: make a frame from the present twin frame and write it, if a host listens."""
        while len(self.waiting) > MAX_BEHIND + 1:
            self.waiting.popleft()
            self.counts["skipped"] += 1
        if self.waiting:
            self.newest = self.waiting.popleft()
        elif self.newest is not None:
            self.counts["held"] += 1
        if self.newest is None:  # nothing sensed yet (the first twin frame on its way)
            return attached
        if not pty.host_attached():
            if attached:  # the host closed the port: what it left unread is gone
                pty.forget_unread()
                self.pending.clear()
            self.counts["no_host_frames"] += 1
            return False
        if not attached:
            self.counts["host_opens"] += 1
        self.counts["host_bytes"] += len(pty.read())  # the board takes no commands: discarded
        if time.monotonic() < self.stall_until:  # the board stops scanning
            self.counts["stalled_frames"] += 1
            return True
        self.queue(k)
        return True

    def next_fault(self):
        if self.planned:
            fault = self.planned.popleft()
        else:
            fault = None
            for how in CORRUPTIONS:
                p = self.p[how]
                if p > 0 and self.rng.random() < p:
                    fault = ("corrupt", how)
                    break
            if fault is None and self.p_drop_frame > 0 and self.rng.random() < self.p_drop_frame:
                fault = ("drop", None)
        if fault is not None:
            self.fault_counts[fault[0]] += 1
        return fault

    def queue(self, k: int) -> None:
        if len(self.pending) > MAX_PENDING_BYTES:
            self.counts["overflow_frames"] += 1  # the host does not read the port: the board's buffer is full
            return
        fault = self.next_fault()
        if fault is not None and fault[0] == "drop":
            self.counts["drop_frame"] += 1
            return
        how = None if fault is None else fault[1]
        twin_seq, sup, deep = self.newest
        t_us = self.t0_us + int(round(k * self.period_s * 1e6))
        data = bytearray(encode_frame(k + self.seq_offset, t_us, sup, deep))
        if how == "bit_flip":
            bit = int(self.rng.integers(FRAME_LEN * 8))
            data[bit // 8] ^= 1 << (bit % 8)
        elif how == "drop_byte":
            del data[int(self.rng.integers(FRAME_LEN))]
        elif how == "insert_garbage":
            n = int(self.rng.integers(1, self.garbage_max + 1))
            data[:0] = self.rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        if how is None or how == "insert_garbage":
            self.sent.append((k, t_us, twin_seq))  # the frame itself is intact
        if how is not None:
            self.counts[how] += 1
        self.counts["frames"] += 1
        self.pending += data


def main(argv: list[str]) -> int:
    return serve_device(Board, argv, (EOFError, OSError))  # (a pty error: the board powers off too)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
