"""A Net F/T box on loopback, backed by the simulated Mini40 (the SimForceTorque twin, 1 kHz).

Covers: RDT requests (stop, real-time and buffered streaming, sample counts, software bias,
latch reset accepted; the bias is the mean of the last BIAS_SAMPLES readings, taken here
rather than by the twin, whose tare() would advance the world), one client at a time (the latest
requester), records at the RDT output rate (comrdtrate: the twin's rate over a whole number; the
twin's rate is the fastest, where the box would go up to 7000 Hz) with rdt_sequence from 1 per
stream and ft_sequence from the twin's device clock at ft_sample_rate_hz, counts from the active
configuration's calibration, and optionally the box's web server (`web.py`: `/`, netftapi2.xml,
netftcalapi.xml, and the CGI settings setcfgsel, comrdtrate, comrdtbsiz, cfgnam/cfgcalsel).
Not covered: the box's other settings (filters, tool transforms, units other than the
calibration's: ignored as `web.py` says), thresholds and the latch, TCP and EtherNet/IP interfaces.

Faults (hardware.emulation's vocabulary): stall() (stop sending while still taking requests),
drop(n) (the next n records are lost), corrupt(n) (the next n datagrams arrive "truncated"),
disconnect() (the box leaves the network: nothing sent or answered, the calibration page gone);
drop_every (drop every n-th record) and status (the status word put in every record) are
attributes that may change while running.

Ports: `port` (RDT, UDP) and `http_port` (the calibration page) take 0 for any free port, as the
loopback bench does; the box's own are USUAL_PORTS (RDT 49152, HTTP 80), which the standalone
launcher uses (HTTP falls back to HTTP_FALLBACK_PORT where port 80 is not allowed).
"""

from __future__ import annotations

import http.server
import logging
import socket
from collections import deque

import numpy as np

from hardware.emulation import Emulator
from hardware.netft import web, wire

log = logging.getLogger(__name__)

EMULATOR_SETUP = "platform"
POLL_S = 0.001  # how often the emulator looks for requests and new twin samples
BIAS_SAMPLES = 32  # the software bias takes the mean of the latest readings, as the twin's tare does
DEFAULT_CALIBRATION = wire.Calibration(1_000_000.0, 1_000_000.0, "N", "N-m")
DEFAULT_SERIAL = "FT00001"  # the emulated transducer's calibration serial (calsn)
MINI40_SI_20_1_RANGES = (20.0, 20.0, 60.0, 1.0, 1.0, 1.0)  # Fx Fy Fz N, Tx Ty Tz N·m (ATI's Mini40 sheet)


USUAL_PORTS = {"port": wire.RDT_PORT, "http_port": 80}  # the box's RDT and web server ports
HTTP_FALLBACK_PORT = 8080  # where binding port 80 is not allowed (not root): say so when used


class NetFTEmulator(Emulator):
    """rt: a started RealtimeWorld of the "platform" setup (its rig has the F/T twin).

    http_port: None serves no web pages; 0 picks a free port (see http_address).
    records_per_packet: records per datagram in buffered mode (0x0003), comrdtbsiz at start.
    more_calibrations: further stored calibrations (web.StoredCalibration), index 1 on; configuration
    slot k uses calibration k, so `setting.cgi?setcfgsel=1` switches to the first of them.
    """

    DEVICE = "netft"
    TWINS = ("ft",)
    CORRUPTIONS = ("truncated",)
    USUAL_PORTS = USUAL_PORTS

    def __init__(self, rt, host: str = "127.0.0.1", port: int = 0, http_port: int | None = None,
                 calibration: wire.Calibration = DEFAULT_CALIBRATION, calibration_serial: str = DEFAULT_SERIAL,
                 max_ratings: tuple[float, ...] = MINI40_SI_20_1_RANGES,
                 more_calibrations: tuple[web.StoredCalibration, ...] = (), ft_sample_rate_hz: float = 7000.0,
                 records_per_packet: int = 10, drop_every: int = 0, status: int = 0,
                 product: str = "Net F/T (emulated Mini40)",
                 stall_after_s: float | None = None, disconnect_after_s: float | None = None) -> None:
        super().__init__(rt, stall_after_s=stall_after_s, disconnect_after_s=disconnect_after_s)
        self.host, self.port, self.http_port = host, port, http_port
        self.ft_sample_rate_hz = float(ft_sample_rate_hz)
        self.drop_every, self.status = int(drop_every), int(status)
        self._last_counts = (0,) * 6
        self.web = web.BoxWeb(product, [web.StoredCalibration(calibration_serial, calibration, tuple(max_ratings)),
                                        *more_calibrations],
                              rt.rig.ft.cfg.rate_hz, ft_sample_rate_hz, records_per_packet,
                              status=lambda: self.status, counts=lambda: self._last_counts)
        self.http_address: str | None = None
        self.requests: list[tuple[int, int]] = []  # (command, count) received, for tests
        self._sock: socket.socket | None = None
        self._http: http.server.HTTPServer | None = None
        # Stream state (emulator thread only).
        self._client = None
        self._mode: int | None = None  # CMD_START_REALTIME / CMD_START_BUFFERED while streaming
        self._count = 0  # records asked for in this stream (0: endless)
        self._rdt = 0  # rdt_sequence of the last record of this stream
        self._made = 0  # records produced in this stream (dropped ones included)
        self._taken = 0  # twin samples seen in this stream (the output rate takes every decimation-th)
        self._pending: list[bytes] = []  # buffered-mode records not yet sent
        self._bias = np.zeros(6, np.int64)
        self._recent_raw: deque[np.ndarray] = deque(maxlen=BIAS_SAMPLES)  # unbiased counts, newest last

    # ---- life cycle ------------------------------------------------------------------------
    def _open(self) -> str:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock = sock
        sock.bind((self.host, self.port))
        sock.settimeout(POLL_S)
        self.port = sock.getsockname()[1]
        if self.http_port is not None:
            self._http = http.server.ThreadingHTTPServer((self.host, self.http_port), self._handler())
            self.http_port = self._http.server_address[1]
            self.http_address = f"{self.host}:{self.http_port}"
            self._spawn(self._http.serve_forever, "http", 0.05)
        self._spawn(self._run, "rdt")
        return f"{self.host}:{self.port}"

    def _wake(self) -> None:
        self._close_http()

    def _close_http(self) -> None:
        if self._http is not None:
            http_server, self._http = self._http, None
            if any(t.name.endswith("-http") and t.is_alive() for t in self._threads):
                http_server.shutdown()
            http_server.server_close()

    def _close(self) -> None:
        self._close_http()
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    @property
    def calibration(self) -> wire.Calibration:
        """The active configuration's calibration (what the records' counts are in)."""
        return self.web.calibration

    @property
    def records_per_packet(self) -> int:
        return self.web.buffer_records

    def _handler(self):
        box = self.web

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                code, content_type, text = box.get(self.path)
                if code != 200:
                    self.send_error(code)
                    return
                body = text.encode()
                self.send_response(200)
                self.send_header("Content-Type", content_type)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args) -> None:
                pass

        return Handler

    # ---- serving ---------------------------------------------------------------------------
    def _run(self) -> None:
        sock = self._sock
        while not self._stop.is_set():
            if self.disconnected:  # off the network: no requests, no records, no page
                self._close_http()
                sock.close()
                return
            try:
                data, addr = sock.recvfrom(64)
                self._request(data, addr)
            except TimeoutError:
                pass
            except OSError as exc:
                if self._stop.is_set():
                    break
                log.debug("netft emulator: %s", exc)  # e.g. a client gone (ICMP unreachable)
            with self.rt.lock:
                samples = self.rt.rig.ft.read_available()
            for w in samples:
                self._emit(w)
            if self._mode == wire.CMD_START_BUFFERED and self._pending:
                self._flush(force=False)

    def _request(self, data: bytes, addr) -> None:
        try:
            command, count = wire.decode_request(data)
        except wire.RDTError as exc:
            log.warning("netft emulator: ignored request from %s: %s", addr, exc)
            return
        self.requests.append((command, count))
        if command in (wire.CMD_START_REALTIME, wire.CMD_START_BUFFERED):
            self._client, self._mode, self._count = addr, command, count
            self._rdt = self._made = self._taken = 0
            self._pending = []
        elif command == wire.CMD_STOP:
            if addr == self._client:
                self._mode = None
        elif command == wire.CMD_BIAS:
            if self._recent_raw:
                self._bias = np.rint(np.mean(self._recent_raw, axis=0)).astype(np.int64)
        elif command != wire.CMD_RESET_LATCH:
            log.warning("netft emulator: unknown command 0x%04x from %s", command, addr)

    def _emit(self, w) -> None:
        with self.web.lock:
            cal, decimation = self.web.calibration, self.web.decimation
        raw = np.array(cal.to_counts(w.force_n, w.torque_nm), np.int64)
        self._recent_raw.append(raw)
        self._last_counts = tuple(int(c) for c in raw - self._bias)
        if self._mode is None:
            return
        self._taken += 1
        if (self._taken - 1) % decimation:
            return  # between two records at the RDT output rate
        self._made += 1
        self._rdt += 1
        ft_seq = int(round(w.device_t_ns * self.ft_sample_rate_hz / 1e9))
        counts = np.clip(raw - self._bias, -(1 << 31), (1 << 31) - 1).tolist()
        record = wire.encode_record(self._rdt, ft_seq, self.status, counts)
        dropped = self.drop_every > 0 and self._made % self.drop_every == 0
        fault = None if dropped or self.stalled else self._next_fault()
        if fault is not None and fault[0] == "corrupt":
            record = record[:-3]  # a short datagram: the client cannot decode it
        if not dropped and not self.stalled and (fault is None or fault[0] != "drop"):
            if self._mode == wire.CMD_START_BUFFERED:
                self._pending.append(record)
                self._flush(force=False)
            else:
                self._send(record)
        if self._count and self._made >= self._count:  # a counted stream ends after its records
            self._flush(force=True)
            self._mode = None

    def _flush(self, force: bool) -> None:
        while len(self._pending) >= self.records_per_packet or (force and self._pending):
            chunk, self._pending = self._pending[:self.records_per_packet], self._pending[self.records_per_packet:]
            self._send(b"".join(chunk))

    def _send(self, data: bytes) -> None:
        try:
            self._sock.sendto(data, self._client)
        except OSError as exc:
            log.debug("netft emulator: send to %s failed: %s", self._client, exc)
