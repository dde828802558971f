"""NetFTSensor against NetFTEmulator on a RealtimeWorld, a scripted fake box, and a third-party RDT client."""

import socket
import threading
import time
import urllib.error
import urllib.request
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from hardware.interfaces import DeviceError
from hardware.netft import NetFTConfig, NetFTEmulator, NetFTSensor, web, wire
from hardware.netft.driver import RECV_POLL_S
from layerskin_exp.config import ConfigError
from tests.hardware.conftest import start_realtime_world


@pytest.fixture(scope="module")
def rt():
    """One platform world for the module (building one takes seconds); one emulator drains it at a time."""
    world = start_realtime_world("platform")
    yield world
    world.stop()


@pytest.fixture
def emulator(rt):
    emus = []

    def make(**kw):
        emu = NetFTEmulator(rt, http_port=0, **kw)
        emu.start()
        emus.append(emu)
        return emu

    yield make
    for emu in emus:
        emu.stop()


def sensor_for(emu, on_sample=None, **kw):
    kw = {"http_port": emu.http_port, "connect_timeout_s": 2.0, **kw}
    cfg = NetFTConfig(host="127.0.0.1", port=emu.port, **kw)
    return NetFTSensor(cfg, on_sample)


def collect(sensor, n, timeout_s=5.0):
    """At least n samples (fails after timeout_s: a generous bound, not a timing claim)."""
    out, deadline = [], time.monotonic() + timeout_s
    while len(out) < n:
        assert time.monotonic() < deadline, f"only {len(out)} of {n} samples"
        time.sleep(0.01)
        out += sensor.read_available()
    return out


def wait_for(pred, timeout_s=3.0):
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline
        time.sleep(0.005)


def test_the_driver_streams_the_simulated_mini40_with_the_box_calibration(emulator):
    emu = emulator()
    seen = []
    with sensor_for(emu, seen.append) as ft:
        assert ft.calibration_used == emu.calibration  # read from netftapi2.xml over HTTP
        w = collect(ft, 200)
        assert seen[:len(w)] == w  # on_sample saw every sample, in order, before read_available did
    seq = np.array([x.seq for x in w])
    assert np.all(np.diff(seq) == 1) and ft.health.lost == 0 and ft.health.out_of_order == 0
    # The twin samples at 1 kHz; ft_sequence counts at 7 kHz: device time steps ~1 ms.
    dt_ms = np.diff([x.device_t_ns for x in w]) / 1e6
    assert np.all((dt_ms > 0.8) & (dt_ms < 1.2)), dt_ms
    assert np.all(np.diff([x.host_t_ns for x in w]) >= 0)
    f = np.array([x.force_n for x in w])
    assert np.all(np.abs(f) < 1.0)  # unloaded: the untared bias (< 0.3 N) and noise
    assert ("start real-time", 0) == (wire.COMMANDS[emu.requests[0][0]], emu.requests[0][1])
    wait_for(lambda: emu.requests[-1] == (wire.CMD_STOP, 0))  # disconnect() ends the stream


def test_tare_makes_the_box_bias_itself(emulator):
    emu = emulator()
    with sensor_for(emu) as ft:
        collect(ft, 50)
        ft.tare()
        wait_for(lambda: (wire.CMD_BIAS, 0) in emu.requests)
        time.sleep(0.05)
        ft.read_available()  # samples in flight from before the bias
        w = collect(ft, 300)
    f = np.array([x.force_n for x in w])
    assert np.all(np.abs(f.mean(axis=0)) < 0.01)  # Mini40 noise: 5-10 mN per sample
    assert np.all(np.diff([x.seq for x in w]) == 1)  # the restarted stream continues the count
    assert ft.health.out_of_order == 0


def test_counts_from_the_config_when_the_box_page_is_not_read(emulator):
    emu = emulator(calibration=wire.Calibration(1000.0, 1000.0, "N", "N-mm"))
    with sensor_for(emu, fetch_calibration=False, http_port=1, counts_per_force=1000.0, counts_per_torque=1000.0,
                    torque_unit="N-mm") as ft:
        w = collect(ft, 50)
    assert ft.calibration_used.torque_unit == "N-mm"
    assert np.all(np.abs([x.force_n for x in w]) < 1.0)
    assert np.all(np.abs([x.torque_nm for x in w]) < 0.05)


def test_dropped_records_are_counted_as_lost(emulator):
    emu = emulator(drop_every=5)
    with sensor_for(emu) as ft:
        w = collect(ft, 200)
    seq = [x.seq for x in w]
    assert ft.health.lost == pytest.approx(len(w) / 4, abs=2)
    gaps = seq[-1] - seq[0] + 1 - len(w)  # every gap between the first and last collected sample
    late = ft.health.received - len(w)  # samples that arrived after collecting, before the close
    assert gaps <= ft.health.lost <= gaps + late + 1  # at most one dropped record beside each late one


def test_scheduled_drops_and_corrupt_datagrams_are_counted(emulator):
    emu = emulator()
    with sensor_for(emu) as ft:
        collect(ft, 20)
        emu.drop(5)
        wait_for(lambda: emu.scheduled == 0)
        collect(ft, 20)
        assert ft.health.lost == 5 and ft.health.corrupt == 0
        emu.corrupt(3)
        wait_for(lambda: emu.scheduled == 0)
        collect(ft, 20)
        assert ft.health.corrupt == 3 and ft.health.lost == 5 + 3  # a short datagram's record never arrives
    assert emu.fault_counts == {"drop": 5, "corrupt": 3}


def test_a_disconnected_box_answers_nothing(emulator):
    emu = emulator()
    with sensor_for(emu) as ft:
        collect(ft, 20)
        emu.disconnect()
        wait_for(lambda: "ft stalled" in (ft.fault(time.monotonic_ns()) or ""), 2.0)
    with pytest.raises(DeviceError):
        sensor_for(emu, connect_timeout_s=0.3).connect()  # neither RDT nor the calibration page answers


def test_a_status_word_from_the_box_is_a_fault(emulator):
    emu = emulator(status=0x80020000)
    with sensor_for(emu) as ft:
        w = collect(ft, 5)
        reason = ft.fault(time.monotonic_ns())
    assert w[0].status == 0x80020000
    assert "0x80020000" in reason and "saturation" in reason


def test_a_box_that_stops_sending_faults_after_the_stall_timeout(emulator):
    emu = emulator()
    with sensor_for(emu) as ft:
        collect(ft, 20)
        assert ft.fault(time.monotonic_ns()) is None
        emu.stall()
        time.sleep(0.01)
        ft.read_available()
        last = ft._box_clock.newest_host_ns  # when the box made its newest record, on the host clock
        # Checked at the rig clock's times, not against the wall clock: silent up to the timeout, faulted after.
        assert ft.fault(last + 40_000_000) is None
        assert "ft stalled: no sample for 60 ms" in ft.fault(last + 60_000_000)


def test_a_failing_guard_callback_is_reported(emulator):
    emu = emulator()

    def guard(w):
        raise RuntimeError("guard broke")

    with sensor_for(emu, guard) as ft:
        collect(ft, 5)
        assert "on_sample callback failed" in ft.fault(time.monotonic_ns())


def test_buffered_counted_streams_pack_records_and_end(emulator):
    emu = emulator(records_per_packet=10)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(2.0)
        s.connect(("127.0.0.1", emu.port))
        s.send(wire.encode_request(wire.CMD_START_BUFFERED, 25))
        sizes, recs = [], []
        while len(recs) < 25:
            data = s.recv(4096)
            sizes.append(len(data) // wire.RECORD.size)
            recs += wire.decode_records(data)
        s.settimeout(0.1)
        with pytest.raises(TimeoutError):
            s.recv(4096)  # a counted stream ends
    assert sizes == [10, 10, 5]
    assert [r.rdt_sequence for r in recs] == list(range(1, 26))


class FakeBox:
    """A scripted Net F/T: answers the first request with the given datagrams."""

    def __init__(self, datagrams, answer=True):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.port = self.sock.getsockname()[1]
        self.datagrams, self.answer = datagrams, answer
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        try:
            _, addr = self.sock.recvfrom(64)
        except OSError:
            return
        if self.answer:
            for d in self.datagrams:
                self.sock.sendto(d, addr)

    def close(self):
        self.sock.close()
        self.thread.join()


def test_wrapping_duplicate_late_and_corrupt_records_are_counted():
    rec = lambda seq, ft: wire.encode_record(seq, ft, 0, (1000, 0, -2000, 0, 0, 0))  # noqa: E731
    top = 2**32
    script = [rec(top - 2, top - 14), rec(top - 1, top - 7), b"\x12\x34" * 9, rec(0, 0), rec(1, 7),
              rec(1, 7), rec(3, 21), rec(2, 14), rec(4, 28)]
    box = FakeBox(script)
    try:
        ft = NetFTSensor(NetFTConfig(host="127.0.0.1", port=box.port, fetch_calibration=False, connect_timeout_s=1.0))
        with ft:
            w = collect(ft, 6)
    finally:
        box.close()
    assert [x.seq for x in w] == [top - 2, top - 1, top, top + 1, top + 3, top + 4]
    assert ft.health.corrupt == 1 and ft.health.duplicate == 1 and ft.health.out_of_order == 1
    assert ft.health.lost == 1  # seq 2 came late: counted as lost when 3 arrived, then out of order
    # ft_sequence unwrapped across its wrap: 7 samples per record at 7 kHz = 1 ms.
    assert np.diff([x.device_t_ns for x in w]).tolist() == [1_000_000, 1_000_000, 1_000_000, 2_000_000, 1_000_000]
    assert np.allclose(w[0].force_n, [1e-3, 0.0, -2e-3])


def test_a_box_that_does_not_answer_fails_connect_naming_it():
    box = FakeBox([], answer=False)
    try:
        ft = NetFTSensor(NetFTConfig(host="127.0.0.1", port=box.port, fetch_calibration=False, connect_timeout_s=0.3))
        with pytest.raises(DeviceError, match=rf"ft: no RDT data .* 127\.0\.0\.1:{box.port} within 0\.3 s"):
            ft.connect()
        assert not ft.is_connected
    finally:
        box.close()


def test_an_unreadable_calibration_page_fails_connect():
    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]  # nothing listens there
    ft = NetFTSensor(NetFTConfig(host="127.0.0.1", port=49152, http_port=port, connect_timeout_s=0.5))
    with pytest.raises(DeviceError, match="netftapi2.xml.*fetch_calibration=false"):
        ft.connect()


def test_config_rejects_slow_stall_timeouts_and_bad_units():
    with pytest.raises(ConfigError, match="hardware.netft.stall_timeout_s"):
        NetFTConfig(stall_timeout_s=0.2)
    with pytest.raises(ConfigError, match="hardware.netft.torque_unit"):
        NetFTConfig(torque_unit="ft-lb")


def test_a_third_party_rdt_client_reads_the_emulator(emulator):
    """pyNetFT (ATI's RDT protocol and the calibration XML, in its own C++ core) against our emulator."""
    pynetft = pytest.importorskip("pynetft")
    emu = emulator()
    client = pynetft.Client(pynetft.Config(sensor_host="127.0.0.1", rdt_port=emu.port, http_port=emu.http_port))
    with client:
        it = client.samples(timeout=2.0)
        samples = [next(it) for _ in range(100)]
        health = client.health()
    assert health.sensor_configuration.calibration.counts_per_force_unit == emu.calibration.counts_per_force
    assert health.fault_code == pynetft.FaultCode.NONE and health.ft_stall_count == 0
    assert health.lost_count == 0 and health.out_of_order_count == 0 and health.malformed_count == 0
    seqs = [s.rdt_sequence for s in samples]
    assert seqs == sorted(set(seqs))  # (its Python queue may skip samples a slow reader has not taken)
    assert all(abs(f) < 1.0 for s in samples for f in s.force)


def http_get(emu, target):
    with urllib.request.urlopen(f"http://{emu.http_address}{target}", timeout=5) as r:
        return r.read().decode()


def test_the_web_server_serves_pages_and_settings_over_http(emulator):
    emu = emulator()
    page = ET.fromstring(http_get(emu, "/netftapi2.xml"))
    assert int(page.findtext("cfgcpf")) == 1_000_000  # an integer parser reads the right count
    assert page.findtext("setcfgsel") == "0" and page.findtext("cfgcalsn") == emu.web.calibrations[0].serial
    assert ET.fromstring(http_get(emu, "/netftcalapi.xml")).findtext("calsn") == page.findtext("cfgcalsn")
    assert "<html>" in http_get(emu, "/")
    with pytest.raises(urllib.error.HTTPError, match="404"):
        http_get(emu, "/nothing.htm")


def test_the_rdt_output_rate_follows_comrdtrate(emulator):
    emu = emulator()
    http_get(emu, "/comm.cgi?comrdtrate=250")
    with sensor_for(emu) as ft:
        w = collect(ft, 60)
    assert np.all(np.diff([x.seq for x in w]) == 1)  # every record of the slower stream arrives
    dt_ms = np.diff([x.device_t_ns for x in w]) / 1e6  # one record per 4 twin samples (1 kHz)
    assert np.all((dt_ms > 3.6) & (dt_ms < 4.4)), dt_ms


def test_a_third_party_client_reads_the_configuration_setcfgsel_selects(emulator):
    pynetft = pytest.importorskip("pynetft")
    finer = web.StoredCalibration("FT00002", wire.Calibration(4_000_000.0, 8_000_000.0, "N", "N-m"),
                                  (10.0, 10.0, 30.0, 0.5, 0.5, 0.5))
    emu = emulator(more_calibrations=(finer,))
    with sensor_for(emu) as ft:  # configuration 0: 1e6 counts per N
        before = np.mean([x.force_n for x in collect(ft, 50)], axis=0)
    http_get(emu, "/setting.cgi?setcfgsel=1")
    client = pynetft.Client(pynetft.Config(sensor_host="127.0.0.1", rdt_port=emu.port, http_port=emu.http_port))
    with client:
        it = client.samples(timeout=2.0)
        samples = [next(it) for _ in range(50)]
        health = client.health()
    cal = health.sensor_configuration.calibration
    assert (cal.counts_per_force_unit, cal.counts_per_torque_unit) == (4_000_000.0, 8_000_000.0)
    assert health.fault_code == pynetft.FaultCode.NONE
    # the records are in the selected calibration's counts: the same unloaded force (the twin's
    # untared bias, > 0.05 N here) in N either way; a wrong scale would read it 4x off. Judged as
    # the ratio of the two readings: the bias drifts and is noisy between the two windows (one run
    # read 0.126 then 0.136 N in z), which an absolute 0.01 N could not tell from a scale error.
    after = np.mean([s.force for s in samples], axis=0)
    ratio = np.linalg.norm(after) / np.linalg.norm(before)
    assert np.linalg.norm(before) > 0.05 and 0.8 < ratio < 1.25, (before, after)


class HandBox:
    """The test as the box: records sent by hand, ft_sequence = host time since base at 7 kHz."""

    def __init__(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.port = self.sock.getsockname()[1]
        self.base_ns, self.rdt, self.last_send_ns, self.addr = time.monotonic_ns(), 1, 0, None

    def wait_request(self):
        _, self.addr = self.sock.recvfrom(64)

    def send(self):
        self.last_send_ns = time.monotonic_ns()
        ft_seq = (self.last_send_ns - self.base_ns) * 7000 // 1_000_000_000
        self.sock.sendto(wire.encode_record(self.rdt, ft_seq, 0, (0, 0, 0, 0, 0, 0)), self.addr)
        self.rdt += 1


def test_records_held_in_the_os_while_the_reader_is_not_run_are_no_stall(monkeypatch):
    box = HandBox()
    ft = NetFTSensor(NetFTConfig(host="127.0.0.1", port=box.port, fetch_calibration=False, connect_timeout_s=2.0))
    run_rx = threading.Event()
    run_rx.set()
    real = ft._wait_readable

    def gated():  # the receive thread held back before it waits, as a thread the scheduler does not run
        run_rx.wait()
        return real()

    monkeypatch.setattr(ft, "_wait_readable", gated)
    try:
        starter = threading.Thread(target=lambda: (box.wait_request(), box.send()), daemon=True)
        starter.start()
        ft.connect()
        starter.join()
        for _ in range(5):
            box.send()
            time.sleep(0.002)
        collect(ft, 6)
        assert ft.fault(box.last_send_ns) is None
        bound_ns = ft.config.stall_timeout_s * 1e9
        run_rx.clear()
        time.sleep(2 * RECV_POLL_S)  # a select already under way returns
        paused_from, first_ns = box.rdt, None
        while first_ns is None or box.last_send_ns - first_ns <= 1.5 * bound_ns:  # the box streams on
            box.send()
            first_ns = first_ns or box.last_send_ns
            time.sleep(0.005)
        # judged at the moment the box sent its newest record, the receive thread not having run since
        assert ft.fault(box.last_send_ns + 1_000_000) is None
        w = ft.read_available()
        assert w[-1].seq == box.rdt - 1 and box.rdt - paused_from == len(w) and ft.health.lost == 0
        # the box now goes silent: reported by its own sample counter
        reason = ft.fault(box.last_send_ns + int(10 * bound_ns))
        assert reason is not None and reason.startswith("ft stalled: no sample for")
        assert f"rdt_sequence {box.rdt - 1}" in reason
    finally:
        run_rx.set()
        ft.disconnect()
        box.sock.close()
