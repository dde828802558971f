"""The drivers' stream-health counters in the session file: stored at close as a checked metadata
record, read back as Session.stream_health, shown by `inspect`; a file written before the record
existed reads None ("not recorded"), and a damaged count is named, never read as valid."""

from __future__ import annotations

from log_records import frame

from layerskin_exp.log import SessionWriter, load_session
from layerskin_exp.log.cli import main as cli_main
from layerskin_exp.log.container.recover import recover

HEALTH = {"skin": {"received": 1523, "lost": 274, "duplicate": 2, "out_of_order": 1, "corrupt": 3, "reconnects": 0,
                   "dropped": 5},
          "ft": {"received": 4000, "lost": 0, "duplicate": 0, "out_of_order": 0, "corrupt": 0, "reconnects": 1}}


def _write(path, health):
    w = SessionWriter(path, metadata={"backend": "sim"}, labels={"trial": 1})
    for i in range(20):
        w.write(frame(i))
    w.close("complete", stream_health=health)


def test_counters_are_stored_read_back_and_inspected(tmp_path, capsys):
    path = tmp_path / "s.mcap"
    _write(path, HEALTH)
    s = load_session(path, warn=False)
    assert s.stream_health == HEALTH and s.complete and not s.damaged_fields
    assert "stream_health" not in s.metadata  # its own attribute, not a metadata record
    assert cli_main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if line.startswith(("    skin ", "    ft "))}
    # received, lost, dropped, duplicate, out of order, corrupt, reconnects
    assert rows["skin"] == ["1523", "274", "5", "2", "1", "3", "0"]
    assert rows["ft"] == ["4000", "0", "-", "0", "0", "0", "1"]


def test_a_file_without_the_record_reads_none_and_inspect_says_not_recorded(tmp_path, capsys):
    path = tmp_path / "old.mcap"
    _write(path, None)  # as every writer did before the counters were stored
    s = load_session(path, warn=False)
    assert s.stream_health is None and s.complete and not s.damaged
    cli_main(["inspect", str(path)])
    assert "stream health: not recorded" in capsys.readouterr().out


def test_a_damaged_count_is_named_left_out_and_not_recovered(tmp_path, capsys):
    path = tmp_path / "s.mcap"
    _write(path, HEALTH)
    raw = path.read_bytes()
    at = raw.index(b'"lost":274', raw.index(b"stream_health")) + len(b'"lost":')
    path.write_bytes(raw[:at] + b"3" + raw[at + 1:])  # 274 -> 374: still a count, only the check can tell
    s = load_session(path, warn=False)
    assert s.damaged_fields == ["stream_health.skin"] and s.damaged and not s.complete
    assert s.stream_health == {"ft": HEALTH["ft"]}
    assert cli_main(["inspect", str(path)]) == 1
    assert "DAMAGED METADATA (left out): stream_health.skin" in capsys.readouterr().out
    dst = tmp_path / "recovered.mcap"
    recover(path, dst)
    r = load_session(dst, warn=False)
    assert r.stream_health == {"ft": HEALTH["ft"]}  # the damaged count is not written as if valid
    assert r.metadata["recovered"]["damaged_metadata"] == ["stream_health.skin"]
