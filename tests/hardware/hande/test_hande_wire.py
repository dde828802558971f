"""URCap socket wire module on captured request/reply bytes and the unit calibration."""

import pytest

from hardware.hande import wire


def test_requests_encode_as_the_urcap_expects():
    assert wire.encode_set([("POS", 128), ("SPE", 255), ("FOR", 0), ("GTO", 1)]) == b"SET POS 128 SPE 255 FOR 0 GTO 1\n"
    assert wire.encode_set([("ACT", 1)]) == b"SET ACT 1\n"
    assert wire.encode_get("STA") == b"GET STA\n"
    with pytest.raises(ValueError):
        wire.encode_set([("STA", 3)])  # read-only
    with pytest.raises(ValueError):
        wire.encode_set([("POS", 256)])
    with pytest.raises(ValueError):
        wire.encode_get("XYZ")


def test_ack_reply_has_no_line_end_and_may_arrive_in_pieces():
    assert wire.take_ack(b"") is None
    assert wire.take_ack(b"ac") is None
    assert wire.take_ack(b"ack") == (True, b"")
    assert wire.take_ack(b"\nack") == (True, b"")  # a line end left by a previous reply
    with pytest.raises(wire.HandEProtocolError):
        wire.take_ack(b"POS 3\n")
    with pytest.raises(wire.HandEProtocolError):
        wire.take_ack(b"?\n")


def test_get_reply_is_the_variable_and_a_value_on_one_line():
    assert wire.take_value(b"POS 1", "POS") is None
    assert wire.take_value(b"POS 12\n", "POS") == (12, b"")
    assert wire.take_value(b"STA 3\nOBJ", "STA") == (3, b"OBJ")
    assert wire.take_value(b"\r\nFLT 14\r\n", "FLT") == (14, b"")
    for bad, var in ((b"OBJ 3\n", "POS"), (b"POS x\n", "POS"), (b"?\n", "POS"), (b"POS 1 2\n", "POS")):
        with pytest.raises(wire.HandEProtocolError):
            wire.take_value(bad, var)
    with pytest.raises(wire.HandEProtocolError):
        wire.take_value(b"x" * 100, "POS")  # no line end in sight


def test_requests_parse_on_the_emulator_side():
    assert wire.parse_request(b"SET POS 128 GTO 1") == wire.SetRequest((("POS", 128), ("GTO", 1)))
    assert wire.parse_request(b"GET OBJ") == wire.GetRequest("OBJ")
    for bad in (b"SET POS", b"HELLO", b"SET POS x", b"GET"):
        with pytest.raises(wire.HandEProtocolError):
            wire.parse_request(bad)
    assert wire.encode_value("PRE", 200) == b"PRE 200\n"


def test_calibration_maps_mm_speed_and_force_to_counts():
    cal = wire.Calibration()  # stroke 50 mm, 0 open .. 255 closed, 20..150 mm/s
    assert cal.mm_to_count(50.0) == 0 and cal.mm_to_count(0.0) == 255 and cal.mm_to_count(25.0) == 128
    assert cal.count_to_mm(0) == 50.0 and cal.count_to_mm(255) == 0.0
    assert cal.speed_to_count(20.0) == 0 and cal.speed_to_count(150.0) == 255 and cal.speed_to_count(85.0) == 128
    assert cal.force_to_count(100.0) == 255 and cal.force_to_count(0.0) == 0
    for mm in (0.0, 7.3, 36.0, 50.0):
        assert abs(cal.count_to_mm(cal.mm_to_count(mm)) - mm) <= 50.0 / 255 / 2 + 1e-12
    # a gripper whose auto-calibration found 3 (open) .. 230 (closed)
    c2 = wire.Calibration(50.0, 3, 230)
    assert c2.mm_to_count(50.0) == 3 and c2.mm_to_count(0.0) == 230
    assert c2.count_to_mm(3) == 50.0 and c2.count_to_mm(240) == 0.0  # past closed: clamped
    assert "overcurrent" in wire.describe_fault(0x0E)


@pytest.mark.parametrize("kw, key", [({"stall_timeout_s": 0.2}, "stall_timeout_s"), ({"port": 0}, "port"),
                                     ({"open_count": 200, "closed_count": 100}, "open_count"),
                                     ({"poll_rate_hz": 10.0}, "poll_rate_hz")])
def test_config_names_the_bad_key(kw, key):
    from hardware.hande import HandEConfig
    from layerskin_exp.config import ConfigError

    with pytest.raises(ConfigError, match=f"hardware.hande.{key}"):
        HandEConfig(**kw)
