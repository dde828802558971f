"""RTDE and dashboard framing on bytes captured from the ur_rtde 1.6.5 client (a logging server
on 127.0.0.2 answered it; these are the client's own packages)."""

import struct

import pytest

from hardware.ur5e import wire

# Client -> controller, as captured.
PROTOCOL_V2 = bytes.fromhex("0005560002")
GET_VERSION = bytes.fromhex("000376")
START = bytes.fromhex("000353")
CLEAR_CMD = bytes.fromhex("0008550400000000")  # recipe 4 (input_int_register_0) = 0
IS_STEADY = bytes.fromhex("000855040000002f")  # command 47
STOP_SCRIPT = bytes.fromhex("00085504000000ff")  # command 255
# moveL([0.3, 0.1, 0.39, 0, 3.14, 0], v=0.01, a=0.1, asynchronous=True): recipe 1.
MOVEL = bytes.fromhex(
    "004c5501000000033fd33333333333333fb999999999999a3fd8f5c28f5c28f6000000000000000040091eb851eb851f"
    "00000000000000003f847ae147ae147b3fb999999999999a00000001")
STOPL = bytes.fromhex("00145513000000213fe000000000000000000000")  # stopL(0.5): recipe 19, command 33
# speedL([0, 0, 0, 0, 0, 0.026], 0.5, 0.0): recipe 13, command 10.
SPEEDL = bytes.fromhex(
    "0048550d0000000a000000000000000000000000000000000000000000000000000000000000000000000000000000003f9a9fbe"
    "76c8b4393fe00000000000000000000000000000")
SPEED_STOP = bytes.fromhex("001055080000000f4024000000000000")  # speedStop(10): recipe 8, command 15
CONTROL_OUTPUTS = (b"\x01 O@\x7f@\x00\x00\x00\x00\x00timestamp,robot_status_bits,safety_status_bits,runtime_state,"
                   b"output_int_register_0,output_int_register_1,output_int_register_2,output_double_register_0,"
                   b"output_double_register_1,output_double_register_2,output_double_register_3,"
                   b"output_double_register_4,output_double_register_5,")
NO_CMD_INPUTS = b"\x00\x18Iinput_int_register_0,"
DASHBOARD = [bytes.fromhex(h) for h in ("506f6c7973636f706556657273696f6e0a", "6765742073657269616c206e756d6265720a",
                                         "697320696e2072656d6f746520636f6e74726f6c0a")]

MOVEL_INPUTS = ["input_int_register_0"] + [f"input_double_register_{i}" for i in range(8)] + ["input_int_register_1"]


def test_framing_splits_packages_across_arbitrary_chunks():
    stream = PROTOCOL_V2 + GET_VERSION + CONTROL_OUTPUTS + NO_CMD_INPUTS + START + MOVEL + CLEAR_CMD
    for chunk in (1, 3, 7, len(stream)):
        r = wire.PacketReader()
        got = [p for i in range(0, len(stream), chunk) for p in r.feed(stream[i:i + chunk])]
        assert [chr(k) for k, _ in got] == ["V", "v", "O", "I", "S", "U", "U"]
        assert wire.pack(*got[5]) == MOVEL


def test_requests_decode_as_the_client_meant_them():
    (kind, payload), = wire.PacketReader().feed(PROTOCOL_V2)
    assert kind == wire.RTDE_REQUEST_PROTOCOL_VERSION and wire.decode_protocol_version_request(payload) == 2
    assert wire.encode_protocol_version_request(2) == PROTOCOL_V2
    (kind, payload), = wire.PacketReader().feed(CONTROL_OUTPUTS)
    freq, names = wire.decode_setup_outputs_request(payload)
    assert freq == 500.0 and names[:4] == ["timestamp", "robot_status_bits", "safety_status_bits", "runtime_state"]
    assert len(names) == 13  # the trailing comma the client sends adds no empty name
    (kind, payload), = wire.PacketReader().feed(NO_CMD_INPUTS)
    assert wire.decode_setup_inputs_request(payload) == ["input_int_register_0"]


def test_movel_data_package_carries_command_pose_speed_and_async_flag():
    recipe = wire.Recipe(1, tuple(MOVEL_INPUTS), tuple(wire.variable_type(n, "input") for n in MOVEL_INPUTS))
    (kind, payload), = wire.PacketReader().feed(MOVEL)
    v = recipe.decode(payload)
    assert kind == wire.RTDE_DATA_PACKAGE and v["input_int_register_0"] == 3 and v["input_int_register_1"] == 1
    assert [v[f"input_double_register_{i}"] for i in range(8)] == [0.3, 0.1, 0.39, 0.0, 3.14, 0.0, 0.01, 0.1]
    assert wire.encode_data(recipe, v) == MOVEL


@pytest.mark.parametrize(("package", "recipe_id", "command", "doubles"), [
    (STOPL, 19, 33, [0.5]), (SPEED_STOP, 8, 15, [10.0]), (IS_STEADY, 4, 47, []), (STOP_SCRIPT, 4, 255, []),
    (SPEEDL, 13, 10, [0, 0, 0, 0, 0, 0.026, 0.5, 0.0])])
def test_command_packages(package, recipe_id, command, doubles):
    (kind, payload), = wire.PacketReader().feed(package)
    assert payload[0] == recipe_id and struct.unpack_from(">i", payload, 1)[0] == command
    assert list(struct.unpack_from(f">{len(doubles)}d", payload, 5)) == doubles


def test_replies_and_types():
    assert wire.encode_accepted(wire.RTDE_REQUEST_PROTOCOL_VERSION, True) == b"\x00\x04V\x01"
    assert wire.decode_controller_version(wire.encode_controller_version(5, 14, 0, 1123)[3:]) == (5, 14, 0, 1123)
    reply = wire.encode_setup_reply(wire.RTDE_CONTROL_PACKAGE_SETUP_INPUTS, 4, ["INT32"])
    assert reply == b"\x00\x09I\x04INT32" and wire.decode_setup_reply(reply[3:]) == (4, ["INT32"])
    assert wire.variable_type("actual_TCP_pose", "output") == "VECTOR6D"
    assert wire.variable_type("joint_mode", "output") == "VECTOR6INT32"
    assert wire.variable_type("output_int_register_47", "output") == "INT32"
    assert wire.variable_type("output_int_register_48", "output") == "NOT_FOUND"
    assert wire.variable_type("external_force_torque", "input") == "VECTOR6D"
    assert wire.variable_type("bogus", "output") == "NOT_FOUND"


def test_output_package_round_trip_with_zero_defaults():
    names = ("timestamp", "actual_TCP_pose", "runtime_state", "safety_status_bits", "joint_mode")
    recipe = wire.Recipe(1, names, tuple(wire.variable_type(n, "output") for n in names))
    data = wire.encode_data(recipe, {"timestamp": 1.5, "actual_TCP_pose": (0.3, -0.2, 0.25, 3.14, 0, 0),
                                     "runtime_state": 2})
    assert len(data) == 3 + 1 + 8 + 48 + 4 + 4 + 24
    out = recipe.decode(wire.PacketReader().feed(data)[0][1])
    assert out["timestamp"] == 1.5 and out["runtime_state"] == 2 and out["safety_status_bits"] == 0
    assert out["actual_TCP_pose"] == (0.3, -0.2, 0.25, 3.14, 0.0, 0.0) and out["joint_mode"] == (0,) * 6
    with pytest.raises(ValueError, match="recipe 1, expected 2"):
        wire.Recipe(2, names, recipe.types).decode(wire.PacketReader().feed(data)[0][1])


def test_bad_header_is_rejected():
    with pytest.raises(ValueError, match="size 2"):
        wire.PacketReader().feed(b"\x00\x02U")


def test_dashboard_lines():
    buf = bytearray(b"".join(DASHBOARD)[:-3])
    assert wire.dashboard_lines(buf) == ["PolyscopeVersion", "get serial number"]
    buf += DASHBOARD[2][-3:]
    assert wire.dashboard_lines(buf) == ["is in remote control"] and not buf
    assert wire.encode_dashboard_line(wire.DASHBOARD_WELCOME) == b"Connected: Universal Robots Dashboard Server\n"


def test_script_reader_takes_programs_in_any_chunks_and_drops_what_is_too_long():
    from hardware.ur5e.controller import ScriptReader

    program = b"def rtde_control():\n  textmsg(\"x\")\n  if True:\n    sync()\n  end\nend"
    stream = b"textmsg(\"alone\")\n" + program + b"\n" + b"y" * 300 + b"\n" + program
    for chunk in (1, 7, 64, len(stream)):
        r = ScriptReader(limit_bytes=200)
        got = [p for i in range(0, len(stream), chunk) for p in r.feed(stream[i:i + chunk])]
        # The indented "end" closes an if, not the program; the last "end" needs no newline.
        assert got == [program.decode()] * 2
        assert r.ignored_lines == 1 and r.dropped_bytes == 300 and r.buffered_bytes == 0
    # A program that outgrows the limit is dropped whole; the next one is read.
    r = ScriptReader(limit_bytes=200)
    assert r.feed(b"def big():\n" + b"  sync()\n" * 40 + b"end\n") == []
    assert r.dropped_bytes > 200
    assert r.feed(program + b"\n") == [program.decode()]


def test_safety_status_bits_follow_the_safety_mode():
    assert wire.safety_status_bits(wire.SAFETY_MODE_NORMAL) == wire.SAFETY_BIT_NORMAL
    assert wire.safety_status_bits(wire.SAFETY_MODE_PROTECTIVE_STOP) & wire.SAFETY_BIT_PROTECTIVE_STOPPED
    for mode in (wire.SAFETY_MODE_ROBOT_EMERGENCY_STOP, wire.SAFETY_MODE_SYSTEM_EMERGENCY_STOP):
        bits = wire.safety_status_bits(mode)
        assert bits & wire.SAFETY_EMERGENCY_STOPPED and not bits & wire.SAFETY_BIT_PROTECTIVE_STOPPED
