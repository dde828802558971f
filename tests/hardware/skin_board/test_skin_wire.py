"""Skin board wire protocol: layout against a hand-derived byte fixture, parsing through corruption."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hardware.skin_board.wire import (
    FRAME_LEN,
    SEQ_MOD,
    SYNC,
    TIME_MOD,
    FrameParser,
    Unwrapper,
    encode_frame,
)

# One frame derived by hand from the layout in README.md: seq 0xFFFE, board time 0x89ABCDEF µs,
# superficial all 0x123 except [0, 1] = 0xFFF and [15, 0] = 0x001, deep all 0xABC except
# [2, 3] = 0x000. A pair (a, b) travels as the 24-bit LE word a | b << 12: (0x123, 0xFFF) ->
# 23 F1 FF, (0x123, 0x123) -> 23 31 12, (0x001, 0x123) -> 01 30 12, (0xABC, 0xABC) -> BC CA AB,
# (0xABC, 0x000) -> BC 0A 00 (deep[2, 3] is value 256 + 35 = 291, the second of pair 145).
FIXTURE = bytes.fromhex(
    "a55a534b" "01" "00" "feff" "efcdab89"
    + "23f1ff" + "233112" * 119 + "013012" + "233112" * 7
    + "bccaab" * 17 + "bc0a00" + "bccaab" * 110
    + "a5d802a5")


def crc32_bitwise(data: bytes) -> int:
    """CRC-32/ISO-HDLC one bit at a time (reflected 0x04C11DB7, init and xorout 0xFFFFFFFF)."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def fixture_layers():
    sup = np.full((16, 16), 0x123, np.uint16)
    sup[0, 1], sup[15, 0] = 0xFFF, 0x001
    deep = np.full((16, 16), 0xABC, np.uint16)
    deep[2, 3] = 0
    return sup, deep


def random_frames(seed: int, n: int):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        sup = rng.integers(0, 4096, (16, 16), dtype=np.uint16)
        deep = rng.integers(0, 4096, (16, 16), dtype=np.uint16)
        out.append((int(rng.integers(SEQ_MOD)), int(rng.integers(TIME_MOD)), sup, deep))
    out[0][2][0, 0], out[-1][3][15, 15] = 4095, 0  # the ends of the ADC range
    return out


def stream_of(frames) -> bytes:
    return b"".join(encode_frame(*f) for f in frames)


def key(seq, t_us, sup, deep):
    return (seq, t_us, sup.tobytes(), deep.tobytes())


def test_fixture_decodes_to_known_values():
    assert len(FIXTURE) == FRAME_LEN == 784
    assert int.from_bytes(FIXTURE[-4:], "little") == crc32_bitwise(FIXTURE[:-4])
    (f,) = FrameParser().feed(FIXTURE)
    sup, deep = fixture_layers()
    assert (f.seq, f.device_t_us, f.flags) == (0xFFFE, 0x89ABCDEF, 0)
    assert f.superficial.dtype == np.uint16 and f.superficial.shape == (16, 16)
    np.testing.assert_array_equal(f.superficial, sup)
    np.testing.assert_array_equal(f.deep, deep)


def test_encoder_writes_the_fixture():
    assert encode_frame(0xFFFE, 0x89ABCDEF, *fixture_layers()) == FIXTURE
    # seq and time are taken modulo their wire width
    assert encode_frame(0xFFFE + 3 * SEQ_MOD, 0x89ABCDEF + TIME_MOD, *fixture_layers()) == FIXTURE


def test_round_trip_in_any_chunking():
    frames = random_frames(1, 5)
    data = stream_of(frames)
    for chunk in (1, 3, 100, FRAME_LEN - 1, FRAME_LEN, 5000):
        p = FrameParser()
        got = [f for i in range(0, len(data), chunk) for f in p.feed(data[i:i + chunk])]
        assert [key(f.seq, f.device_t_us, f.superficial, f.deep) for f in got] == [key(*f) for f in frames]
        assert (p.corrupt, p.skipped_bytes, p.crc_failures, p.buffered) == (0, 0, 0, 0)


def test_encoder_rejects_bad_layers():
    sup, deep = fixture_layers()
    with pytest.raises(ValueError, match="16, 16"):
        encode_frame(0, 0, sup[:8], deep)
    sup[3, 3] = 4096
    with pytest.raises(ValueError, match="0..4095"):
        encode_frame(0, 0, sup, deep)


def test_resync_after_garbage():
    frames = random_frames(2, 4)
    enc = [encode_frame(*f) for f in frames]
    garbage = b"\x00\xa5\x5a\xa5\x5aS\xffjunk" + SYNC[:3]  # partial sync words among the junk
    data = enc[0] + garbage + enc[1] + enc[2] + garbage + enc[3]
    for chunk in (1, 7, len(data)):
        p = FrameParser()
        got = [f for i in range(0, len(data), chunk) for f in p.feed(data[i:i + chunk])]
        assert [f.seq for f in got] == [f[0] for f in frames]
        assert p.skipped_bytes == 2 * len(garbage)
        assert (p.corrupt, p.resyncs, p.crc_failures) == (2, 2, 0)


def test_joining_mid_frame_is_not_corruption():
    frames = random_frames(3, 3)
    data = stream_of(frames)[FRAME_LEN // 2:]
    p = FrameParser()
    got = p.feed(data)
    assert [f.seq for f in got] == [frames[1][0], frames[2][0]]
    assert p.skipped_bytes == FRAME_LEN - FRAME_LEN // 2 and p.corrupt == 0


@pytest.mark.parametrize("byte", [5, 100, FRAME_LEN - 2])  # flags, payload, CRC
def test_crc_rejects_a_flipped_bit(byte):
    frames = random_frames(4, 3)
    data = bytearray(stream_of(frames))
    data[FRAME_LEN + byte] ^= 0x10
    p = FrameParser()
    got = p.feed(bytes(data))
    assert [f.seq for f in got] == [frames[0][0], frames[2][0]]
    assert (p.crc_failures, p.corrupt, p.resyncs, p.skipped_bytes) == (1, 1, 1, FRAME_LEN)


def test_flipped_sync_and_other_version_are_skipped():
    frames = random_frames(5, 4)
    data = bytearray(stream_of(frames))
    data[FRAME_LEN + 1] ^= 0x01  # frame 1 loses its sync word
    data[2 * FRAME_LEN + 4] = 2  # frame 2 claims protocol version 2
    p = FrameParser()
    got = p.feed(bytes(data))
    assert [f.seq for f in got] == [frames[0][0], frames[3][0]]
    assert (p.crc_failures, p.bad_version, p.corrupt, p.skipped_bytes) == (0, 1, 2, 2 * FRAME_LEN)


def test_a_fake_sync_in_garbage_costs_one_candidate():
    frames = random_frames(6, 2)
    fake = SYNC + b"\x01" + bytes(FRAME_LEN)  # sync and version, then a full length of zeros
    data = encode_frame(*frames[0]) + fake + encode_frame(*frames[1])
    p = FrameParser()
    got = p.feed(data)
    assert [f.seq for f in got] == [frames[0][0], frames[1][0]]
    assert p.crc_failures == 1 and p.corrupt == 1 and p.skipped_bytes == len(fake)


def test_unwrapper_crosses_the_sequence_and_time_wraps():
    u = Unwrapper(frame_period_us=2360)
    t0 = TIME_MOD - 3000
    got = [u(s % SEQ_MOD, (t0 + 2360 * k) % TIME_MOD) for k, s in enumerate(range(65534, 65539))]
    assert [s for s, _ in got] == [65534, 65535, 65536, 65537, 65538]
    assert [t for _, t in got] == [t0 + 2360 * k for k in range(5)]


def test_unwrapper_counts_gaps_longer_than_the_sequence_period():
    u = Unwrapper(frame_period_us=2360)
    u(100, 1_000_000)
    gap = 3 * SEQ_MOD + 500  # 197 108 frames, ~465 s without a frame
    seq, t = u((100 + gap) % SEQ_MOD, (1_000_000 + gap * 2361) % TIME_MOD)  # board period 0.04 % long
    assert seq == 100 + gap and t == 1_000_000 + gap * 2361


def test_unwrapper_repeat_and_step_back():
    u = Unwrapper(frame_period_us=2360)
    assert u(0, 5000) == (0, 5000)
    assert u(0, 5000)[0] == 0  # the same frame again: a duplicate, not 65 536 lost
    assert u(SEQ_MOD - 1, 5000 - 2360)[0] == -1  # an older frame: a step back


# ---- fuzz --------------------------------------------------------------------------------------
_op = st.one_of(
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 7)),
    st.tuples(st.just("delete"), st.floats(0, 1), st.integers(1, FRAME_LEN + 100)),
    st.tuples(st.just("insert"), st.floats(0, 1), st.binary(min_size=1, max_size=60)),
    st.tuples(st.just("insert"), st.floats(0, 1), st.binary(max_size=FRAME_LEN + 10).map(lambda b: SYNC + b"\x01" + b)),
)


def corrupt(data: bytes, ops) -> bytes:
    buf = bytearray(data)
    for kind, where, arg in ops:
        i = int(where * len(buf))
        if kind == "flip" and buf:
            buf[min(i, len(buf) - 1)] ^= 1 << arg
        elif kind == "delete":
            del buf[i:i + arg]
        elif kind == "insert":
            buf[i:i] = arg
    return bytes(buf)


@settings(max_examples=400, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6), ops=st.lists(_op, max_size=8),
       chunks=st.lists(st.integers(1, 2 * FRAME_LEN), min_size=1, max_size=8))
def test_fuzz_corruption_never_raises_nor_invents_frames(seed, n, ops, chunks):
    frames = random_frames(seed, n)
    sent = {key(*f) for f in frames}
    data = corrupt(stream_of(frames), ops)
    p = FrameParser()
    got, i, k = [], 0, 0
    while i < len(data):
        step = chunks[k % len(chunks)]
        got += p.feed(data[i:i + step])
        i, k = i + step, k + 1
    for f in got:
        assert f.superficial.shape == f.deep.shape == (16, 16)
        assert key(f.seq, f.device_t_us, f.superficial, f.deep) in sent
    # every byte is accounted for: in an accepted frame, skipped, or waiting for more
    assert p.frames * FRAME_LEN + p.skipped_bytes + p.buffered == len(data)
    if not ops:
        assert len(got) == n and p.corrupt == 0
