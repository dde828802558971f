"""One live writer per session file: a second SessionWriter on the same path is refused at once,
naming the first; a file left by a dead writer may be replaced; nothing held is truncated."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from log_records import frame
from mcap.reader import make_reader

from layerskin_exp.log import SessionInUseError, SessionWriter, load_session


def _official_messages(path) -> int:
    """Messages the mcap library's own reader finds (it raises on a malformed file)."""
    with open(path, "rb") as fh:
        return sum(1 for _ in make_reader(fh).iter_messages())


@pytest.mark.parametrize("overwrite", [False, True])
def test_second_writer_is_refused_and_first_keeps_its_data(tmp_path, overwrite):
    path = tmp_path / "t.mcap.partial"
    first = SessionWriter(path, labels={"who": "first"}, overwrite=True)
    for i in range(100):
        first.write(frame(i))
    first.flush()
    size = path.stat().st_size
    with pytest.raises(SessionInUseError) as err:
        SessionWriter(path, labels={"who": "second"}, overwrite=overwrite)
    msg = str(err.value)
    assert str(path) in msg and f"pid {os.getpid()}" in msg and socket.gethostname() in msg
    assert "another SessionWriter" in msg
    assert path.stat().st_size == size  # not truncated
    for i in range(100, 300):
        first.write(frame(i))
    first.close()
    s = load_session(path)
    assert s.complete and s.labels == {"who": "first"}
    np.testing.assert_array_equal(s.streams["skin"]["seq"], np.arange(300))
    assert _official_messages(path) == 600
    assert not (tmp_path / "t.mcap.partial.owner").exists()


CHILD = textwrap.dedent(
    """
    import sys
    sys.path[:0] = [sys.argv[2], sys.argv[3]]
    from log_records import frame
    from layerskin_exp.log import SessionWriter
    w = SessionWriter(sys.argv[1], labels={"who": "child"}, overwrite=True)
    for i in range(200):
        w.write(frame(i))
    w.flush()
    print("ready", flush=True)
    sys.stdin.readline()  # until the parent says go on
    for i in range(200, 400):
        w.write(frame(i))
    w.close()
    """
)


def test_writer_in_another_process_is_named(tmp_path):
    path = tmp_path / "trial.mcap.partial"
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    proc = subprocess.Popen(
        # this checkout's package first, whatever is installed
        [sys.executable, str(script), str(path), str(Path(__file__).parent), str(Path(__file__).parents[2])],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )
    try:
        assert proc.stdout.readline().strip() == "ready"
        with pytest.raises(SessionInUseError, match=f"pid {proc.pid} on host"):
            SessionWriter(path, labels={"who": "parent"}, overwrite=True)
        proc.stdin.write("go\n")
        proc.stdin.flush()
        assert proc.wait(timeout=60) == 0
    finally:
        proc.kill()
    s = load_session(path)
    assert s.complete and s.labels == {"who": "child"}
    assert len(s.streams["skin"]["seq"]) == 400 and _official_messages(path) == 800


def test_stale_partial_from_a_dead_writer_is_replaced(tmp_path):
    path = tmp_path / "t.mcap.partial"
    dead = SessionWriter(path, labels={"who": "dead"})
    for i in range(50):
        dead.write(frame(i))
    dead.flush()
    dead._file.close()  # what a crash does: the descriptor (and the lock) goes, the file stays
    (tmp_path / "t.mcap.partial.owner").write_text("stale note from the crashed run")
    with SessionWriter(path, labels={"who": "rerun"}, overwrite=True) as w:
        w.write(frame(0))
    s = load_session(path)
    assert s.complete and s.labels == {"who": "rerun"} and len(s.streams["skin"]["seq"]) == 1


def test_a_rerun_removes_the_owner_note_copies_a_killed_writer_left(tmp_path):
    """A writer killed between writing its owner note's temporary copy and moving it into place
    leaves `<file>.<pid>.tmp`; the next owner of the file removes it, and nothing else."""
    path = tmp_path / "t.mcap.partial"
    stale = [tmp_path / "t.mcap.partial.4242.tmp", tmp_path / "t.mcap.partial.77.tmp"]
    kept = [tmp_path / "t.mcap.partial.notes.tmp", tmp_path / "u.mcap.partial.4242.tmp"]
    for p in stale + kept:
        p.write_text('{"pid": 4242}')
    with SessionWriter(path, labels={"who": "rerun"}, overwrite=True) as w:
        w.write(frame(0))
    assert not any(p.exists() for p in stale)
    assert all(p.exists() for p in kept)
    assert sorted(p.name for p in tmp_path.glob("t.mcap.partial*")) == ["t.mcap.partial", "t.mcap.partial.notes.tmp"]


def test_existing_file_without_overwrite_is_still_refused(tmp_path):
    path = tmp_path / "t.mcap"
    path.write_bytes(b"recorded data")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        SessionWriter(path)
    assert path.read_bytes() == b"recorded data"


def test_move_to_renames_before_releasing(tmp_path):
    tmp, final = tmp_path / "t.mcap.partial", tmp_path / "t.mcap"
    w = SessionWriter(tmp, overwrite=True)
    w.write(frame(0))
    w.close("complete", move_to=final)
    assert not tmp.exists() and w.path == final and load_session(final).complete
    # The name is free again at once: a rerun writes a new file, the finished one is untouched.
    with SessionWriter(tmp, overwrite=True) as w2:
        w2.write(frame(1))
    assert load_session(final).streams["skin"]["seq"].tolist() == [0]


def test_refused_metadata_releases_the_file(tmp_path):
    path = tmp_path / "t.mcap"
    with pytest.raises(ValueError, match="reserved"):
        SessionWriter(path, metadata={"outcome": {"x": 1}})
    with SessionWriter(path, overwrite=True) as w:  # not held by the failed writer
        w.write(frame(0))
