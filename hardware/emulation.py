"""What the six device emulators share: life cycle, serving, and one fault vocabulary.

Life cycle: `start()` opens what the emulator serves (`_open`, returning where a driver reaches
it: a pty path, host:port, a capture name), then starts the threads `_open` registered with
`_spawn`; `stop()` stops them, joins them and closes everything (`_close`); both are idempotent
and the emulator is a context manager. A thread that fails leaves its exception in `error`.

Each emulator names the simulated twins whose streams it drains (`TWINS`); the RealtimeWorld
discards the received records of every other twin, so an emulator run on its own does not
queue the streams of the devices it does not serve.

Faults, the same four words for every device (a device names the ones it can show in `FAULTS`):
  stall(duration_s=None)  stop delivering while the link stays up (None: until resume())
  drop(n=1)               the next n outgoing messages (frames, records, replies, images) are lost
  corrupt(n=1, how=None)  the next n outgoing messages arrive damaged (`how`: the device's ways,
                          CORRUPTIONS; None: its first)
  disconnect()            the link goes: a pty closes (the port vanishes), TCP connections close,
                          a UDP box stops answering, a camera's capture ends
`schedule(*entries)` is the general form of drop/corrupt: one entry per outgoing message, "drop",
"corrupt", ("corrupt", how) or None (intact). Two keyword arguments every emulator takes put a
fault on a timer from start(): `stall_after_s`, `disconnect_after_s`.

Serving helpers: `Pty` (a raw pseudo-terminal that knows whether a host has it open), and
`free_loopback_host` (an address 127.0.0.N on which a device's usual ports are free).

Device processes (an emulated device in a process of its own): `DeviceProcess` (the parent's side:
the process and the pipe to it), `serve_device` (the child's entry) and `PipeLog` (the child's log
records sent to the parent, which logs them into the run's log).
"""

from __future__ import annotations

import logging
import math
import os
import queue
import select
import socket
import termios
import threading
import time
import tty
from collections import Counter, deque

FAULTS = ("stall", "drop", "corrupt", "disconnect")


def _check_delay(name: str, value) -> float | None:
    if value is None:
        return None
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name}={value!r}: must be a finite number of seconds >= 0")
    return value


class Emulator:
    """Base of the device emulators. rt: the started RealtimeWorld the emulator is backed by."""

    DEVICE = "device"  # name in messages
    TWINS: tuple[str, ...] = ()  # twins (rig attributes) whose streams this emulator drains
    FAULTS: tuple[str, ...] = FAULTS  # the faults this device can show
    CORRUPTIONS: tuple[str, ...] = ("garbled",)  # ways a message is corrupted, the default first

    def __init__(self, rt, *, stall_after_s: float | None = None, disconnect_after_s: float | None = None) -> None:
        self.rt = rt
        self.stall_after_s = _check_delay("stall_after_s", stall_after_s)
        self.disconnect_after_s = _check_delay("disconnect_after_s", disconnect_after_s)
        self.where: str | None = None
        self.error: BaseException | None = None
        self.fault_counts: Counter = Counter()  # faults applied, by kind
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._timers: list[threading.Timer] = []
        self._started = False
        self._fault_lock = threading.Lock()
        self._planned: deque = deque()  # (kind, how) or None, one per outgoing message
        self._stall_until = 0.0  # monotonic s; inf: until resume()
        self._disconnected = threading.Event()

    # ---- life cycle ------------------------------------------------------------------------
    def start(self) -> str:
        """Open and start serving; returns where a driver reaches the device."""
        if self._started:
            return self.where
        self._stop.clear()
        self._disconnected.clear()
        try:
            self.where = self._open()
        except BaseException:
            self._threads = []
            self._close()
            raise
        self._started = True
        claim = getattr(self.rt, "claim", None)
        if claim is not None:
            claim(self, self.TWINS)
        for t in self._threads:
            if t.ident is None:  # (_open may have needed one running already)
                t.start()
        for delay, fault in ((self.stall_after_s, self.stall), (self.disconnect_after_s, self.disconnect)):
            if delay == 0:  # from the start: in force before a driver can connect, not raced by a timer
                fault()
            elif delay is not None:
                timer = threading.Timer(delay, fault)
                timer.daemon = True
                timer.start()
                self._timers.append(timer)
        return self.where

    def stop(self) -> None:
        if not self._started:
            return
        self._stop.set()
        for timer in self._timers:
            timer.cancel()
        self._timers = []
        self._wake()
        for t in self._threads:
            t.join(timeout=5.0)
        self._threads = []
        self._close()
        release = getattr(self.rt, "release", None)
        if release is not None:
            release(self)
        self._started = False

    @property
    def running(self) -> bool:
        return self._started and not self._stop.is_set()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _spawn(self, target, name: str, *args) -> threading.Thread:
        """A daemon thread started with the emulator (or at once when it is already running);
        an exception it raises is kept in `error`."""

        def body() -> None:
            try:
                target(*args)
            except BaseException as exc:  # noqa: BLE001 - reported to the test or the CLI through `error`
                if not self._stop.is_set():
                    self.error = exc

        t = threading.Thread(target=body, name=f"{self.DEVICE}-emu-{name}", daemon=True)
        self._threads.append(t)
        if self._started:
            t.start()
        return t

    # What a subclass provides.
    def _open(self) -> str:
        raise NotImplementedError

    def _close(self) -> None:
        """Release what _open took (called once the threads have stopped, or after _open failed)."""

    def _wake(self) -> None:
        """Unblock the threads so they see the stop (optional)."""

    # ---- faults ------------------------------------------------------------------------------
    def _require(self, kind: str) -> None:
        if kind not in self.FAULTS:
            raise ValueError(f"{self.DEVICE} emulator: fault {kind!r} is not modelled; "
                             f"this device shows {self.FAULTS}")

    def stall(self, duration_s: float | None = None) -> None:
        """Deliver nothing for duration_s from now (None: until resume()); the link stays up."""
        self._require("stall")
        until = math.inf if duration_s is None else time.monotonic() + float(duration_s)
        self._stall_until = max(self._stall_until, until)
        self.fault_counts["stall"] += 1
        self._on_stall(True)

    def resume(self) -> None:
        """End a stall."""
        self._stall_until = 0.0
        self._on_stall(False)

    # ---- a device in its own process -----------------------------------------------------------
    # An emulator whose device runs in a DeviceProcess returns it from _device(); the fault
    # schedule then goes to that process, and the process's read-out (self._info, kept by the
    # emulator's bridge) answers `scheduled` (under SCHEDULED_KEY) and `stalled`.
    SCHEDULED_KEY = "scheduled"

    def _device(self) -> DeviceProcess | None:
        return None

    def _serve_device(self, device: DeviceProcess, timeout_s: float = 20.0) -> str:
        """Once `_open` has started the device's process (kept where `_device()` and the bridge
        find it): start the bridge (`self._bridge`, which carries the process's "ready"), wait
        until the process serves, and hand it the drop/corrupt faults scheduled before start.
        Returns where it serves. If it does not start, the bridge is stopped and DeviceError raised."""
        self._spawn(self._bridge, "bridge").start()
        try:
            device.wait_ready(timeout_s)
        except BaseException:  # DeviceError, or a stop while waiting: the bridge goes too
            self._stop.set()
            for t in self._threads:
                t.join(timeout=2.0)
            raise
        with self._fault_lock:
            planned, self._planned = list(self._planned), deque()
        if planned:
            self._plan(planned)
        return device.where

    def _plan(self, planned: list) -> None:
        device = self._device()
        device.send(("plan", planned))
        device.wait_ack("plan", lambda v: True)

    @property
    def stalled(self) -> bool:
        if self._device() is not None:
            return bool(self._info.get("stalled"))
        return time.monotonic() < self._stall_until

    def drop(self, n: int = 1) -> None:
        """The next n outgoing messages are lost."""
        self.schedule(*["drop"] * int(n))

    def corrupt(self, n: int = 1, how: str | None = None) -> None:
        """The next n outgoing messages arrive damaged (how: one of CORRUPTIONS)."""
        self.schedule(*[("corrupt", how)] * int(n))

    def schedule(self, *entries) -> None:
        """One entry per next outgoing message: "drop", "corrupt", ("corrupt", how) or None."""
        plan = []
        for e in entries:
            if e is None:
                plan.append(None)
                continue
            kind, how = (e, None) if isinstance(e, str) else e
            if kind not in ("drop", "corrupt"):
                raise ValueError(f"{self.DEVICE} emulator: schedule entry {e!r}: use 'drop', 'corrupt', "
                                 "('corrupt', how) or None")
            self._require(kind)
            if kind == "corrupt":
                how = how or self.CORRUPTIONS[0]
                if how not in self.CORRUPTIONS:
                    raise ValueError(f"{self.DEVICE} emulator: corruption {how!r}: choose one of {self.CORRUPTIONS}")
            plan.append((kind, how))
        with self._fault_lock:
            self._planned.extend(plan)
        if self._device() is not None:  # the device applies its own schedule
            with self._fault_lock:
                planned, self._planned = list(self._planned), deque()
            self._plan(planned)

    @property
    def scheduled(self) -> int:
        """Entries of the drop/corrupt schedule not yet applied."""
        if self._device() is not None:
            return int(self._info.get(self.SCHEDULED_KEY, 0))
        with self._fault_lock:
            return len(self._planned)

    def _next_fault(self) -> tuple[str, str | None] | None:
        """What happens to the next outgoing message: None (intact), ("drop", None) or
        ("corrupt", how); the schedule first, then the emulator's own random draw."""
        with self._fault_lock:
            if self._planned:
                fault = self._planned.popleft()
                if fault is not None:
                    self.fault_counts[fault[0]] += 1
                return fault
        fault = self._draw_fault()
        if fault is not None:
            self.fault_counts[fault[0]] += 1
        return fault

    def _draw_fault(self) -> tuple[str, str | None] | None:
        """A random fault for the next message (emulators with fault probabilities override)."""
        return None

    def disconnect(self) -> None:
        """The link goes (see the module docstring for what that is on each kind of link)."""
        self._require("disconnect")
        self.fault_counts["disconnect"] += 1
        self._disconnected.set()
        self._on_disconnect()

    @property
    def disconnected(self) -> bool:
        return self._disconnected.is_set()

    def _on_stall(self, stalled: bool) -> None:
        """Hook for emulators whose stall is carried out elsewhere (another process)."""

    def _on_disconnect(self) -> None:
        """Hook: carry out the disconnect (or leave it to the serving thread, which polls
        `disconnected`)."""


class Pty:
    """A raw pseudo-terminal: the emulator holds the master, a driver opens `path`.

    hold_slave: keep a slave descriptor open (the master then never sees a hang-up, and bytes
    written while no host has the port open wait in the pty for the next one). Without it,
    `host_attached()` says whether a host has the port open, and `forget_unread()` discards what
    a host left unread, as a USB CDC device's host side does when the port closes.
    """

    def __init__(self, hold_slave: bool = False) -> None:
        self.master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line discipline: bytes pass unchanged
        tty.setraw(self.master)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(slave)
        self.slave: int | None = slave
        if not hold_slave:
            os.close(slave)
            self.slave = None
        self._poll = select.poll()
        self._poll.register(self.master, select.POLLIN | select.POLLHUP)

    @property
    def closed(self) -> bool:
        return self.master < 0

    def host_attached(self) -> bool:
        if self.master < 0:
            return False
        return not any(ev & select.POLLHUP for _, ev in self._poll.poll(0))

    def forget_unread(self) -> None:
        """Discard bytes written to the host that no host read (the port is closed now)."""
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return
        try:
            termios.tcflush(fd, termios.TCIFLUSH)
        finally:
            os.close(fd)

    def read(self, timeout_s: float = 0.0) -> bytes:
        """What the host wrote (b"" when nothing came within timeout_s or no host is attached)."""
        if self.master < 0:
            return b""
        if timeout_s > 0:
            r, _, _ = select.select([self.master], [], [], timeout_s)
            if not r:
                return b""
        try:
            return os.read(self.master, 4096)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:  # EIO: no host has the port open
            if timeout_s > 0:
                time.sleep(timeout_s)
            return b""

    def write(self, data) -> int:
        """Write what the pty takes now; returns the bytes written (the rest did not fit)."""
        if self.master < 0:
            return 0
        try:
            return os.write(self.master, data)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError:
            return 0

    def close(self) -> None:
        for fd in (self.master, self.slave):
            if fd is not None and fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master, self.slave = -1, None


class TcpSerialLink:
    """A serial line carried over TCP, as a serial device server (ser2net) or a networked GRBL
    (Grbl_ESP32, FluidNC) carries one: the emulator listens on a loopback port and a driver opens
    `path`, a pyserial URL ("socket://127.0.0.1:PORT"). The same surface as `Pty` (read, write,
    host_attached, forget_unread, close), so an emulator's protocol loop runs on either.

    Why a loopback bench uses it: the kernel hands a pseudo-terminal's bytes from one side to the
    other in a worker thread of ordinary priority (flush_to_ldisc on a kworker). On a busy host that
    worker waits for a CPU like any other thread (80-330 ms sampled beside twice the core count of
    busy processes, while a stream of skin frames kept the same pool busy), so a '?' reached the
    emulated GRBL late however it was scheduled itself, and its report counted as missing. Loopback
    TCP delivers in the sender's own system call.

    Bytes written while no host is connected wait, up to `hold_bytes`, for the next host (as a pty
    whose slave stays open keeps them); a host that connects while another is connected takes the
    line over (a serial port has one user). The listening port stays until close().
    """

    def __init__(self, host: str = "127.0.0.1", hold_bytes: int = 4096) -> None:
        self._listener: socket.socket | None = socket.create_server((host, 0))
        self._listener.setblocking(False)
        self.path = f"socket://{host}:{self._listener.getsockname()[1]}"
        self._client: socket.socket | None = None
        self._held = bytearray()
        self._hold_bytes = int(hold_bytes)

    @property
    def closed(self) -> bool:
        return self._listener is None

    def _accept(self) -> None:
        if self._listener is None:
            return
        try:
            client, _ = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        self._drop_client()
        client.setblocking(False)
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._client = client
        held, self._held = bytes(self._held), bytearray()
        if held:
            self.write(held)

    def _drop_client(self) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except OSError:
                pass
            self._client = None

    def host_attached(self) -> bool:
        self._accept()
        return self._client is not None

    def forget_unread(self) -> None:
        """Discard bytes held for a host that is not connected."""
        self._held.clear()

    def read(self, timeout_s: float = 0.0) -> bytes:
        """What the host wrote (b"" when nothing came within timeout_s or no host is connected)."""
        if self._listener is None:
            return b""
        watched = [self._listener] + ([self._client] if self._client is not None else [])
        ready, _, _ = select.select(watched, [], [], max(timeout_s, 0.0))
        if self._listener in ready:
            self._accept()
        client = self._client
        if client is None or client not in ready:
            return b""
        try:
            data = client.recv(4096)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            data = b""
        if not data:  # the host closed its end
            self._drop_client()
        return data

    def write(self, data) -> int:
        """Write what the link takes now; returns the bytes taken (the rest did not fit)."""
        if self._listener is None:
            return 0
        self._accept()
        if self._client is None:
            take = min(len(data), self._hold_bytes - len(self._held))
            self._held += bytes(data[:take])
            return take
        try:
            return self._client.send(data)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError:
            self._drop_client()
            return 0

    def close(self) -> None:
        self._drop_client()
        if self._listener is not None:
            self._listener.close()
            self._listener = None


SERIAL_LINKS = ("pty", "tcp")


def check_serial_link(kind: str, emulator: str) -> None:
    """Refuse an unknown link kind in the emulator's constructor (not later, in its device process)."""
    if kind not in SERIAL_LINKS:
        raise ValueError(f"{emulator} emulator: link {kind!r}: choose one of {SERIAL_LINKS} "
                         "(see hardware.emulation.serial_link)")


def serial_link(kind: str, hold: bool = False) -> Pty | TcpSerialLink:
    """An emulated serial device's end of its line: "pty" (a path any serial program opens) or
    "tcp" (a pyserial socket:// URL; see TcpSerialLink for why a loopback bench uses it)."""
    if kind == "pty":
        return Pty(hold_slave=hold)
    if kind == "tcp":
        return TcpSerialLink(hold_bytes=4096 if hold else 0)
    raise ValueError(f"serial link {kind!r}: choose one of {SERIAL_LINKS}: 'pty' (a port path) or 'tcp' (a socket:// URL)")


def free_loopback_host(ports: dict[int, int], first: int = 2, last: int = 254) -> str:
    """A loopback address 127.0.0.N on which every (port, socket type) of `ports` can be bound,
    so that emulators on a device's usual ports do not collide with each other."""
    for n in range(first, last + 1):
        host = f"127.0.0.{n}"
        socks = []
        try:
            for port, kind in ports.items():
                s = socket.socket(socket.AF_INET, kind)
                socks.append(s)
                s.bind((host, port))
            return host
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise OSError(f"no loopback address 127.0.0.N ({first}..{last}) with the ports {sorted(ports)} free")


class PipeLog(logging.Handler):
    """A device process's log records sent to the parent as ("log", level, text) (send: a callable
    that sends one message over the pipe); the parent logs them (DeviceProcess.poll)."""

    def __init__(self, send, level: int = logging.INFO) -> None:
        super().__init__(level)
        self._send = send

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self._send(("log", record.levelno, record.getMessage()))
        except OSError:
            pass


def run_as_a_device() -> str:
    """Called first in an emulated device's own process: ask the kernel to schedule it as the
    separate machine it stands for, ahead of the host's ordinary work (round-robin real-time
    priority 1, the lowest; a device's loop sleeps between its cycles and takes little CPU, and
    the kernel's real-time throttling keeps 5 % of each second for everything else). Measured:
    at ordinary priority, under twice the core count of busy processes, the skin board's own
    process waited 55-65 ms for a CPU and the driver rightly saw a silent board; a real board
    never waits for the host. Where real-time scheduling is not permitted (no CAP_SYS_NICE) the
    process runs at ordinary priority and a busy host can delay it. Returns which, for the log."""
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(1))
        return "real-time round-robin priority 1"
    except (AttributeError, PermissionError, OSError) as exc:
        return f"ordinary priority (real-time scheduling refused: {exc}); a busy host may delay it"


def serve_device(make, argv: list[str], parent_gone: tuple = (EOFError, BrokenPipeError, ConnectionResetError)) -> int:
    """Entry of a device process (`python -m MODULE FD OPTIONS_JSON`, see DeviceProcess):
    make(conn, **options).run(); the parent going away (parent_gone) powers the device off,
    any other failure is sent to the parent, which raises it, and re-raised here. The process
    first asks to be scheduled as a device (`run_as_a_device`) and logs which it got."""
    import json
    from multiprocessing.connection import Connection

    conn = Connection(int(argv[0]))
    conn.send(("log", logging.INFO, f"device process {os.getpid()}: {run_as_a_device()}"))
    try:
        make(conn, **json.loads(argv[1])).run()
    except parent_gone:
        return 0
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which raises it
        try:
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
        except OSError:
            pass
        raise
    return 0


class DeviceProcess:
    """The process an emulated device runs in (`python -m MODULE FD OPTIONS_JSON`), and the pipe
    to it (FD: a multiprocessing Connection over a socketpair), as a real device is another
    machine: it keeps its own clock whatever the host's interpreter is doing.

    The child sends ("ready", where), ("error", text), ("log", level, text) (logged here under
    `logger`, so its lines reach the run's log) and ("info", ..., ack) read-outs, the last item an
    acknowledgement (kind, value) or None; `poll` hands the read-outs and the child's other
    messages (commands to apply) to the caller's handler. A
    bridge thread of the emulator calls `poll` in its loop; wait_ack blocks until the child has
    taken a command (a fault in force before the call returns)."""

    def __init__(self, module: str, options: dict, device: str, logger) -> None:
        import json
        import subprocess
        import sys
        from multiprocessing.connection import Connection
        from pathlib import Path

        root = Path(__file__).resolve().parents[1]
        parent, child = socket.socketpair()
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]))
        self.device, self.log = device, logger
        self.proc = subprocess.Popen([sys.executable, "-m", module, str(child.fileno()), json.dumps(options)],
                                     pass_fds=[child.fileno()], cwd=str(root), env=env)
        child.close()
        self.conn = Connection(parent.detach())
        self.where = None
        self.error: str | None = None
        self.ready = threading.Event()
        self._cv = threading.Condition()
        self._acks: dict = {}
        # Messages to the child go through one sender thread: a bridge that blocked in send() on
        # a full pipe while the child blocked sending its frames back (the bridge is also the
        # one that reads them) deadlocked both, and the emulator's stop() with them.
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._send_error: str | None = None
        self._sender = threading.Thread(target=self._send_loop, name=f"{device}-pipe-out", daemon=True)
        self._sender.start()

    def send(self, msg: tuple) -> None:
        """Queue msg for the child (in order; never blocks). OSError once the pipe has broken."""
        if self._send_error is not None:
            raise OSError(self._send_error)
        self._outbox.put(msg)

    def _send_loop(self) -> None:
        while (msg := self._outbox.get()) is not None:
            try:
                self.conn.send(msg)
            except OSError as exc:
                self._send_error = f"{self.device} emulator: its pipe broke ({exc})"
                self.went_away(exc)
                return

    def poll(self, timeout_s: float, handle) -> None:
        """Take what the child sent (waiting up to timeout_s for the first): read-outs ("info",
        ...) and the child's other messages go to handle(msg), before a read-out's
        acknowledgement is recorded. EOFError/OSError: the child went away."""
        if not self.conn.poll(timeout_s):
            return
        while self.conn.poll():
            msg = self.conn.recv()
            kind = msg[0]
            if kind == "log":
                self.log.log(msg[1], "%s (emulated): %s", self.device, msg[2])
            elif kind == "ready":
                self.where = msg[1]
                self.ready.set()
            elif kind == "error":
                self.error = msg[1]
                self.log.error("%s emulator: its process failed: %s", self.device, msg[1])
                self.ready.set()
            else:
                handle(msg)
                ack = msg[-1] if kind == "info" else None
                if ack is not None:
                    with self._cv:
                        self._acks[ack[0]] = ack[1]
                        self._cv.notify_all()

    def went_away(self, exc: BaseException) -> None:
        """The pipe broke: whoever waits for the child learns it."""
        self.error = self.error or f"its process went away ({exc})"
        self.ready.set()
        with self._cv:
            self._cv.notify_all()

    def wait_ready(self, timeout_s: float) -> None:
        from hardware.interfaces import DeviceError

        if not self.ready.wait(timeout_s) or self.error is not None:
            raise DeviceError(f"{self.device} emulator: its process did not start "
                              f"({self.error or f'no answer within {timeout_s} s'})")

    def wait_ack(self, kind: str, ok, timeout_s: float = 5.0) -> None:
        from hardware.interfaces import DeviceError

        deadline = time.monotonic() + timeout_s
        with self._cv:
            while not (kind in self._acks and ok(self._acks[kind])):
                left = deadline - time.monotonic()
                if left <= 0 or self.error is not None:
                    raise DeviceError(f"{self.device} emulator: its process did not take {kind!r} within "
                                      f"{timeout_s} s{f' ({self.error})' if self.error else ''}")
                self._cv.wait(left)
            del self._acks[kind]

    def close(self) -> None:
        import subprocess

        try:
            self.send(("quit",))
        except OSError:
            pass
        self._outbox.put(None)  # the sender ends after the quit
        try:
            self.proc.wait(timeout=3.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._sender.join(timeout=2.0)
        self.conn.close()
