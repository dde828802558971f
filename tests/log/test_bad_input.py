"""Bad files get one clear SessionFileError (and the CLI one line, exit code 2)."""

from __future__ import annotations

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
