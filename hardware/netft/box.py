"""The emulated Net F/T box's own process: its RDT socket, its sample clock, its faults.

Run as `python -m hardware.netft.box FD OPTIONS_JSON`, started by `NetFTEmulator`, for the reason
a real box is another machine: it never waits for the host (in the trial's interpreter its thread,
and the world that makes its samples, starved on a busy host). Here the box samples on its own
clock: sample k at the world's power-on time + k / twin rate, its ft_sequence that time at
ft_sample_rate_hz, whatever the host or the world does.

The world (and the box's web server) stays in the parent: its bridge thread drains the F/T twin,
turns each sample into counts of the active calibration and sends them over the pipe (FD, a
multiprocessing Connection) with the settings that may change while running (RDT decimation and
buffer size, status word, drop_every). At each tick the box takes the oldest sample not yet used
(skipping those more than MAX_BEHIND old), or holds the newest while none has come, and streams
as the RDT protocol says (see `hardware.netft.emulator`). Faults are applied here, per record.
"""

from __future__ import annotations

import logging
import math
import socket
import sys
import time
from collections import Counter, deque
from multiprocessing.connection import Connection

import numpy as np

from hardware.emulation import serve_device
from hardware.netft import wire

BIAS_SAMPLES = 32  # the software bias takes the mean of the latest readings, as the twin's tare does
MAX_BEHIND = 4
READOUT_S = 0.01


class Box:
    def __init__(self, conn: Connection, *, host: str, port: int, twin_rate_hz: float, ft_sample_rate_hz: float,
                 t0_s: float, settings: list) -> None:
        self.conn = conn
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.sock.setblocking(False)
        self.period_s = 1.0 / float(twin_rate_hz)
        self.ft_rate = float(ft_sample_rate_hz)
        self.t0_s = float(t0_s)
        self.decimation, self.records_per_packet, self.status, self.drop_every = settings
        self.waiting: deque = deque()
        self.newest = None
        self.recent_raw: deque = deque(maxlen=BIAS_SAMPLES)
        self.bias = np.zeros(6, np.int64)
        self.counts: Counter = Counter()
        self.fault_counts: Counter = Counter()
        self.planned: deque = deque()
        self.requests: list = []
        self.stall_until = 0.0
        self.disconnected = False
        self.quit = False
        self.client = None
        self.mode: int | None = None
        self.count = self.rdt = self.made = self.taken = 0
        self.pending: list[bytes] = []

    def log(self, level: int, text: str) -> None:
        self.conn.send(("log", level, text))

    def readout(self, ack=None) -> None:
        self.conn.send(("info", dict(self.counts), dict(self.fault_counts), len(self.planned), self.requests,
                        time.monotonic() < self.stall_until, self.disconnected, self.bias.tolist(), ack))
        self.requests = []

    def handle(self, msg: tuple) -> None:
        kind = msg[0]
        if kind == "samples":
            self.waiting.extend(msg[1])
            self.decimation, self.records_per_packet, self.status, self.drop_every = msg[2]
        elif kind == "settings":
            self.decimation, self.records_per_packet, self.status, self.drop_every = msg[1]
            self.readout(ack=("settings", True))
        elif kind == "stall":
            self.stall_until = max(self.stall_until, math.inf if msg[1] is None else time.monotonic() + msg[1])
            self.readout(ack=("stall", True))
        elif kind == "resume":
            self.stall_until = 0.0
            self.readout(ack=("stall", False))
        elif kind == "plan":
            self.planned.extend(tuple(e) if e is not None else None for e in msg[1])
            self.readout(ack=("plan", len(self.planned)))
        elif kind == "disconnect":
            self.disconnected = True
        elif kind == "quit":
            self.quit = True

    def run(self) -> None:
        self.conn.send(("ready", self.sock.getsockname()[1]))
        start = time.monotonic()
        k, next_readout = 0, start
        while not self.quit:
            while self.conn.poll():
                self.handle(self.conn.recv())
            if self.quit:
                break
            now = time.monotonic()
            if self.disconnected:
                k = int((now - start) / self.period_s) + 1  # no ticks now; the wait below stays a period
                if self.sock.fileno() >= 0:
                    self.sock.close()  # off the network: no requests, no records
                    self.log(logging.INFO, "left the network (disconnect)")
            else:
                self.take_requests()
                due = int((now - start) / self.period_s)
                while k <= due:
                    self.tick(k)
                    k += 1
                if self.mode == wire.CMD_START_BUFFERED and self.pending:
                    self.flush(force=False)
            if now >= next_readout:
                self.readout()
                next_readout = now + READOUT_S
            wait = start + k * self.period_s - time.monotonic()
            self.conn.poll(max(0.0, min(wait, READOUT_S)))
        self.sock.close()
        self.readout()

    def take_requests(self) -> None:
        while True:
            try:
                data, addr = self.sock.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                self.log(logging.DEBUG, f"{exc}")  # e.g. a client gone (ICMP unreachable)
                continue
            try:
                command, count = wire.decode_request(data)
            except wire.RDTError as exc:
                self.log(logging.WARNING, f"ignored request from {addr}: {exc}")
                continue
            self.requests.append((command, count))
            if command in (wire.CMD_START_REALTIME, wire.CMD_START_BUFFERED):
                self.client, self.mode, self.count = addr, command, count
                self.rdt = self.made = self.taken = 0
                self.pending = []
            elif command == wire.CMD_STOP:
                if addr == self.client:
                    self.mode = None
            elif command == wire.CMD_BIAS:
                if self.recent_raw:
                    self.bias = np.rint(np.mean(self.recent_raw, axis=0)).astype(np.int64)
            elif command != wire.CMD_RESET_LATCH:
                self.log(logging.WARNING, f"unknown command 0x{command:04x} from {addr}")

    def next_fault(self):
        if not self.planned:
            return None
        fault = self.planned.popleft()
        if fault is not None:
            self.fault_counts[fault[0]] += 1
        return fault

    def tick(self, k: int) -> None:
        while len(self.waiting) > MAX_BEHIND + 1:
            self.waiting.popleft()
            self.counts["skipped"] += 1
        if self.waiting:
            self.newest = np.asarray(self.waiting.popleft(), np.int64)
            self.recent_raw.append(self.newest)
        elif self.newest is not None:
            self.counts["held"] += 1
        if self.newest is None or self.mode is None:
            return
        stalled = time.monotonic() < self.stall_until
        self.taken += 1
        if (self.taken - 1) % self.decimation:
            return  # between two records at the RDT output rate
        self.made += 1
        self.rdt += 1
        ft_seq = int(round((self.t0_s + k * self.period_s) * self.ft_rate)) & 0xFFFFFFFF
        counts = np.clip(self.newest - self.bias, -(1 << 31), (1 << 31) - 1).tolist()
        record = wire.encode_record(self.rdt, ft_seq, self.status, counts)
        dropped = self.drop_every > 0 and self.made % self.drop_every == 0
        fault = None if dropped or stalled else self.next_fault()
        if fault is not None and fault[0] == "corrupt":
            record = record[:-3]  # a short datagram: the client cannot decode it
        if not dropped and not stalled and (fault is None or fault[0] != "drop"):
            if self.mode == wire.CMD_START_BUFFERED:
                self.pending.append(record)
                self.flush(force=False)
            else:
                self.send(record)
        if self.count and self.made >= self.count:  # a counted stream ends after its records
            self.flush(force=True)
            self.mode = None

    def flush(self, force: bool) -> None:
        n = self.records_per_packet
        while len(self.pending) >= n or (force and self.pending):
            chunk, self.pending = self.pending[:n], self.pending[n:]
            self.send(b"".join(chunk))

    def send(self, data: bytes) -> None:
        try:
            self.sock.sendto(data, self.client)
        except OSError as exc:
            self.log(logging.DEBUG, f"send to {self.client} failed: {exc}")


def main(argv: list[str]) -> int:
    return serve_device(Box, argv)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
