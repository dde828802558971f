"""Damage harness: sessions the simulator wrote (one calibration trial, one grip trial), damaged
the ways a disk, a copy or a kill damages files (cut at every record boundary, a flipped bit in
every record kind, a chunk present twice, a zeroed range). Whatever is read back, or recovered,
holds no sample twice and no metadata value that differs from what was recorded."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from layerskin_exp.log import SessionFileError, load_session
from layerskin_exp.log.container.recover import recover
from tests.protocols.conftest import TINY_CALIBRATION, TINY_GRIP, run_cli

CHUNK = 0x06


def records(raw: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, total length) of every top-level record after the leading magic."""
    out, off = [], 8
    while off + 9 <= len(raw) - 8:
        length = 9 + int.from_bytes(raw[off + 1:off + 9], "little")
        out.append((off, raw[off], length))
        off += length
    return out


def damaged_copies(raw: bytes) -> list[tuple[str, bytes]]:
    """(damage kind, damaged bytes), deterministic."""
    recs = records(raw)
    cases = [("truncation", raw[:off]) for off, _, _ in recs[1:]]
    rng = np.random.default_rng(31)
    cases += [("truncation", raw[:int(k)]) for k in rng.integers(8, len(raw), 8)]
    by_kind: dict[int, list] = {}
    for rec in recs:
        by_kind.setdefault(rec[1], []).append(rec)
    for kind, group in sorted(by_kind.items()):
        # every metadata record (0x0C), else the first, middle and last record of the kind
        picks = group if kind == 0x0C else [group[0], group[len(group) // 2], group[-1]]
        for off, _, length in picks:
            for at in sorted({off + 1, off + 9 + (length - 9) // 2, off + length - 1}):
                flipped = bytearray(raw)
                flipped[at] ^= 1 << int(rng.integers(8))
                cases.append((f"bit flip in record 0x{kind:02x}", bytes(flipped)))
    chunks = [(off, length) for off, kind, length in recs if kind == CHUNK]
    for off, length in (chunks[0], chunks[len(chunks) // 2]):
        cases.append(("duplicated chunk", raw[:off + length] + raw[off:off + length] + raw[off + length:]))
    for start in rng.integers(8, len(raw) - 64, 6):
        cases.append(("zeroed range", raw[:int(start)] + bytes(64) + raw[int(start) + 64:]))
    return cases


@pytest.fixture(scope="session")
def sim_sessions(tmp_path_factory):
    """{protocol: bytes of one complete session} the simulator wrote."""
    root = tmp_path_factory.mktemp("harness")
    out = {}
    for app, overrides in (("force_calibration", [*TINY_CALIBRATION, "positions.count=1", "slide.repeats=0"]),
                           ("grip_depth", TINY_GRIP)):
        r = run_cli(f"protocols.{app}", [*overrides, f"data_root={root / 'data'}", "progress=false",
                                          f"hydra.run.dir={root / app}"], root)
        assert r.returncode == 0, r.stderr[-2000:]
        path = sorted((root / "data" / app).glob("*/*.mcap"))[0]
        clean = load_session(path, warn=False)
        assert clean.complete and clean.stream_health  # the harness damages the health record too
        out[app] = path.read_bytes()
    return out


def problems(s, clean) -> list[str]:
    """What s returns that it must not: a sample twice, a metadata value not as recorded."""
    found = []
    for name, arrays in s.streams.items():  # a sequence number more often than recorded
        if "seq" not in arrays:
            continue
        want = Counter(clean.streams[name]["seq"].tolist()) if name in clean.streams else Counter()
        if any(k > want[seq] for seq, k in Counter(arrays["seq"].tolist()).items()):
            found.append(f"duplicated samples in {name}")
    for k, v in s.labels.items():
        if clean.labels.get(k) != v:
            found.append(f"label {k} altered")
    for k, v in clean.metadata.items():  # a record's fields left out are named, not altered
        got = s.metadata.get(k, v)
        if isinstance(v, dict) and isinstance(got, dict):
            found += [f"metadata {k}.{f} altered" for f in got if got[f] != v.get(f)]
        elif got != v:
            found.append(f"metadata {k} altered")
    for device, counters in (s.stream_health or {}).items():  # the drivers' counts, as recorded
        if counters != (clean.stream_health or {}).get(device):
            found.append(f"stream_health {device} altered")
    if s.outcome is not None and s.outcome != clean.outcome:
        found.append("outcome altered")
    if s.epoch_offset_ns not in (0, clean.epoch_offset_ns):
        found.append("log_time offset altered")
    if s.complete and (s.streams.keys() != clean.streams.keys() or s.labels != clean.labels):
        found.append("complete but not as recorded")
    return found


# slow: hundreds of damaged copies of each session read back and recovered (~90 s and ~40 s); its
# cases come from the sessions' own records, so a smaller session would check fewer damages.
@pytest.mark.slow
@pytest.mark.parametrize("app", ["force_calibration", "grip_depth"])
def test_damaged_copies_never_return_duplicates_or_altered_metadata(sim_sessions, tmp_path, app):
    raw = sim_sessions[app]
    src = tmp_path / "clean.mcap"
    src.write_bytes(raw)
    clean = load_session(src, warn=False)
    failures = []
    for i, (kind, data) in enumerate(damaged_copies(raw)):
        path = tmp_path / f"case{i}.mcap"
        path.write_bytes(data)
        try:
            s = load_session(path, warn=False)
        except SessionFileError:
            continue
        found = problems(s, clean)
        lost_meta = set(clean.labels) - set(s.labels) or {k for k in clean.metadata if k not in s.metadata} or {
            f"stream_health.{d}" for d in clean.stream_health if d not in (s.stream_health or {})}
        if kind.startswith("bit flip") and lost_meta and not (s.damaged_fields or s.damaged):
            found.append(f"metadata {sorted(lost_meta)} gone without a word")
        dst = tmp_path / f"case{i}.recovered.mcap"
        if kind == "truncation" and i % 4:  # a cut tail is what recover is tested on most elsewhere
            failures += [f"{kind} (case {i}): {p}" for p in found]
            continue
        try:
            recover(path, dst)
        except SessionFileError:
            pass
        else:
            r = load_session(dst, warn=False)
            found += [f"recovered: {p}" for p in problems(r, clean)]
            assert not r.complete
        failures += [f"{kind} (case {i}): {p}" for p in found]
    assert not failures, failures[:20]
