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

The box runs in a process of its own (`hardware.netft.box`, which says why and how it samples):
it owns the RDT socket and streams on its own clock; the world and the web server stay in this
process, whose bridge thread sends it the twin's samples as counts of the active calibration.
Its log lines reach this process's log (the run's log).

Ports: `port` (RDT, UDP) and `http_port` (the calibration page) take 0 for any free port, as the
loopback bench does; the box's own are USUAL_PORTS (RDT 49152, HTTP 80), which the standalone
launcher uses (HTTP falls back to HTTP_FALLBACK_PORT where port 80 is not allowed).
"""

from __future__ import annotations

import http.server
import logging
import time

import numpy as np

from hardware.emulation import DeviceProcess, Emulator
from hardware.netft import web, wire

log = logging.getLogger(__name__)

EMULATOR_SETUP = "platform"
POLL_S = 0.002  # how often the bridge looks for new twin samples (the box samples on its own clock)
START_TIMEOUT_S = 20.0
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
        self._http: http.server.HTTPServer | None = None
        self._box: DeviceProcess | None = None
        self._info: dict = {}
        self._bias = np.zeros(6, np.int64)

    # ---- life cycle ------------------------------------------------------------------------
    def _open(self) -> str:
        if self.http_port is not None:
            self._http = http.server.ThreadingHTTPServer((self.host, self.http_port), self._handler())
            self.http_port = self._http.server_address[1]
            self.http_address = f"{self.host}:{self.http_port}"
            self._spawn(self._http.serve_forever, "http", 0.05)
        with self.rt.lock:
            self.rt.rig.ft.read_available()  # start with fresh samples
            t0_s = float(self.rt.world.t_s)
            twin_rate_hz = float(self.rt.rig.ft.cfg.rate_hz)
        opts = {"host": self.host, "port": self.port, "twin_rate_hz": twin_rate_hz,
                "ft_sample_rate_hz": self.ft_sample_rate_hz, "t0_s": t0_s, "settings": self._settings()}
        self._box = DeviceProcess("hardware.netft.box", opts, self.DEVICE, log)
        self.port = self._serve_device(self._box, START_TIMEOUT_S)
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
        if self._box is not None:
            self._box.close()
            self._box = None

    @property
    def calibration(self) -> wire.Calibration:
        """The active configuration's calibration (what the records' counts are in)."""
        return self.web.calibration

    @property
    def records_per_packet(self) -> int:
        return self.web.buffer_records

    def _handler(self):
        box, emulator = self.web, self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                code, content_type, text = box.get(self.path)
                if code != 200:
                    self.send_error(code)
                    return
                if ".cgi" in self.path:  # a setting: in force in the box before the page answers
                    emulator._push_settings()
                body = text.encode()
                self.send_response(200)
                self.send_header("Content-Type", content_type)
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                self.wfile.write(body)

            def log_message(self, *args) -> None:
                pass

        return Handler

    # ---- faults: carried out by the box process -----------------------------------------------
    def _on_stall(self, stalled: bool) -> None:
        """Stall or resume the box and wait until it has taken it."""
        if self._box is None:
            return
        if stalled:
            left = self._stall_until - time.monotonic()
            self._box.send(("stall", None if left == float("inf") else max(left, 0.0)))
        else:
            self._box.send(("resume",))
        self._box.wait_ack("stall", lambda v: v == stalled)

    def _on_disconnect(self) -> None:  # off the network: no requests, no records, no page
        self._close_http()
        if self._box is not None:
            self._box.send(("disconnect",))

    SCHEDULED_KEY = "planned"

    def _device(self) -> DeviceProcess | None:
        return self._box

    # ---- bridge ----------------------------------------------------------------------------------
    def _push_settings(self) -> None:
        """Hand the box the web page's settings now and wait until it has them (a setting page
        answers once the setting is in force, as the real box's does; before, the box took it with
        the next samples, and the first RDT records after comrdtrate still came at the old rate)."""
        if self._box is not None and self._box.ready.is_set():
            self._box.send(("settings", self._settings()))
            self._box.wait_ack("settings", lambda v: True)

    def _settings(self) -> list:
        with self.web.lock:
            decimation, per_packet = self.web.decimation, self.web.buffer_records
        return [decimation, per_packet, self.status, self.drop_every]

    def _bridge(self) -> None:
        box = self._box
        try:
            while not self._stop.is_set():
                box.poll(POLL_S, lambda msg: self._readout(*msg[1:-1]))
                if box.ready.is_set() and box.error is None:
                    with self.rt.lock:
                        samples = self.rt.rig.ft.read_available()
                    if samples:
                        with self.web.lock:
                            cal = self.web.calibration
                        raw = [[int(c) for c in cal.to_counts(w.force_n, w.torque_nm)] for w in samples]
                        self._last_counts = tuple(int(c) for c in np.asarray(raw[-1], np.int64) - self._bias)
                        box.send(("samples", raw, self._settings()))
        except (EOFError, OSError) as exc:
            if not self._stop.is_set():
                log.warning("netft emulator: the box process went away (%s)", exc)
                self.error = self.error or exc
                box.went_away(exc)

    def _readout(self, counts, fault_counts, planned, requests, stalled, disconnected, bias) -> None:
        self.requests.extend(tuple(r) for r in requests)
        self._bias = np.asarray(bias, np.int64)
        for k in ("drop", "corrupt"):  # applied in the box; stall and disconnect are counted here
            if fault_counts.get(k):
                self.fault_counts[k] = fault_counts[k]
        self._info = {"planned": planned, "stalled": stalled, "disconnected": disconnected, "counts": counts}
