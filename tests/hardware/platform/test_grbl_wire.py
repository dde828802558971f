"""GRBL 1.1 wire module on captured lines (as GRBL 1.1h prints them) and the character-counting
arithmetic of interface.md."""

import pytest

from hardware.platform import wire

# Captured from GRBL 1.1 (interface.md examples and 1.1h's report formats).
STATUS_IDLE = b"<Idle|MPos:0.000,0.000,5.000|FS:0,0|WCO:0.000,0.000,0.000>\r\n"
STATUS_RUN = b"<Run|MPos:1.250,-2.500,5.000|FS:1200,0|Ov:100,100,100>\r\n"
STATUS_HOLD1 = b"<Hold:1|MPos:3.000,0.000,5.000|FS:250,0>\r\n"
STATUS_HOLD0 = b"<Hold:0|MPos:3.100,0.000,5.000|FS:0,0>\r\n"
STATUS_WPOS = b"<Idle|WPos:-2.500,0.000,11.000|F:500|Pn:XZ>\r\n"
BANNER = b"\r\nGrbl 1.1h ['$' for help]\r\n"


def lines(raw: bytes) -> list[str]:
    return wire.LineSplitter().feed(raw)


def test_status_reports_parse_with_state_position_and_feed():
    st = wire.parse_line(lines(STATUS_IDLE)[0])
    assert (st.state, st.substate, st.mpos, st.wco, st.feed, st.spindle) == \
        ("Idle", None, (0.0, 0.0, 5.0), (0.0, 0.0, 0.0), 0.0, 0.0)
    assert not st.moving
    run = wire.parse_line(lines(STATUS_RUN)[0])
    assert run.state == "Run" and run.mpos == (1.25, -2.5, 5.0) and run.feed == 1200.0 and run.moving
    assert run.fields["Ov"] == "100,100,100"
    h1, h0 = (wire.parse_line(lines(s)[0]) for s in (STATUS_HOLD1, STATUS_HOLD0))
    assert (h1.state, h1.substate, h1.moving) == ("Hold", 1, True)
    assert (h0.state, h0.substate, h0.moving) == ("Hold", 0, False)
    w = wire.parse_line(lines(STATUS_WPOS)[0])
    assert w.mpos is None and w.wpos == (-2.5, 0.0, 11.0) and w.feed == 500.0


def test_responses_alarms_banner_and_push_messages():
    raw = (b"ok\r\nerror:22\r\nALARM:2\r\n[MSG:Reset to continue]\r\n" + BANNER
           + b"[MSG:'$H'|'$X' to unlock]\r\n$110=1200.000\r\n>G54G20:ok\r\n>G1:error:22\r\n[GC:G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0]\r\n")
    msgs = [wire.parse_line(s) for s in lines(raw)]
    assert msgs == [wire.Ok(), wire.Error(22), wire.Alarm(2), wire.Feedback("MSG", "Reset to continue"),
                    wire.Banner("1.1h"), wire.Feedback("MSG", "'$H'|'$X' to unlock"), wire.Setting(110, "1200.000"),
                    wire.StartupLine("G54G20", "ok"), wire.StartupLine("G1", "error:22"),
                    wire.Feedback("GC", "G0 G54 G17 G21 G90 G94 M5 M9 T0 F0 S0")]
    assert "feed rate not set" in str(msgs[1]) and "soft limit" in str(msgs[2])


@pytest.mark.parametrize("bad", ["<Idle|MPos:1.0,abc,2.0|FS:0,0>", "<Bogus|MPos:0,0,0>", "<Idle|FS:0,0>",
                                 "<Idle|MPos:0.000,0.000>", "okk", "error:x", "Grbl 1.1h", "\ufffd\ufffdgarbage",
                                 "<Idle|MPos:0.000,0.000,0.000"])
def test_corrupt_lines_are_rejected(bad):
    with pytest.raises(wire.GrblParseError):
        wire.parse_line(bad)


def test_splitter_reassembles_lines_across_reads():
    sp = wire.LineSplitter()
    chunks = [b"ok\r\n<Id", b"le|MPos:0.000,0.000,0.000|FS:0,0>\r\nerr", b"or:9", b"\r\n\r\n", b"\xff\xfe\n"]
    got = [line for c in chunks for line in sp.feed(c)]
    assert got[:3] == ["ok", "<Idle|MPos:0.000,0.000,0.000|FS:0,0>", "error:9"]
    assert len(got) == 4 and "\ufffd" in got[3]  # the non-ASCII line comes out for the parser to reject
    sp.feed(b"x" * 600)  # noise with no line end is dropped, not buffered forever
    assert sp.overlong == 1 and sp.feed(b"ok\n") == ["ok"]


def test_move_line_bytes_and_emulator_parse_round_trip():
    raw = wire.encode_move([1.5, -2.0, 5.0], 600.0)
    assert raw == b"G21G90G1X1.500Y-2.000Z5.000F600.0\n"
    block, overflow = wire.clean_line(raw.rstrip(b"\n"))
    assert not overflow
    assert wire.parse_words(block) == [("G", 21.0), ("G", 90.0), ("G", 1.0), ("X", 1.5), ("Y", -2.0), ("Z", 5.0),
                                       ("F", 600.0)]
    assert wire.clean_line(b"g1 x1 (a comment) y.5 ; the rest")[0] == "G1X1Y.5"
    assert wire.clean_line(b"G1" + b"X1" * 40)[1]  # longer than GRBL's 80-byte line buffer
    with pytest.raises(ValueError):
        wire.encode_line("G1X1\r")
    with pytest.raises(wire.GcodeError) as e:
        wire.parse_words("G1X")
    assert e.value.code == 2


def test_status_format_round_trip():
    raw = wire.format_status("Hold", 0, (1.0, -2.0, 3.25), 0.0, 0.0, wco=(0.0, 0.0, 0.0))
    assert raw == b"<Hold:0|MPos:1.000,-2.000,3.250|FS:0,0|WCO:0.000,0.000,0.000>\r\n"
    st = wire.parse_line(lines(raw)[0])
    assert (st.state, st.substate, st.mpos) == ("Hold", 0, (1.0, -2.0, 3.25))
    assert wire.parse_line(lines(wire.format_banner())[0]) == wire.Banner("1.1h")


def test_char_counter_follows_the_interface_md_example():
    # interface.md: lines of 25, 40, 31, 58 and 20 characters into a 128-byte buffer
    cc = wire.CharCounter(128)
    for n in (25, 40, 31):
        assert cc.fits(n)
        cc.sent(n)
    assert cc.outstanding == 96 and not cc.fits(58)
    assert cc.acked() == 25 and cc.outstanding == 71 and not cc.fits(58)  # 129 > 128
    assert cc.acked() == 40 and cc.fits(58)
    cc.sent(58)
    assert cc.fits(20)
    cc.sent(20)
    assert cc.outstanding == 31 + 58 + 20 and cc.in_flight == 3
    with pytest.raises(ValueError):
        cc.sent(20)  # 129 bytes would overflow
    cc.clear()
    assert cc.outstanding == 0 and cc.in_flight == 0
    with pytest.raises(ValueError):
        cc.acked()  # a response with nothing in flight
    with pytest.raises(ValueError):
        cc.sent(129)  # can never fit


@pytest.mark.parametrize("kw, key", [({"stall_timeout_s": 0.1}, "stall_timeout_s"), ({"units": "cm"}, "units"),
                                     ({"status_rate_hz": 10.0}, "status_rate_hz"),
                                     ({"offset_mm": (0.0, float("nan"), 0.0)}, "offset_mm")])
def test_config_names_the_bad_key(kw, key):
    from hardware.platform import GrblPlatformConfig
    from layerskin_exp.config import ConfigError

    with pytest.raises(ConfigError, match=f"hardware.platform.{key}"):
        GrblPlatformConfig(**kw)
    assert GrblPlatformConfig(units="inch").mm_per_unit == 25.4
