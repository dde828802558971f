"""Bad files get one clear SessionFileError (and the CLI one line, exit code 2)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from mcap.writer import Writer

from layerskin_exp.log import SessionFileError, load_session


def _foreign_mcap(path):
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("x", "jsonschema", b"{}")
        cid = w.register_channel("/odom", "json", sid)
        w.add_message(cid, 1, b"{}", 1)
        w.finish()


@pytest.mark.parametrize(
    "content, match",
    [
        (b"", "empty"),
        (b"hello, this is a text file\n" * 10, "not an MCAP file"),
        (b"\x89MCA", "cut off"),
        (None, "not a layerskin session"),
    ],
)
def test_bad_files_raise_session_file_error(tmp_path, content, match):
    path = tmp_path / "bad.mcap"
    if content is None:
        _foreign_mcap(path)
    else:
        path.write_bytes(content)
    with pytest.raises(SessionFileError, match=match):
        load_session(path)


def test_missing_file(tmp_path):
    with pytest.raises(SessionFileError, match="no such session file"):
        load_session(tmp_path / "nope.mcap")


def test_cli_prints_one_line_and_exits_2(tmp_path):
    path = tmp_path / "notes.txt"
    path.write_text("not a session")
    r = subprocess.run(
        [sys.executable, "-m", "layerskin_exp.log", "inspect", str(path)], capture_output=True, text=True
    )
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "not an MCAP file" in r.stderr and "Traceback" not in r.stderr


# ---------------------------------------------------------------------------- damaged sessions
# The ways issue 15 found a file could crash the reader: each now reads around the damage or
# ends in one SessionFileError naming the file.


def _session_file(tmp_path, compression="lz4"):
    from log_records import frame
    from mcap.reader import make_reader

    from layerskin_exp.log import SessionWriter

    path = tmp_path / "s.mcap"
    with SessionWriter(path, labels={"trial": 1}, compression=compression) as w:
        for i in range(300):
            w.write(frame(i))
    with open(path, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    return path, bytearray(path.read_bytes()), chunks


def test_directory_named_like_a_session(tmp_path):
    from layerskin_exp.log.container.recover import recover

    d = tmp_path / "x.mcap"
    d.mkdir()
    with pytest.raises(SessionFileError, match="is a directory"):
        load_session(d)
    with pytest.raises(SessionFileError, match=str(d)):
        recover(d, tmp_path / "out.mcap")
    r = subprocess.run([sys.executable, "-m", "layerskin_exp.log", "inspect", str(d)], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "is a directory" in r.stderr


def test_flipped_bit_in_the_mcap_header_is_damage_not_a_crash(tmp_path):
    path, raw, _ = _session_file(tmp_path)
    raw[8 + 9 + 4 + 3] ^= 0x80  # inside the header's library string: invalid UTF-8
    path.write_bytes(bytes(raw))
    s = load_session(path, warn=False)
    assert not s.complete and s.damaged and len(s.streams["skin"]["seq"]) == 300
    raw[9] ^= 0x40  # the header's record length
    path.write_bytes(bytes(raw))
    s = load_session(path, warn=False)
    assert not s.complete and len(s.streams["skin"]["seq"]) == 300


def _chunk_field(raw, chunk, field_offset):
    return chunk.chunk_start_offset + 9 + field_offset


def test_corrupted_compression_name_skips_that_chunk(tmp_path):
    path, raw, chunks = _session_file(tmp_path)
    bad = chunks[3]
    raw[_chunk_field(raw, bad, 32 + 4)] ^= 0x01  # "lz4" -> "mz4"
    path.write_bytes(bytes(raw))
    s = load_session(path, warn=False)
    assert not s.complete and s.chunks_skipped == 1
    # the lost span is on the host timeline: the chunk's log (Unix) times less the session's offset
    assert (s.lost[0].start_ns, s.lost[0].end_ns) == (bad.message_start_time - s.epoch_offset_ns,
                                                      bad.message_end_time - s.epoch_offset_ns)
    assert 0 < 300 - len(s.streams["skin"]["seq"]) < 100


def test_huge_uncompressed_size_is_not_allocated(tmp_path):
    from layerskin_exp.log.container.scan import scan

    path, raw, chunks = _session_file(tmp_path)
    for c in chunks[2:4]:
        raw[_chunk_field(raw, c, 16 + 5)] ^= 0x01  # uncompressed size += 1 TiB
    path.write_bytes(bytes(raw))
    sc = scan(path)
    assert sc.data.nbytes < 10 * len(raw)
    s = load_session(path, warn=False)
    # The summary's chunk index (CRC-checked) still has the true sizes: nothing is lost.
    assert len(s.streams["skin"]["seq"]) == 300 and s.damaged and not s.complete


def test_inspect_shows_the_damage(tmp_path):
    path, raw, chunks = _session_file(tmp_path)
    bad = chunks[len(chunks) // 2]
    raw[bad.chunk_start_offset + bad.chunk_length // 2 : bad.chunk_start_offset + bad.chunk_length // 2 + 8] = bytes(8)
    path.write_bytes(bytes(raw))
    r = subprocess.run([sys.executable, "-m", "layerskin_exp.log", "inspect", str(path)], capture_output=True, text=True)
    assert r.returncode == 1, r.stderr  # damaged: readable, not complete
    assert "complete: False" in r.stdout and "DAMAGED: 1 chunk(s) skipped" in r.stdout
    off = load_session(path, warn=False).epoch_offset_ns  # the report gives host times
    assert f"lost: {bad.message_start_time - off} .. {bad.message_end_time - off} ns" in r.stdout
    assert "outcome: complete" in r.stdout


def test_recover_rewrites_around_a_damaged_chunk(tmp_path):
    from mcap.reader import make_reader

    from layerskin_exp.log.container.recover import recover

    path, raw, chunks = _session_file(tmp_path)
    bad = chunks[len(chunks) // 2]
    raw[bad.chunk_start_offset + bad.chunk_length - 100] ^= 0xFF
    path.write_bytes(bytes(raw))
    damaged = load_session(path, warn=False)
    out = tmp_path / "fixed.mcap"
    n = recover(path, out)
    with open(out, "rb") as fh:
        assert sum(1 for _ in make_reader(fh).iter_messages()) == n
    r = load_session(out, warn=False)
    assert not r.complete and r.outcome is None and not r.damaged
    assert r.streams["skin"]["seq"].tolist() == damaged.streams["skin"]["seq"].tolist()
    assert r.metadata["recovered"]["lost"][0]["start_ns"] == bad.message_start_time


@pytest.mark.parametrize("args", [["layout", "gripper"], ["layout", "platform", "--estimate"]])
def test_output_into_a_closed_pipe_ends_quietly(args):
    """`python -m layerskin_exp.log layout | head`: the reader closes the pipe before the JSON is
    written; the command ends with exit 0 and nothing on stderr (it printed a BrokenPipeError)."""
    p = subprocess.Popen([sys.executable, "-m", "layerskin_exp.log", *args], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()  # before the interpreter has even started: its first write meets a closed pipe
    err = p.stderr.read()
    assert p.wait() == 0 and err == b"", err.decode()


def test_layout_of_a_session_file_and_of_a_file_without_one(tmp_path):
    import json

    from log_records import frame

    from layerskin_exp.log import SessionWriter

    path = tmp_path / "s.mcap"
    with SessionWriter(path, metadata={"backend": "lab"}) as w:
        w.write(frame(0))
    r = subprocess.run([sys.executable, "-m", "layerskin_exp.log", "layout", str(path)], capture_output=True, text=True)
    assert r.returncode == 0 and "configById" in json.loads(r.stdout)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])  # no layout: written at close
    r = subprocess.run([sys.executable, "-m", "layerskin_exp.log", "layout", str(cut)], capture_output=True, text=True)
    assert r.returncode == 2 and "no stored layout" in r.stderr and r.stderr.count("\n") == 1


# ---------------------------------------------------------------------------- special paths
def test_inspect_and_recover_refuse_a_fifo_without_opening_it(tmp_path):
    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    try:
        for args in (["inspect", str(fifo)], ["recover", str(fifo), str(tmp_path / "out.mcap")]):
            r = subprocess.run([sys.executable, "-m", "layerskin_exp.log", *args], capture_output=True, text=True,
                               timeout=60)
            assert r.returncode == 2 and "Traceback" not in r.stderr
            assert r.stderr == f"error: {fifo}: a FIFO (named pipe), not a session file; skipped without opening it\n"
    finally:  # a reader blocked on the FIFO gets its end of file
        try:
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass
    assert not (tmp_path / "out.mcap").exists()


def test_recover_from_a_symlink_loop_names_the_loop(tmp_path, capsys):
    from layerskin_exp.log.cli import main

    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    a.symlink_to(b)
    b.symlink_to(a)
    assert main(["recover", str(a), str(tmp_path / "out.mcap")]) == 2
    assert capsys.readouterr().err == (f"error: {a}: a symbolic link loop (the link leads back to itself); "
                                       "point at the file itself\n")
    assert main(["inspect", str(a)]) == 2
    assert "a symbolic link loop" in capsys.readouterr().err


def test_recover_into_a_full_disk_leaves_no_output(tmp_path, monkeypatch, capsys):
    import errno

    from layerskin_exp.log.cli import main
    from layerskin_exp.log.container import recover as recover_module

    src, _, _ = _session_file(tmp_path)
    real_open = open

    class Full:
        def __init__(self, fh):
            self.fh = fh

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def __getattr__(self, name):
            return getattr(self.fh, name)

    monkeypatch.setattr(recover_module, "open", lambda path, mode: Full(real_open(path, mode)), raising=False)
    out = tmp_path / "out.mcap"
    assert main(["recover", str(src), str(out)]) == 2
    assert capsys.readouterr().err == f"error: {out}: cannot be written (No space left on device); nothing was left there\n"
    assert not out.exists()
