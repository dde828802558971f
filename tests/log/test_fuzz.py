"""Random damage to real session files: load_session, inspect and recover either read around it
or raise SessionFileError; never another exception, never a false "complete", and what they
return is the recorded data (never bytes the damage made up)."""

from __future__ import annotations

import io
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
from log_records import records
from mcap.reader import make_reader

from layerskin_exp.log import SessionFileError, SessionWriter, load_session
from layerskin_exp.log.cli import main as cli_main
from layerskin_exp.log.container.recover import recover

N_CASES = 200


def _session(path, compression):
    with SessionWriter(path, metadata={"config": {"seed": 1}, "backend": "sim"}, labels={"trial": 3},
                       compression=compression, chunk_span_ns=25_000_000) as w:
        for r in records(240, seed=5):
            w.write(r)
    return path.read_bytes()


def _structure_bytes(raw: bytes) -> np.ndarray:
    """Offsets of every byte outside the chunks' compressed records (headers, metadata, indexes,
    summary): a uniform flip would rarely hit them, yet they steer the whole reader."""
    with io.BytesIO(raw) as fh:
        idx = make_reader(fh).get_summary().chunk_indexes
    mask = np.ones(len(raw), bool)
    for c in idx:
        mask[c.chunk_start_offset + 60 : c.chunk_start_offset + c.chunk_length] = False
    return np.flatnonzero(mask)


def _damage(raw: bytes, rng, structure: np.ndarray) -> bytes:
    out = bytearray(raw)
    kind = rng.integers(4)
    if kind == 3:  # eight consecutive bytes, as in the issue
        p = int(rng.integers(8, len(raw) - 8))
        for k in range(8):
            out[p + k] ^= int(rng.integers(1, 256))
        return bytes(out)
    for _ in range(int(rng.integers(1, 4))):
        p = int(rng.choice(structure)) if kind == 1 else int(rng.integers(0, len(raw)))
        out[p] ^= 1 << int(rng.integers(8)) if kind == 2 else int(rng.integers(1, 256))
    return bytes(out)


def _assert_recorded(s, full):
    """Everything s holds is what was recorded; if complete, it is all of it, exactly."""
    if s.complete:
        assert not s.lost and not s.damaged
        assert s.labels == full.labels and s.metadata == full.metadata
        assert s.streams.keys() == full.streams.keys()
        for name, arrays in full.streams.items():
            for key, value in arrays.items():
                if isinstance(value, np.ndarray):
                    np.testing.assert_array_equal(s.streams[name][key], value, err_msg=f"{name}.{key}")
                else:
                    assert s.streams[name][key] == value
        return
    skin = s.streams.get("skin")
    if skin is None:
        return
    ref = full.streams["skin"]
    pos = np.searchsorted(ref["seq"], skin["seq"])
    assert np.all(pos < len(ref["seq"])) and np.array_equal(ref["seq"][pos], skin["seq"])
    np.testing.assert_array_equal(skin["superficial"], ref["superficial"][pos])
    np.testing.assert_array_equal(skin["deep"], ref["deep"][pos])
    # Without the log_time offset, host times are log times: named, never read as host times.
    shift = full.epoch_offset_ns if {"log_time", "log_time.offset_ns"} & set(s.damaged_fields) else 0
    np.testing.assert_array_equal(skin["host_t_ns"], ref["host_t_ns"][pos] + shift)
    if s.outcome == "complete" and not s.warnings:
        raise AssertionError("frames missing without a word")
    missing = np.setdiff1d(ref["host_t_ns"] + shift, skin["host_t_ns"])
    if missing.size and s.outcome == "complete" and s.lost:
        # every missing frame lies in a reported lost range (or one whose bounds are unknown)
        covered = np.zeros(missing.size, bool)
        for x in s.lost:
            lo = -np.inf if x.start_ns is None else x.start_ns
            hi = np.inf if x.end_ns is None else x.end_ns
            covered |= (missing >= lo) & (missing <= hi)
        assert covered.all(), (missing[~covered][:5], s.lost)


@pytest.mark.parametrize("compression", ["lz4", "zstd", "none"])
def test_random_damage_is_read_around_or_refused(tmp_path, compression):
    src = tmp_path / "clean.mcap"
    raw = _session(src, compression)
    full = load_session(src)
    assert full.complete
    structure = _structure_bytes(raw)
    rng = np.random.default_rng({"lz4": 1, "zstd": 2, "none": 3}[compression])
    outcomes = {"complete": 0, "damaged": 0, "refused": 0}
    for case in range(N_CASES // 3 + 1):
        path = tmp_path / f"case{case}.mcap"
        path.write_bytes(_damage(raw, rng, structure))
        refused = False
        try:
            s = load_session(path, warn=False)
        except SessionFileError as exc:
            assert str(path) in str(exc)
            outcomes["refused"] += 1
            refused = True
        else:
            _assert_recorded(s, full)
            outcomes["complete" if s.complete else "damaged"] += 1
        out, err = io.StringIO(), io.StringIO()
        with redirect_stdout(out), redirect_stderr(err):
            code = cli_main(["inspect", str(path)])
        assert "Traceback" not in err.getvalue()
        # 0 only for a complete trial, 1 for a readable damaged one, 2 for a refused file
        assert code == (2 if refused else 0 if s.complete else 1), (code, refused)
        if code == 2:
            assert err.getvalue().count("\n") == 1
        dst = tmp_path / f"case{case}.recovered.mcap"
        try:
            recover(path, dst)
        except SessionFileError:
            continue
        with open(dst, "rb") as fh:  # the rewritten file is valid MCAP for the official reader
            n_official = sum(1 for _ in make_reader(fh).iter_messages())
        r = load_session(dst, warn=False)
        assert not r.complete and not r.lost
        _assert_recorded(r, full)
        assert n_official >= 2 * len(r.streams.get("skin", {}).get("seq", []))
    print(compression, outcomes)
    assert outcomes["damaged"] > 5, outcomes  # the damage is mostly read around, not refused
