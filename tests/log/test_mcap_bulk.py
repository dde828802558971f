"""The writer adds each chunk's messages to the mcap library's open chunk in bulk (private
Writer internals, see writer._OpenChunk). These tests catch a library change: the fast path must
attach to the installed mcap, and its files must be byte-identical to the library's own
Writer.add_message path."""

from __future__ import annotations

import mcap
import pytest
from log_records import records

from layerskin_exp.log import SessionWriter
from layerskin_exp.log.session import writer as W

META = {"config": {"a": 1}, "backend": "sim", "calibration": {"gain": [1.0]}}


def _write(path, recs, **kw):
    # one fixed date: a simulated session written without the rig is dated when it is opened
    with SessionWriter(path, metadata=META, labels={"trial": 1}, epoch_offset_ns=1_767_603_600 * 10**9, **kw) as w:
        for r in recs:
            w.write(r)
    return w


def test_bulk_path_attaches_to_the_installed_mcap(tmp_path):
    with SessionWriter(tmp_path / "a.mcap") as w:
        assert w._bulk is not None, (
            f"mcap {getattr(mcap, '__version__', '?')}: Writer internals changed; the session writer "
            f"fell back to Writer.add_message (correct but slow): update writer._OpenChunk"
        )


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_bulk_file_is_byte_identical_to_add_message_file(tmp_path, monkeypatch, compression):
    recs = records(500, seed=3)
    _write(tmp_path / "bulk.mcap", recs, compression=compression)
    monkeypatch.setattr(W._OpenChunk, "attach", classmethod(lambda cls, writer: None))
    w = _write(tmp_path / "lib.mcap", recs, compression=compression)
    assert w._bulk is None
    bulk, lib = (tmp_path / "bulk.mcap").read_bytes(), (tmp_path / "lib.mcap").read_bytes()
    assert len(bulk) > 100_000  # a real session, not two empty files
    assert bulk == lib
