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


def status(port) -> bytes:
    port.send(b"?")
    return port.read_until(b">\r\n")


def wait_status(port, prefix: bytes, timeout_s: float = 5.0) -> bytes:
    """Poll `?` until a report starts with prefix; returns that report."""
    t0 = time.monotonic()
    while True:
        rep = status(port)
        if rep.startswith(prefix):
            return rep
        assert time.monotonic() - t0 < timeout_s, rep
        time.sleep(0.005)


def mpos(report: bytes) -> np.ndarray:
    field = report.split(b"MPos:")[1].split(b"|")[0]
    return np.array([float(v) for v in field.split(b",")])


def test_jog_moves_without_touching_the_parser_state(grbl):
    emu, port = grbl
    port.send(b"$J=G91X1F600\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"
    assert b"|FS:600," in wait_status(port, b"<Jog|")
    assert np.allclose(mpos(wait_status(port, b"<Idle|")), [1.0, 0.0, 5.0])
    port.send(b"$G\n")  # G91 and F600 held for the jog only
    assert port.read_until(b"ok\r\n") == b"[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\r\nok\r\n"
    port.send(b"$J=X0Y0Z40F600\n")  # beyond the travel: skipped with error:15, no alarm
    assert port.read_until(b"\r\n") == b"error:15\r\n"
    assert status(port).startswith(b"<Idle|")
    for line, answer in ((b"$J=G1X1F600", b"error:16"), (b"$J=X1", b"error:22"), (b"$JX1F600", b"error:3")):
        port.send(line + b"\n")
        assert port.read_until(b"\r\n") == answer + b"\r\n", line
    port.send(b"$J=G91Z10F300\n")  # G-code is locked out while jogging
    port.send(b"G1Z6F600\n")
    assert port.read_until(b"error:9\r\n") == b"ok\r\nerror:9\r\n"
    port.send(b"\x18")  # (a reset while jogging: ALARM:3, as while running)
    assert port.read_until(b"unlock]\r\n").startswith(b"ALARM:3\r\n")
    port.send(b"$J=X1F600\n")
    assert port.read_until(b"\r\n") == b"error:8\r\n"  # jogs only from Idle or Jog


def test_jog_cancel_stops_flushes_the_queue_and_resyncs_the_parser(grbl):
    emu, port = grbl
    port.send(b"$J=G91Z10F300\n$J=G91Z10F300\n")  # 2 x 10 mm at 5 mm/s, queued
    assert port.read_until(b"ok\r\nok\r\n") == b"ok\r\nok\r\n"
    assert _wait(lambda: mpos(status(port))[2] > 6.0)
    port.send(b"\x85")
    stop = mpos(wait_status(port, b"<Idle|"))
    assert 6.0 < stop[2] < 15.0  # stopped along the first jog; the second was flushed
    port.send(b"$J=G91Z1F600\n")  # relative to where the cancel left the stage
    assert port.read_until(b"\r\n") == b"ok\r\n"
    assert np.allclose(mpos(wait_status(port, b"<Idle|")), stop + [0.0, 0.0, 1.0], atol=1e-3)
    port.send(b"$J=G91Z5F300\n")  # a feed hold cancels a jog too: Idle, not Hold
    port.read_until(b"ok\r\n")
    wait_status(port, b"<Jog|")
    port.send(b"!")
    wait_status(port, b"<Idle|")


def test_spindle_coolant_tool_and_g53_words_are_accepted_and_reported(grbl):
    emu, port = grbl
    port.send(b"M3 S500 M8 T2\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"
    port.send(b"$G\n")
    assert port.read_until(b"ok\r\n") == b"[GC:G0 G54 G17 G21 G90 G94 M3 M8 T2 F0 S500]\r\nok\r\n"
    # the first report after a reset carries WCO and defers Ov by one report (report.c); Ov carries A:
    reports = [status(port) for _ in range(3)]
    assert b"|FS:0,500|" in reports[2] and reports[2].endswith(b"|Ov:100,100,100|A:SF>\r\n"), reports
    for line in (b"M5", b"M9", b"S0", b"T0", b"G91", b"G53G0X1Y0Z5"):
        port.send(line + b"\n")
        assert port.read_until(b"\r\n") == b"ok\r\n", line
    assert np.allclose(mpos(wait_status(port, b"<Idle|")), [1.0, 0.0, 5.0])  # G53: machine X1, not +1
    for line, answer in ((b"M7", b"error:20"), (b"M3M5", b"error:21"), (b"T256", b"error:38")):
        port.send(line + b"\n")
        assert port.read_until(b"\r\n") == answer + b"\r\n", line


def test_program_end_waits_for_the_motion_then_resets_the_modes(grbl):
    emu, port = grbl
    port.send(b"G91 M3 S100\n")
    port.read_until(b"ok\r\n")
    port.send(b"G0 X0.5 M30\n")
    assert port.read_until(b"ok\r\n") == b"[MSG:Pgm End]\r\nok\r\n"
    assert np.allclose(emu._twin_pos(), [0.5, 0.0, 5.0], atol=1e-3)  # answered once the move was done
    port.send(b"$G\n")
    assert port.read_until(b"ok\r\n") == b"[GC:G1 G54 G17 G21 G90 G94 M5 M9 T0 F0 S100]\r\nok\r\n"


def test_program_pause_holds_until_cycle_start(grbl):
    emu, port = grbl
    port.send(b"G0X0.5\nM0\nG0X0\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"
    wait_status(port, b"<Hold:0|")  # the move done, then the pause
    assert port.buf == b""  # M0 unanswered, the next line waits behind it
    port.send(b"~")
    assert port.read_until(b"ok\r\nok\r\n") == b"ok\r\nok\r\n"
    assert np.allclose(mpos(wait_status(port, b"<Idle|")), [0.0, 0.0, 5.0])


def test_a_third_party_streamer_completes_a_job_that_ends_in_m5_m30(grbl):
    grbl_streamer = pytest.importorskip("grbl_streamer")
    emu, port = grbl
    port.close()
    port.close = lambda: None
    events = []
    g = grbl_streamer.GrblStreamer(lambda event, *data: events.append((event, data)))
    g.cnect(emu.path, 115200)
    try:
        assert _wait(lambda: any(e == "on_boot" for e, _ in events))
        g.write("G21 G90\nM3 S1000\nG1 X0.5 Y0 Z5 F1200\nM5\nM9\nG0 X0 Y0 Z5\nM30\n")
        g.job_run()
        assert _wait(lambda: any(e == "on_job_completed" for e, _ in events), 10.0)
        assert not [e for e in events if e[0] in ("on_error", "on_alarm")], events
        assert _wait(lambda: emu.state == "Idle" and np.allclose(emu._twin_pos(), [0.0, 0.0, 5.0], atol=1e-3))
    finally:
        g.disconnect()


def test_startup_lines_are_validated_stored_and_run_after_a_reset(grbl):
    emu, port = grbl
    port.send(b"$N\n")
    assert port.read_until(b"ok\r\n") == b"$N0=\r\n$N1=\r\nok\r\n"
    port.send(b"$N0=G20 G91\n")
    assert port.read_until(b"\r\n") == b"ok\r\n"
    port.send(b"$N1=G5\n")  # not valid G-code: not stored
    assert port.read_until(b"\r\n") == b"error:20\r\n"
    port.send(b"$N\n")
    assert port.read_until(b"ok\r\n") == b"$N0=G20G91\r\n$N1=\r\nok\r\n"
    port.send(b"\x18")
    assert port.read_until(b"G91:ok\r\n") == b"\r\nGrbl 1.1h ['$' for help]\r\n>G20G91:ok\r\n"
    port.send(b"$G\n")
    assert port.read_until(b"ok\r\n").startswith(b"[GC:G0 G54 G17 G20 G91 G94")


def test_restore_defaults_and_wipe(grbl):
    emu, port = grbl
    port.send(b"$110=300\n$N0=G21\n")
    assert port.read_until(b"ok\r\nok\r\n") == b"ok\r\nok\r\n"
    port.send(b"$RST=$\n")  # settings back, then a reset (startup lines kept)
    assert port.read_until(b"G21:ok\r\n") == \
        b"[MSG:Restoring defaults]\r\nok\r\n\r\nGrbl 1.1h ['$' for help]\r\n>G21:ok\r\n"
    port.send(b"$$\n")
    assert b"$110=1200.000\r\n" in port.read_until(b"ok\r\n")
    port.send(b"$RST=#\n")
    assert port.read_until(b"help]\r\n>G21:ok\r\n").startswith(b"[MSG:Restoring defaults]\r\nok\r\n")
    port.send(b"$RST=*\n")  # everything, startup lines included
    assert port.read_until(b"help]\r\n") == b"[MSG:Restoring defaults]\r\nok\r\n\r\nGrbl 1.1h ['$' for help]\r\n"
    port.send(b"$N\n")
    assert port.read_until(b"ok\r\n") == b"$N0=\r\n$N1=\r\nok\r\n"
    port.send(b"$RST=X\n")
    assert port.read_until(b"\r\n") == b"error:3\r\n"


def test_sleep_ignores_lines_until_a_reset_which_comes_back_in_alarm(grbl):
    emu, port = grbl
    port.send(b"$SLP\n")
    assert port.read_until(b"Sleeping]\r\n") == b"ok\r\n[MSG:Sleeping]\r\n"
    assert status(port).startswith(b"<Sleep|")
    port.send(b"G21\n")  # not read while asleep
    assert status(port).startswith(b"<Sleep|") and port.buf == b""
    port.send(b"\x18")
    assert port.read_until(b"unlock]\r\n") == b"\r\nGrbl 1.1h ['$' for help]\r\n[MSG:'$H'|'$X' to unlock]\r\n"
    port.send(b"$X\n")
    assert port.read_until(b"ok\r\n") == b"[MSG:Caution: Unlocked]\r\nok\r\n"


def _speed_mm_s(emu) -> float:
    with emu.rt.lock:
        return float(np.linalg.norm(emu.rt.rig.platform.scene.stage.velocity))


def test_feed_override_bytes_change_the_report_and_the_speed(grbl):
    emu, port = grbl
    port.send(b"G1X0Y0Z25F600\n")  # 20 mm at 10 mm/s
    port.read_until(b"ok\r\n")
    wait_status(port, b"<Run|")
    port.send(b"\x91\x93\x93")  # +10 %, +1 %, +1 %
    rep = status(port)  # a change is reported on the next report
    assert b"|FS:672,0|" in rep and rep.endswith(b"|Ov:112,100,100>\r\n"), rep
    assert _wait(lambda: abs(_speed_mm_s(emu) - 11.2) < 1e-6)  # the stage runs at 672 mm/min
    port.send(b"\x94\x92")
    assert status(port).endswith(b"|Ov:101,100,100>\r\n")
    assert _wait(lambda: abs(_speed_mm_s(emu) - 10.1) < 1e-6)
    port.send(b"\x92" * 12)  # clamped at 10 %
    assert status(port).endswith(b"|Ov:10,100,100>\r\n")
    assert _wait(lambda: abs(_speed_mm_s(emu) - 1.0) < 1e-6)
    port.send(b"\x90")
    assert b"|FS:600,0|" in status(port)
    assert _wait(lambda: abs(_speed_mm_s(emu) - 10.0) < 1e-6)
    port.send(b"\x91" * 15)  # at most 200 %, and never above the axes' max rate (1200 mm/min)
    rep = status(port)
    assert b"|FS:1200,0|" in rep and rep.endswith(b"|Ov:200,100,100>\r\n")
    port.send(b"\x18")  # a reset brings the override back to 100 %
    port.read_until(b"unlock]\r\n")
    assert emu.feed_override == 100
