"""Skin board driver against the emulator (on a pty and on loopback TCP) on the realtime simulated world, faults included."""

import os
import threading
import time
import tty

import numpy as np
import pytest

from hardware.interfaces import DeviceError
from hardware.skin_board import SkinBoardConfig, SkinBoardEmulator, SkinBoardReader
from hardware.skin_board.wire import FRAME_LEN, SEQ_MOD, encode_frame
from layerskin_exp.config import ConfigError
from tests.hardware.waiting import wait_for


class Collector:
    """Reads the driver until a condition holds (a generous deadline, never a timing assertion)."""

    def __init__(self, drv):
        self.drv = drv
        self.frames = []

    def until(self, cond, timeout_s=5.0):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.frames += self.drv.read_available()
            if cond():
                return True
            time.sleep(0.005)
        return False

    def seqs(self):
        return [f.seq for f in self.frames]


@pytest.fixture(params=["pty", "tcp"])
def board(realtime_world, request):
    """Factory: (emulator, connected driver, collector) on a fresh realtime world, over either
    serial link: a pty (a port path) or loopback TCP (a socket:// URL, as the loopback bench)."""
    made = []

    def make(seq_offset=0, ring_frames=8192, **faults):
        rt = realtime_world("platform")
        emu = SkinBoardEmulator(rt, seq_offset=seq_offset, link=request.param, **faults)
        port = emu.start()
        assert port.startswith("socket://127.0.0.1:") == (request.param == "tcp")
        drv = SkinBoardReader(SkinBoardConfig(port=port, connect_timeout_s=3.0, ring_frames=ring_frames))
        made.append((emu, drv))
        drv.connect()
        return emu, drv, Collector(drv)

    yield make
    for emu, drv in made:
        drv.disconnect()
        emu.stop()


def assert_matches_twin(frames, emu, seq_offset=0):
    # the board process reports what it wrote in a read-out of its own, which may trail the port
    assert wait_for(lambda: emu.sent and emu.sent[-1].seq + seq_offset >= frames[-1].seq)
    sent = {f.seq + seq_offset: f for f in emu.sent}
    for f in frames:
        twin = sent[f.seq]
        np.testing.assert_array_equal(f.superficial, twin.superficial)
        np.testing.assert_array_equal(f.deep, twin.deep)
        assert f.device_t_ns == twin.device_t_ns // 1000 * 1000  # µs on the wire


def test_driver_reads_the_twins_frames(board):
    emu, drv, c = board()
    t0 = time.monotonic()
    assert c.until(lambda: len(c.frames) >= 200)
    elapsed = time.monotonic() - t0
    assert emu.error is None
    assert_matches_twin(c.frames, emu)
    s = c.seqs()
    assert s == list(range(s[0], s[0] + len(s)))  # contiguous, in order
    assert len(s) <= 424 * elapsed * 1.5 + 50  # not more than the board can have sent
    host = [f.host_t_ns for f in c.frames]
    assert host == sorted(host) and host[-1] <= time.monotonic_ns()
    dev = np.diff([f.device_t_ns for f in c.frames]) * 1e-6
    assert 2.0 < np.median(dev) < 2.7  # one frame pair every ~2.36 ms of board time
    assert drv.health.lost == drv.health.corrupt == drv.health.duplicate == drv.health.out_of_order == 0
    assert drv.health.received >= len(s)
    assert drv.fault(c.frames[-1].host_t_ns) is None
    cal = drv.calibration()
    assert cal["backend"] == "lab" and cal["n_taxels"] == 16 and cal["adc_bits"] == 12
    assert cal["layers"] == ["superficial", "deep"] and cal["pitch_mm"] == 1.5


def test_sequence_wrap_end_to_end(board):
    offset = SEQ_MOD - 60  # the wire sequence number wraps after ~60 frames
    emu, drv, c = board(seq_offset=offset)
    assert c.until(lambda: len(c.frames) >= 150)
    s = c.seqs()
    assert s[0] < SEQ_MOD < s[-1]
    assert s == list(range(s[0], s[0] + len(s)))
    assert drv.health.lost == 0 and drv.health.out_of_order == 0
    assert_matches_twin(c.frames, emu, seq_offset=offset)


def test_injected_faults_are_counted(board):
    emu, drv, c = board()
    assert c.until(lambda: len(c.frames) >= 20)
    schedule = [("corrupt", "bit_flip"), None] * 4 + [("corrupt", "drop_byte"), None] * 3 + \
        [("corrupt", "insert_garbage"), None] * 2 + ["drop", None, "drop", "drop", None]
    emu.schedule(*schedule)
    assert c.until(lambda: emu.scheduled == 0)
    last = emu.sent[-1].seq
    assert c.until(lambda: c.frames and c.frames[-1].seq >= last + 5)
    # frames that never arrived intact show as sequence gaps, damage as corrupt events
    assert drv.health.lost == 4 + 3 + 3
    assert drv.health.corrupt == 4 + 3 + 2
    assert drv.parser.crc_failures == 4 + 3  # a dropped byte shortens a frame: its CRC fails
    assert_matches_twin(c.frames, emu)  # nothing damaged got through


def test_random_faults_never_deliver_a_wrong_frame(board):
    emu, drv, c = board(seed=3, p_bit_flip=0.05, p_drop_byte=0.05, p_insert_garbage=0.05, p_drop_frame=0.02)
    assert c.until(lambda: len(c.frames) >= 300)
    assert_matches_twin(c.frames, emu)
    assert drv.health.corrupt > 0 and drv.health.lost > 0
    s = c.seqs()
    assert s == sorted(set(s))


def test_stall_is_reported_then_clears(board):
    emu, drv, c = board()
    assert c.until(lambda: len(c.frames) >= 20)
    emu.stall(0.3)
    assert c.until(lambda: (drv.fault(time.monotonic_ns()) or "").startswith("skin stalled: no frame for"))
    assert c.until(lambda: drv.fault(time.monotonic_ns()) is None and emu.counts["stalled_frames"] > 0)
    n = len(c.frames)
    assert c.until(lambda: len(c.frames) > n + 10)
    assert drv.health.lost >= emu.counts["stalled_frames"] > 0  # frames of the stall never came


def test_disconnect_is_reported_as_link_lost(board):
    emu, drv, c = board()
    assert c.until(lambda: len(c.frames) >= 20)
    emu.disconnect()
    assert c.until(lambda: "link lost" in (drv.fault(time.monotonic_ns()) or ""))
    assert drv.fault(time.monotonic_ns()).startswith("skin: link lost (")
    t0 = time.monotonic()
    drv.disconnect()
    assert time.monotonic() - t0 < 2.0 and not drv.is_connected
    with pytest.raises(DeviceError, match=emu.path):  # the port went with the cable
        SkinBoardReader(SkinBoardConfig(port=emu.path, connect_timeout_s=0.2)).connect()


def test_reconnect_continues_the_sequence(board):
    emu, drv, c = board()
    assert c.until(lambda: len(c.frames) >= 20)
    drv.disconnect()
    n_made = emu.counts["no_host_frames"]
    deadline = time.monotonic() + 5.0
    while emu.counts["no_host_frames"] < n_made + 20 and time.monotonic() < deadline:  # the board scans on meanwhile
        time.sleep(0.01)
    assert emu.counts["no_host_frames"] >= n_made + 20, "the emulator made no frames while the port was closed"
    drv.connect()
    # frames received before disconnect() but not yet read stay in the driver's ring: the run
    # before the gap ends with the last frame of the first connection, wherever the reads fell
    def gaps():
        s = c.seqs()
        return s, [i for i in range(1, len(s)) if s[i] != s[i - 1] + 1]

    assert c.until(lambda: gaps()[1] != [] and len(c.frames) - gaps()[1][-1] >= 20)
    s, gaps = gaps()
    assert len(gaps) == 1, f"sequence gaps at {[(s[i - 1], s[i]) for i in gaps]}: expected one, the disconnection"
    last, first = s[gaps[0] - 1], s[gaps[0]]
    assert drv.health.reconnects == 1
    assert first - last - 1 >= 20  # at least the frames the board made while the port was closed
    assert drv.health.lost == first - last - 1  # missed while disconnected, and nothing else
    assert_matches_twin(c.frames, emu)


def _read_for(fd, seconds):
    """Everything the port delivers within `seconds` (a non-blocking fd)."""
    out = bytearray()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            out += os.read(fd, 1 << 16)
        except BlockingIOError:
            time.sleep(0.002)
    return bytes(out)


def test_opening_the_port_delivers_what_the_board_sends_now(realtime_world):
    """A CDC device streams to a host that has the port open; nothing made while the port was
    closed, and nothing a host left unread, comes out at the next open."""
    rt = realtime_world("platform")
    made_per_s = 424 * FRAME_LEN  # the board's byte rate
    with SkinBoardEmulator(rt) as emu:
        for attempt in range(2):  # first open; then reopen after leaving bytes unread
            time.sleep(1.0)  # nobody reads the port meanwhile
            fd = os.open(emu.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            try:
                got = _read_for(fd, 0.1)
                time.sleep(0.3 if attempt == 0 else 0.0)  # frames pile up unread before the close
            finally:
                os.close(fd)
            assert 0 < len(got) <= made_per_s * 0.3, (attempt, len(got))  # 0.1 s read + slack, not seconds of backlog
        assert emu.counts["no_host_frames"] > 424  # the frames of the closed seconds were never sent


def test_host_writes_are_read_not_blocked(realtime_world):
    rt = realtime_world("platform")
    payload = b"\x55" * (1 << 20)  # far more than a pty buffers
    with SkinBoardEmulator(rt) as emu:
        fd = os.open(emu.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            view, deadline = memoryview(payload), time.monotonic() + 20.0
            while view and time.monotonic() < deadline:
                try:
                    view = view[os.write(fd, view[:4096]):]
                except BlockingIOError:
                    time.sleep(0.001)
                _read_for(fd, 0)  # the host keeps reading the stream too
            assert not view, f"{len(view)} bytes could not be written: the board does not read the port"
            assert wait_for(lambda: emu.counts["host_bytes"] == len(payload))
        finally:
            os.close(fd)


def test_ring_keeps_the_newest_frames(board):
    emu, drv, c = board(ring_frames=64)  # not read for a while: the oldest frames go, counted
    deadline = time.monotonic() + 5.0
    while drv.ring_dropped == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    frames = drv.read_available()
    assert len(frames) == 64 and drv.ring_dropped > 0
    s = [f.seq for f in frames]
    assert s == list(range(s[0], s[0] + 64))


def test_connect_errors_name_the_port(tmp_path):
    missing = str(tmp_path / "ttyACM9")
    with pytest.raises(DeviceError, match="ttyACM9.*check the USB cable"):
        SkinBoardReader(SkinBoardConfig(port=missing, connect_timeout_s=0.2)).connect()
    master, slave = os.openpty()  # a port that sends only frames with a bad CRC
    tty.setraw(slave)
    sup = np.zeros((16, 16), np.uint16)
    bad = b"noise" + encode_frame(0, 0, sup, sup)[:-1] + b"\x00"
    done = threading.Event()

    def babble():
        while not done.wait(0.01):
            os.write(master, bad)

    t = threading.Thread(target=babble, daemon=True)
    t.start()
    try:
        path = os.ttyname(slave)
        drv = SkinBoardReader(SkinBoardConfig(port=path, connect_timeout_s=0.3))
        with pytest.raises(DeviceError, match=f"{path}: no valid frame within 0.3 s .*[1-9][0-9]* CRC failures"):
            drv.connect()
        assert not drv.is_connected
    finally:
        done.set()
        t.join()
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize("field,value", [("stall_timeout_s", 0.06), ("stall_timeout_s", 0.0), ("port", " "),
                                         ("connect_timeout_s", 0), ("ring_frames", 10)])
def test_config_rejects_bad_values(field, value):
    with pytest.raises(ConfigError, match=f"hardware.skin_board.{field}"):
        SkinBoardConfig(**{field: value})


class _HandBoard:
    """The test as the board: frames written to a pty by hand, board time = host time - base."""

    def __init__(self, monkeypatch):
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.base_ns, self.seq, self.last_write_ns = time.monotonic_ns(), 0, 0
        self.zeros = np.zeros((16, 16), dtype=np.uint16)
        # the receive thread can be held back before it waits for bytes, as a thread the
        # scheduler does not run
        self.run_rx = threading.Event()
        self.run_rx.set()
        self.monkeypatch = monkeypatch

    def hold_back(self, drv):
        real = drv._wait_readable

        def gated(ser):
            self.run_rx.wait()
            return real(ser)

        self.monkeypatch.setattr(drv, "_wait_readable", gated)

    def send(self):
        self.last_write_ns = time.monotonic_ns()
        os.write(self.master, encode_frame(self.seq, (self.last_write_ns - self.base_ns) // 1000, self.zeros,
                                           self.zeros))
        self.seq += 1

    def close(self):
        self.run_rx.set()
        os.close(self.master)
        os.close(self.slave)


def test_frames_held_in_the_os_while_the_reader_is_not_run_are_no_stall(monkeypatch):
    board = _HandBoard(monkeypatch)
    # a short bound: the frames of a pause longer than it fit in the pty's buffer
    drv = SkinBoardReader(SkinBoardConfig(port=os.ttyname(board.slave), connect_timeout_s=3.0,
                                          stall_timeout_s=0.02))
    board.hold_back(drv)
    try:
        connected = threading.Event()

        def stream():  # the board streams from power-on; opening the port flushes what came before
            while not connected.wait(0.005):
                board.send()

        sender = threading.Thread(target=stream, daemon=True)
        sender.start()
        drv.connect()
        connected.set()
        sender.join()
        for _ in range(10):
            board.send()
        assert wait_for(lambda: drv.fault(board.last_write_ns) is None and len(drv.read_available()) > 0)
        bound_ns = drv.cfg.stall_timeout_s * 1e9
        board.run_rx.clear()
        time.sleep(2 * drv.cfg.read_timeout_s)  # a select already under way returns
        paused_from = board.seq
        first_paused_ns = None
        # the board streams on for more than the bound (its own clock), fewer frames than a pty holds
        while first_paused_ns is None or board.last_write_ns - first_paused_ns <= 1.5 * bound_ns:
            board.send()
            first_paused_ns = first_paused_ns or board.last_write_ns
            time.sleep(0.005)
        assert board.seq - paused_from <= 12, "more frames than the pty buffers: the test would lose some"
        # judged at the moment the board wrote its newest frame, the receive thread not having run since
        assert drv.fault(board.last_write_ns + 1_000_000) is None
        frames = drv.read_available()
        assert frames[-1].seq == board.seq - 1 and drv.health.lost == 0  # the drain delivered every frame
        # the board now goes silent: reported by its own clock, the newest frame made > 10 bounds ago
        reason = drv.fault(board.last_write_ns + int(10 * bound_ns))
        assert reason is not None and reason.startswith("skin stalled: no frame for")
        assert f"seq {board.seq - 1}" in reason
    finally:
        board.run_rx.set()
        drv.disconnect()
        board.close()
