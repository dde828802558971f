"""Crash safety: a writer killed with SIGKILL loses at most ~100 ms of data (by log time);
the partial file reads up to the damage with a warning and can be recovered."""

from __future__ import annotations

import mmap
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from log_records import HOST0_NS, flip_value, frame, records

from layerskin_exp.log import SessionWarning, SessionWriter, load_session
from layerskin_exp.log.cli import main as cli_main
from layerskin_exp.log.container.recover import recover

CHUNK_SPAN_NS = 100_000_000

CHILD = textwrap.dedent(
    """
    import mmap, struct, sys
    sys.path.insert(0, sys.argv[3])
    from log_records import frame
    from layerskin_exp.log import SessionWriter
    from layerskin_exp.types import ProtocolEvent
    progress = open(sys.argv[2], "r+b")
    mm = mmap.mmap(progress.fileno(), 8)
    w = SessionWriter(sys.argv[1], metadata={"backend": "sim"}, labels={"trial": 7})
    w.write(ProtocolEvent("phase", "start", frame(0).host_t_ns))
    i = 0
    while True:  # until killed
        w.write(frame(i))
        mm[:8] = struct.pack("<q", i)  # last frame whose write() returned
        i += 1
    """
)


def _kill_mid_write(tmp_path: Path, min_frames: int) -> tuple[Path, int]:
    path = tmp_path / "killed.mcap"
    progress = tmp_path / "progress"
    progress.write_bytes(struct.pack("<q", -1))
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    here = str(Path(__file__).parent)
    proc = subprocess.Popen([sys.executable, str(script), str(path), str(progress), here])
    with open(progress, "r+b") as fh:
        mm = mmap.mmap(fh.fileno(), 8)
        deadline = time.monotonic() + 60
        while struct.unpack("<q", mm[:8])[0] < min_frames:
            assert proc.poll() is None, "writer subprocess died on its own"
            assert time.monotonic() < deadline, "writer subprocess too slow"
            time.sleep(0.01)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        last = struct.unpack("<q", mm[:8])[0]
    assert proc.returncode == -signal.SIGKILL
    return path, last


def test_sigkill_loses_at_most_100ms_and_recovers(tmp_path):
    path, last = _kill_mid_write(tmp_path, min_frames=3000)
    with pytest.warns(SessionWarning, match="did not close"):
        s = load_session(path)
    assert s.outcome is None and not s.complete
    assert s.labels == {"trial": 7} and s.metadata["backend"] == "sim"
    skin = s.streams["skin"]
    n = len(skin["seq"])
    # What was read is exactly the first n frames, bit for bit.
    np.testing.assert_array_equal(skin["seq"], np.arange(n))
    np.testing.assert_array_equal(skin["superficial"][-1], frame(n - 1).superficial)
    np.testing.assert_array_equal(skin["deep"][n // 2], frame(n // 2).deep)
    # Loss bound by data time: frames after the last one read span under one chunk (100 ms).
    # The kill can land between a write() returning and the progress update: the last frame
    # written is `last` or `last + 1`. Frames n.. were in the open chunk, which spans < 100 ms.
    assert n - 1 <= last + 1
    if last >= n:
        assert frame(last).host_t_ns - frame(n).host_t_ns < CHUNK_SPAN_NS, (n, last)
    assert s.streams["events"]["message"] == ["start"]
    assert "skin" in s.clock_sync  # estimated on reading, since close() never ran

    out = tmp_path / "recovered.mcap"
    copied = recover(path, out)
    r = load_session(out, warn=False)
    assert copied == 2 * n + 2  # both layers of n frames, the event and its foxglove.Log view
    assert r.outcome is None and not r.complete
    assert r.metadata["recovered"]["messages"] == copied
    np.testing.assert_array_equal(r.streams["skin"]["superficial"], skin["superficial"])
    np.testing.assert_array_equal(r.streams["skin"]["host_t_ns"], skin["host_t_ns"])
    assert not any("footer" in w for w in r.warnings)  # the rewritten file is a valid MCAP


def test_truncated_files_read_up_to_the_damage(tmp_path):
    recs = records(700)
    path = tmp_path / "full.mcap"
    with SessionWriter(path, labels={"k": 1}, chunk_span_ns=20_000_000) as w:
        for r in recs:
            w.write(r)
    full = load_session(path)
    data = path.read_bytes()
    n_full = len(full.streams["skin"]["seq"])
    seen = []
    for frac in np.linspace(0.02, 0.999, 40):
        cut = tmp_path / f"cut{frac:.3f}.mcap"
        cut.write_bytes(data[: int(len(data) * frac)])
        with pytest.warns(SessionWarning):
            s = load_session(cut)
        assert not s.complete and s.warnings  # a cut inside the summary keeps the outcome
        if "skin" in s.streams:
            k = len(s.streams["skin"]["seq"])
            seen.append(k)
            for name, a in s.streams.items():  # every stream is a prefix of the full one
                m = len(a["host_t_ns"])
                np.testing.assert_array_equal(a["host_t_ns"], full.streams[name]["host_t_ns"][:m])
            np.testing.assert_array_equal(s.streams["skin"]["deep"], full.streams["skin"]["deep"][:k])
    assert seen == sorted(seen) and 0 < seen[-1] <= n_full and len(set(seen)) > 10
    # Garbage appended after a cut (e.g. a zero-filled block) is damage, not an error.
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(data[: len(data) // 2] + bytes(4096))
    with pytest.warns(SessionWarning):
        load_session(junk)


def test_recover_cli(tmp_path, capsys):
    path = tmp_path / "s.mcap"
    with SessionWriter(path) as w:
        for i in range(300):
            w.write(frame(i))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:-2000])
    assert cli_main(["recover", str(cut), str(tmp_path / "out.mcap")]) == 0
    assert "recovered" in capsys.readouterr().out
    assert cli_main(["inspect", str(tmp_path / "out.mcap")]) == 1  # readable, but not a complete trial
    out = capsys.readouterr().out
    assert "skin" in out and "complete: False" in out
    assert cli_main(["inspect", str(cut)]) == 1  # the cut-off file itself
    assert cli_main(["inspect", str(path)]) == 0
    assert "complete: True" in capsys.readouterr().out
    assert HOST0_NS > 0


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("with_summary", [True, False])
def test_damaged_chunk_is_skipped_and_reported(tmp_path, monkeypatch, compression, threads, with_summary):
    """A corrupted byte inside a middle chunk of a closed file: only that chunk's frames are
    missing, every other frame comes back exactly, the lost range is that chunk's time span
    (from the summary's chunk index, or from the neighbouring chunks when the summary is gone),
    and the session is not complete although the file's outcome says so."""
    from mcap.reader import make_reader

    from layerskin_exp.log.container import scan as scan_module

    monkeypatch.setattr(scan_module, "_THREADS", threads)
    monkeypatch.setattr(scan_module, "_BYTES_PER_THREAD", 1)
    path = tmp_path / "damaged.mcap"
    frames = [frame(i) for i in range(300)]
    with SessionWriter(path, compression=compression) as w:
        for f in frames:
            w.write(f)
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    chunk_indexes = summary.chunk_indexes
    off = w.epoch_offset_ns  # chunk times are log (Unix) times: host time + the session's offset
    skin_chunks = [c for c in chunk_indexes if c.message_start_time - off >= frames[0].host_t_ns]
    assert len(skin_chunks) >= 6
    bad = skin_chunks[len(skin_chunks) // 2]
    bad_start_ns, bad_end_ns = bad.message_start_time - off, bad.message_end_time - off
    raw = bytearray(path.read_bytes())
    raw[bad.chunk_start_offset + bad.chunk_length - 200] ^= 0x5A  # inside the chunk's records
    if not with_summary:  # a damaged summary: the reader must find its way without the index
        raw[len(raw) - 8 - 29 - 40] ^= 0xFF
    path.write_bytes(bytes(raw))

    with pytest.warns(SessionWarning, match="chunk"):
        s = load_session(path)
    gone = [f for f in frames if bad_start_ns <= f.host_t_ns <= bad_end_ns]
    kept = [f for f in frames if not bad_start_ns <= f.host_t_ns <= bad_end_ns]
    assert 0 < len(gone) < 100 and kept[-1] is frames[-1]
    skin = s.streams["skin"]
    np.testing.assert_array_equal(skin["seq"], [f.seq for f in kept])
    np.testing.assert_array_equal(skin["superficial"], np.stack([f.superficial for f in kept]))
    np.testing.assert_array_equal(skin["deep"], np.stack([f.deep for f in kept]))
    assert s.outcome == "complete" and not s.complete and s.damaged and s.chunks_skipped == 1
    assert len(s.lost) == 1
    lost = s.lost[0]
    assert str(bad.chunk_start_offset) in lost.reason
    if with_summary:
        assert (lost.start_ns, lost.end_ns) == (bad_start_ns, bad_end_ns)
        assert lost.messages == {"skin": 2 * len(gone)}
    else:  # bounded by the good chunks either side, and containing the lost frames
        assert lost.start_ns <= gone[0].host_t_ns and gone[-1].host_t_ns <= lost.end_ns
        assert lost.start_ns >= kept[len([f for f in kept if f.host_t_ns < gone[0].host_t_ns]) - 1].host_t_ns


def test_multithreaded_decompression_matches_single(tmp_path, monkeypatch):
    from layerskin_exp.log.container import scan as scan_module

    path = tmp_path / "s.mcap"
    with SessionWriter(path) as w:
        for r in records(400):
            w.write(r)
    one = load_session(path)
    monkeypatch.setattr(scan_module, "_THREADS", 3)
    monkeypatch.setattr(scan_module, "_BYTES_PER_THREAD", 1)
    many = load_session(path)
    assert one.streams.keys() == many.streams.keys()
    for name, arrays in one.streams.items():
        for key, value in arrays.items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(value, many.streams[name][key], err_msg=f"{name}.{key}")
            else:
                assert value == many.streams[name][key]


def test_a_chunk_present_twice_is_read_once_and_reported(tmp_path):
    """A chunk written twice (a copy or write retried): each message is returned once, the
    repeats are counted per stream, and `recover` drops them and says so in the file it writes."""
    from mcap.reader import make_reader

    path = tmp_path / "twice.mcap"
    frames = [frame(i) for i in range(300)]
    with SessionWriter(path) as w:
        for f in frames:
            w.write(f)
    with open(path, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    c = chunks[len(chunks) // 2]
    raw = path.read_bytes()
    end = c.chunk_start_offset + c.chunk_length + c.message_index_length
    path.write_bytes(raw[:end] + raw[c.chunk_start_offset:end] + raw[end:])
    s = load_session(path, warn=False)
    skin = s.streams["skin"]
    np.testing.assert_array_equal(skin["seq"], [f.seq for f in frames])
    np.testing.assert_array_equal(skin["superficial"], np.stack([f.superficial for f in frames]))
    in_chunk = sum(c.message_start_time <= f.host_t_ns + w.epoch_offset_ns <= c.message_end_time for f in frames)
    assert s.repeats == {"skin": 2 * in_chunk} and in_chunk > 0  # both layers' messages
    assert not s.complete and any("repeated message(s) dropped" in m for m in s.warnings)
    dst = tmp_path / "recovered.mcap"
    recover(path, dst)
    r = load_session(dst, warn=False)
    np.testing.assert_array_equal(r.streams["skin"]["seq"], [f.seq for f in frames])
    assert r.metadata["recovered"]["repeats"] == {"skin": 2 * in_chunk}
    assert any(f"repeated messages dropped then: {{'skin': {2 * in_chunk}}}" in m for m in r.warnings)


def test_one_host_record_written_twice_at_one_time_is_two_messages_not_a_repeat(tmp_path):
    """Stage samples parsed from one serial read share a host time; at rest their derived frame
    transforms are identical. Host-side records (transforms, events, views) number their own
    messages, so the reader keeps both and the file stays complete (it read as damaged before)."""
    from layerskin_exp.types import FrameTransform, ProtocolEvent

    path = tmp_path / "same.mcap"
    tf = FrameTransform("base", "skin", np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), HOST0_NS)
    ev = ProtocolEvent("phase", "hold", HOST0_NS, HOST0_NS, {})
    with SessionWriter(path) as w:
        w.write(frame(0))
        for record in (tf, tf, ev, ev):
            w.write(record)
    s = load_session(path, warn=False)
    assert s.complete and not s.damaged and not s.repeats
    assert len(s.streams["transforms"]["host_t_ns"]) == 2 and s.streams["events"]["message"] == ["hold", "hold"]


@pytest.mark.parametrize(("record", "key", "field"), [(b"log_time", b"offset_ns", "log_time.offset_ns"),
                                                       (b"labels", b"trial", "labels.trial")])
def test_a_damaged_metadata_field_is_named_left_out_and_not_recovered(tmp_path, record, key, field):
    path = tmp_path / "meta.mcap"
    with SessionWriter(path, metadata={"backend": "sim", "config": {"seed": 1}}, labels={"trial": 3}) as w:
        for i in range(40):
            w.write(frame(i))
    clean = load_session(path, warn=False)
    assert clean.complete and not clean.damaged_fields and not clean.unchecked
    path.write_bytes(flip_value(path.read_bytes(), record, key))
    s = load_session(path, warn=False)
    assert s.damaged_fields == [field] and s.damaged and not s.complete
    assert any(field in m for m in s.warnings)
    assert "trial" not in s.labels if field == "labels.trial" else s.labels == {"trial": 3}
    dst = tmp_path / "recovered.mcap"
    recover(path, dst)
    r = load_session(dst, warn=False)
    assert r.metadata["recovered"]["damaged_metadata"] == [field]
    assert any(f"metadata left out then: ['{field}']" in m for m in r.warnings)
    assert r.labels.get("trial") in (None, 3)  # never the damaged value


def test_a_file_written_before_metadata_checks_reads_unchecked_not_damaged(tmp_path, monkeypatch):
    from layerskin_exp.log.session import writer as writer_module

    monkeypatch.setattr(writer_module, "with_check", lambda name, values: values)
    path = tmp_path / "old.mcap"
    with SessionWriter(path, labels={"trial": 3}) as w:
        w.write(frame(0))
    s = load_session(path, warn=False)
    assert s.complete and not s.damaged and not s.damaged_fields and s.labels == {"trial": 3}
    assert {"session", "log_time", "labels", "clock_sync", "outcome"} <= set(s.unchecked)
