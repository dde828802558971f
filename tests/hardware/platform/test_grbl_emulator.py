"""The GRBL emulator speaks GRBL 1.1 on the wire: raw bytes through its pty, no driver."""

import os
import select
import time

import numpy as np
import pytest

from hardware.platform.emulator import GrblEmulator


def warm(rt):
    """Let the world's first advance (kernel compilation) pass before timing anything."""
    t0 = time.monotonic()
    while rt.world.t_s < 0.05 and time.monotonic() - t0 < 60:
        time.sleep(0.01)


class Port:
    def __init__(self, path):
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        self.buf = b""

    def send(self, raw: bytes) -> None:
        os.write(self.fd, raw)

    def read_until(self, token: bytes, timeout_s: float = 2.0) -> bytes:
        t0 = time.monotonic()
        while token not in self.buf:
            if time.monotonic() - t0 > timeout_s:
                raise AssertionError(f"no {token!r} in {self.buf!r}")
            r, _, _ = select.select([self.fd], [], [], 0.01)
            if r:
                self.buf += os.read(self.fd, 4096)
        i = self.buf.index(token) + len(token)
        out, self.buf = self.buf[:i], self.buf[i:]
        return out

    def close(self):
        os.close(self.fd)


@pytest.fixture
def grbl(realtime_world):
    rt = realtime_world("platform")
    warm(rt)
    emu = GrblEmulator(rt)
    port = Port(emu.start())
    assert port.read_until(b"['$' for help]\r\n") == b"\r\nGrbl 1.1h ['$' for help]\r\n"  # power-up banner
    yield emu, port
    port.close()
    emu.stop()


def test_responses_settings_and_errors(grbl):
    emu, port = grbl
    port.send(b"$$\n")
    out = port.read_until(b"ok\r\n")
    assert b"$20=1\r\n" in out and b"$110=1200.000\r\n" in out and b"$130=30.000\r\n" in out
    port.send(b"G1X1\n")  # no feed rate yet
    assert port.read_until(b"\r\n") == b"error:22\r\n"
    port.send(b"G5X1\n")
    assert port.read_until(b"\r\n") == b"error:20\r\n"
    port.send(b"G0G1X1\n")
    assert port.read_until(b"\r\n") == b"error:21\r\n"
    port.send(b"$Q\n")
    assert port.read_until(b"\r\n") == b"error:3\r\n"
    # GRBL ends a line at \r or \n: CRLF is two lines and draws two responses
    port.send(b"G21\r\n")
    assert port.read_until(b"ok\r\nok\r\n") == b"ok\r\nok\r\n"


def test_status_report_and_realtime_bytes_bypass_the_buffer(grbl):
    emu, port = grbl
    port.send(b"G21G90")  # half a line in the receive buffer...
    port.send(b"?")  # ...does not delay a real-time status request
    assert port.read_until(b">\r\n").startswith(b"<Idle|MPos:0.000,0.000,5.000|FS:0,0")
    port.send(b"\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"


def test_a_line_longer_than_the_buffers_answers_error_11_and_the_parser_goes_on(grbl):
    emu, port = grbl
    port.send(b"G1X1F600" + b"0" * 200 + b"\n")  # 209 bytes: past the 128-byte receive and 80-char line buffers
    assert port.read_until(b"\r\n") == b"error:11\r\n"
    port.send(b"G21\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"
    assert emu.rx_overflow_bytes == 0  # GRBL was free: it emptied its receive buffer as the bytes came


def test_coordinate_offsets_report(grbl):
    emu, port = grbl
    port.send(b"$#\n")
    z = b"0.000,0.000,0.000"
    expected = b"".join(b"[G%d:%s]\r\n" % (n, z) for n in (54, 55, 56, 57, 58, 59, 28, 30, 92))
    assert port.read_until(b"ok\r\n") == expected + b"[TLO:0.000]\r\n[PRB:" + z + b":0]\r\nok\r\n"


def test_check_mode_parses_without_moving_and_leaving_it_resets(grbl):
    emu, port = grbl
    port.send(b"$C\n")
    assert port.read_until(b"ok\r\n") == b"[MSG:Enabled]\r\nok\r\n"
    port.send(b"G21G90G1X1Y1Z6F600\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"
    port.send(b"G1X1\n")  # parse errors still answer
    port.send(b"G5\n")
    assert port.read_until(b"error:20\r\n") == b"ok\r\nerror:20\r\n"
    port.send(b"?")
    assert port.read_until(b">\r\n").startswith(b"<Check|MPos:0.000,0.000,5.000|")  # nothing moved
    port.send(b"$C\n")
    assert port.read_until(b"help]\r\n") == b"[MSG:Disabled]\r\nok\r\n\r\nGrbl 1.1h ['$' for help]\r\n"
    port.send(b"?")
    assert port.read_until(b">\r\n").startswith(b"<Idle|MPos:0.000,0.000,5.000|")


def test_a_third_party_streaming_library_connects_and_streams(grbl):
    """grbl-streamer (PyPI) reads `$#` at boot and halts on any error; it streams with
    character counting against GRBL's 128-byte buffer."""
    grbl_streamer = pytest.importorskip("grbl_streamer")
    emu, port = grbl
    port.close()  # the library is the only reader of the port
    port.close = lambda: None
    events = []
    g = grbl_streamer.GrblStreamer(lambda event, *data: events.append((event, data)))
    g.cnect(emu.path, 115200)
    try:
        assert _wait(lambda: any(e == "on_boot" for e, _ in events))
        g.get_hash_state()
        assert _wait(lambda: ("[PRB:0.000,0.000,0.000:0]",) in [d for e, d in events if e == "on_read"]), \
            (emu.error, emu.lines_received, events)  # the last line of the `$#` answer
        assert g.settings_hash["G54"] == g.settings_hash["G92"] == g.settings_hash["PRB"] == (0.0, 0.0, 0.0)
        g.write("G21 G90\nG1 X0.5 Y0 Z5 F1200\nG1 X0.5 Y0.5 Z5.5\n")
        n = len(events)
        g.job_run()
        assert _wait(lambda: any(e == "on_job_completed" for e, _ in events[n:]), 10.0)  # every line ok'd

        def at_target():
            with emu.rt.lock:
                return np.allclose(emu.rt.rig.platform.position_mm(), [0.5, 0.5, 5.5], atol=0.002)

        assert _wait(at_target, 10.0)
        assert not [e for e in events if e[0] in ("on_error", "on_alarm")], events
    finally:
        g.disconnect()


def _wait(pred, timeout_s: float = 3.0) -> bool:
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout_s:
            return False
        time.sleep(0.005)
    return True


def test_feed_hold_then_reset_keeps_position_and_reset_in_motion_alarms(grbl):
    emu, port = grbl
    port.send(b"G21G90G1X0Y0Z15F1200\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"
    time.sleep(0.1)
    port.send(b"!")
    t0 = time.monotonic()
    while True:
        port.send(b"?")
        rep = port.read_until(b">\r\n")
        if rep.startswith(b"<Hold:0"):
            break
        assert time.monotonic() - t0 < 2
    port.send(b"\x18")
    assert port.read_until(b"help]\r\n").endswith(b"\r\nGrbl 1.1h ['$' for help]\r\n")
    port.send(b"?")
    assert port.read_until(b">\r\n").startswith(b"<Idle|")
    # a reset while running loses steps: ALARM:3 and GRBL comes back locked
    port.send(b"G1Z20F1200\n")
    port.read_until(b"ok\r\n")
    time.sleep(0.05)
    port.send(b"\x18")
    assert port.read_until(b"unlock]\r\n") == b"ALARM:3\r\n\r\nGrbl 1.1h ['$' for help]\r\n[MSG:'$H'|'$X' to unlock]\r\n"
    port.send(b"G1Z6F600\n")
    assert port.read_until(b"\r\n") == b"error:9\r\n"
    port.send(b"$X\n")
    assert port.read_until(b"ok\r\n") == b"[MSG:Caution: Unlocked]\r\nok\r\n"


def test_soft_limit_alarm_blocks_until_reset(grbl):
    emu, port = grbl
    port.send(b"G1X0Y0Z40F600\n")  # beyond z travel (workspace max 30 mm)
    assert port.read_until(b"continue]\r\n") == b"ALARM:2\r\n[MSG:Reset to continue]\r\n"
    port.send(b"G1Z6F600\n")  # ignored until reset: no response
    port.send(b"?")
    assert port.read_until(b">\r\n").startswith(b"<Alarm|")
    assert port.buf == b""
    port.send(b"\x18")
    port.read_until(b"unlock]\r\n")
    assert emu.state == "Alarm"


def test_feed_above_max_rate_is_clamped_and_dwell_waits(grbl):
    emu, port = grbl
    port.send(b"$110=300\n")  # X max rate 300 mm/min = 5 mm/s
    assert port.read_until(b"\r\n") == b"ok\r\n"
    port.send(b"G21G90G1X1Y0Z5F1200\n")  # along X at 1200 mm/min requested
    assert port.read_until(b"\r\n") == b"ok\r\n"
    t0 = time.monotonic()
    while True:
        port.send(b"?")
        rep = port.read_until(b">\r\n")
        if rep.startswith(b"<Run"):
            break
        assert time.monotonic() - t0 < 2
    assert b"|FS:300,0" in rep
    port.send(b"G4P0.05\n")  # answered once the move (1 mm at 5 mm/s) is done and 50 ms passed
    assert port.read_until(b"\r\n", timeout_s=3.0) == b"ok\r\n"
    port.send(b"?")
    assert port.read_until(b">\r\n").startswith(b"<Idle|MPos:1.000,0.000,5.000")
