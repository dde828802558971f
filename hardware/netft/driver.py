"""ATI Mini40 through its Net F/T box: RDT real-time streaming over UDP.

Time stamps: host_t_ns is time.monotonic_ns() when the datagram is received. device_t_ns is an
estimate from the record's ft_sequence, the box's internal sample counter (from its power-up,
at ft_sample_rate_hz, wrapping at 2**32, unwrapped here): device_t_ns = ft_samples * 1e9 /
ft_sample_rate_hz. Its epoch is the box's power-up and its rate the box's quartz, so it carries
an unknown offset and a drift of tens of ppm, which the session's clock alignment fits like any
device clock; it is not a wall time.

Sequence health: rdt_sequence numbers the records of one stream (from 1, wrapping at 2**32):
gaps are lost records, repeats duplicates, steps back out-of-order ones. Wrench.seq is the
unwrapped count, continued across the stream restart that tare() requests.

Stall: judged by the box's sample counter, not by when the receive thread last ran. fault()
first takes every datagram the OS holds for the socket, then estimates when the newest record
was made on the host clock (hardware.watchdog.DeviceClock); a box that stopped sending is
reported once that is older than stall_timeout_s.
"""

from __future__ import annotations

import logging
import select
import socket
import threading
import time
import urllib.request
from collections import deque
from collections.abc import Callable

from hardware.interfaces import DeviceError, ForceTorqueSensor
from hardware.netft import wire
from hardware.netft.config import NetFTConfig
from hardware.watchdog import DeviceClock
from layerskin_exp.types import Wrench

log = logging.getLogger(__name__)

RECV_POLL_S = 0.02  # the receive thread wakes at least this often to notice disconnect()
START_RETRY_S = 0.25  # while waiting for the first record, the start request is sent again (UDP may drop it)
RESTART_WINDOW = 200  # records after tare() within which a step back is read as the stream restarting


class NetFTSensor(ForceTorqueSensor):
    """The Net F/T as a ForceTorqueSensor.

    on_sample(Wrench): called for every sample, in the receive thread, as it arrives (the rig's
    safety guard; it may stop other devices and must be cheap). A callback that raises is
    logged and reported by fault().
    """

    def __init__(self, config: NetFTConfig, on_sample: Callable[[Wrench], object] | None = None) -> None:
        super().__init__()
        self.config = config
        self.on_sample = on_sample
        self.calibration_used: wire.Calibration | None = None
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._first = threading.Event()
        self._lock = threading.Lock()
        self._buf: deque[Wrench] = deque()
        self._rx_lock = threading.Lock()  # one reader of the socket at a time: records in order
        self._reset_state()

    def _reset_state(self) -> None:
        self._last_rdt: int | None = None  # last raw rdt_sequence
        self._seq = 0  # unwrapped rdt count of the last record
        self._last_ft: int | None = None
        self._ft_samples = 0  # unwrapped ft_sequence
        self._restart_left = 0  # records left in which a step back is a restart (after tare)
        self._box_clock = DeviceClock()  # when the box made its newest record, on the host clock
        self._link_error: str | None = None  # the last receive/send error, cleared when records flow again
        self._callback_error: str | None = None
        self._status_fault: str | None = None

    @property
    def address(self) -> str:
        return f"{self.config.host}:{self.config.port}"

    # ---- connect ---------------------------------------------------------------------------
    def _fetch_calibration(self) -> wire.Calibration:
        c = self.config
        if not c.fetch_calibration:
            return wire.Calibration(c.counts_per_force, c.counts_per_torque, c.force_unit, c.torque_unit)
        url = f"http://{c.host}:{c.http_port}/netftapi2.xml"
        try:
            with urllib.request.urlopen(url, timeout=c.connect_timeout_s) as resp:  # noqa: S310 - http to the box
                text = resp.read().decode("utf-8", "replace")
            return wire.parse_calibration_xml(text)
        except (OSError, wire.RDTError) as exc:
            raise DeviceError(f"ft: could not read the Net F/T calibration from {url}: {exc}. Check the box's "
                              "address and web server, or set hardware.netft.fetch_calibration=false and give "
                              "counts_per_force / counts_per_torque from its calibration page") from exc

    def _connect(self) -> None:
        c = self.config
        self._reset_state()
        self.calibration_used = self._fetch_calibration()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.connect((c.host, c.port))
            sock.setblocking(False)  # the receive thread waits in select, fault() drains
        except OSError as exc:
            sock.close()
            raise DeviceError(f"ft: cannot open UDP to the Net F/T at {self.address}: {exc}; check hardware.netft.host "
                              "and the network interface") from exc
        self._sock = sock
        self._stop.clear()
        self._first.clear()
        with self._lock:
            self._buf.clear()
        self._thread = threading.Thread(target=self._run, name="netft-rx", daemon=True)
        self._thread.start()
        deadline = time.monotonic() + c.connect_timeout_s
        while not self._first.is_set():
            self._send(wire.CMD_START_REALTIME, 0)
            if self._first.wait(min(START_RETRY_S, max(deadline - time.monotonic(), 0.0))):
                break
            if time.monotonic() >= deadline:
                self._shutdown()
                raise DeviceError(f"ft: no RDT data from the Net F/T at {self.address} within {c.connect_timeout_s} s;"
                                  " check that the box is powered and reachable, its IP address, and that UDP "
                                  f"port {c.port} is not blocked")
        log.info("ft: streaming from %s (%s)", self.address, self.calibration_used)

    def _disconnect(self) -> None:
        try:
            self._send(wire.CMD_STOP, 0)
        finally:
            self._shutdown()

    def _shutdown(self) -> None:
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)
        self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _send(self, command: int, count: int = 0) -> None:
        sock = self._sock
        if sock is None:
            return
        try:
            sock.send(wire.encode_request(command, count))
        except OSError as exc:
            self._link_error = f"ft: link lost (sending {wire.COMMANDS.get(command, command)} to {self.address}: {exc})"
            log.warning("%s", self._link_error)

    # ---- receive ---------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            if self._wait_readable():
                self._drain()
                if self._link_error is not None:
                    time.sleep(RECV_POLL_S)

    def _wait_readable(self) -> bool:
        """Block up to RECV_POLL_S for a datagram (outside the read lock, so fault() may drain)."""
        sock = self._sock
        try:
            return sock is not None and bool(select.select([sock], [], [], RECV_POLL_S)[0])
        except (OSError, ValueError):  # closed by disconnect()
            return False

    def _drain(self) -> None:
        """Take every datagram the OS holds for the socket, without blocking (from the receive
        thread, or from fault() when the newest record looks old)."""
        sock = self._sock
        if sock is None:
            return
        with self._rx_lock:
            while not self._stop.is_set():
                try:
                    data = sock.recv(65536, socket.MSG_DONTWAIT)
                except (BlockingIOError, InterruptedError):
                    return
                except OSError as exc:
                    if self._stop.is_set():
                        return
                    # A connected UDP socket reports the box's ICMP "port unreachable" here.
                    if self._link_error is None:
                        self._link_error = f"ft: link lost ({self.address}: {exc})"
                        log.warning("%s", self._link_error)
                    return
                host_ns = time.monotonic_ns()
                try:
                    records = wire.decode_records(data)
                except wire.RDTError as exc:
                    self.health.corrupt += 1
                    log.warning("ft: rejected datagram from %s: %s", self.address, exc)
                    continue
                for rec in records:
                    self._take(rec, host_ns)
                if records:
                    self._box_clock.observe(self._ft_device_ns(), host_ns)
                self._link_error = None
                self._first.set()

    def _ft_device_ns(self) -> int:
        """The box's time of the newest record: its unwrapped sample counter at ft_sample_rate_hz."""
        return int(self._ft_samples * 1e9 / self.config.ft_sample_rate_hz)

    def _take(self, rec: wire.RDTRecord, host_ns: int) -> None:
        if self._last_rdt is None:
            seq = rec.rdt_sequence
            self.health.observe_seq(None, seq)
        else:
            d = wire.seq_delta(rec.rdt_sequence, self._last_rdt)
            if d < 0 and self._restart_left > 0:
                d, self._restart_left = 1, 0  # the stream restarted (tare): continue the count
                log.info("ft: stream restarted at rdt_sequence %d", rec.rdt_sequence)
            elif self._restart_left > 0:
                self._restart_left -= 1
            if d > 1:
                log.debug("ft: %d records lost before rdt_sequence %d", d - 1, rec.rdt_sequence)
            seq = self._seq + d
            self.health.observe_seq(self._seq, seq)
            if d <= 0:
                return  # a duplicate or a late record: counted, not delivered twice or out of order
        self._last_rdt, self._seq = rec.rdt_sequence, seq
        if self._last_ft is not None:
            self._ft_samples += max(wire.seq_delta(rec.ft_sequence, self._last_ft), 0)
        else:
            self._ft_samples = rec.ft_sequence
        self._last_ft = rec.ft_sequence
        if rec.status and self._status_fault is None:
            self._status_fault = f"ft: the Net F/T reports status 0x{rec.status:08x} ({wire.decode_status(rec.status)})"
            log.error("%s", self._status_fault)
        force, torque = self.calibration_used.to_si(rec.counts)
        w = Wrench(force, torque, seq, self._ft_device_ns(), host_ns, rec.status)
        with self._lock:
            self._buf.append(w)
        if self.on_sample is not None:
            try:
                self.on_sample(w)
            except Exception as exc:  # noqa: BLE001 - the stream must go on; fault() reports it
                if self._callback_error is None:
                    self._callback_error = f"ft: on_sample callback failed: {exc!r}"
                log.exception("ft: on_sample callback failed")

    # ---- interface -------------------------------------------------------------------------
    def read_available(self) -> list[Wrench]:
        self._require_connected()
        with self._lock:
            out = list(self._buf)
            self._buf.clear()
        return out

    def tare(self) -> None:
        """The box biases itself (RDT software bias, 0x0042) with its current reading; the sensor
        should be unloaded. Streaming is requested again afterwards, as the box may end the
        stream on a new command; the restarted sequence continues Wrench.seq."""
        self._require_connected()
        self._restart_left = RESTART_WINDOW
        self._send(wire.CMD_BIAS, 0)
        self._send(wire.CMD_START_REALTIME, 0)

    def fault(self, now_ns: int) -> str | None:
        """A link error, a failed on_sample, a non-zero status word (both latched until the next
        connect()), or a stall."""
        if self._link_error is not None:
            return self._link_error
        if self._callback_error is not None:
            return self._callback_error
        if self._status_fault is not None:
            return self._status_fault
        bound_ns = self.config.stall_timeout_s * 1e9
        if self.is_connected and (self._box_clock.silent_ns(now_ns) or 0) > bound_ns:
            self._drain()  # records the receive thread has not been scheduled to read yet
            quiet_ns = self._box_clock.silent_ns(now_ns)
            if quiet_ns > bound_ns and self._link_error is None:
                return (f"ft stalled: no sample for {quiet_ns / 1e6:.0f} ms (from {self.address}; box time of the "
                        f"newest record, rdt_sequence {self._last_rdt})")
            return self._link_error
        return None
