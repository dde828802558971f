"""The GRBL emulator speaks GRBL 1.1 on the wire: raw bytes through its pty, no driver."""

import os
import select
import time

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


def test_receive_buffer_overflow_is_counted(grbl):
    emu, port = grbl
    port.send(b"(" + b"x" * 199)  # 200 bytes without a line end: 72 beyond the 128-byte buffer
    t0 = time.monotonic()
    while emu.rx_overflow_bytes < 72 and time.monotonic() - t0 < 2:
        time.sleep(0.005)
    assert emu.rx_overflow_bytes == 72


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
