"""The report's loading path never dies on one bad input: it skips the file, names it and the
reason, and carries on; a trial present twice is used once; sessions= may be one file."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from analysis.sessions import load_campaign
from layerskin_exp.log import SessionFileError, load_session

sys.path.insert(0, str(Path(__file__).parent))
from synthetic import calibration_trial  # noqa: E402


def _campaign(root: Path, n: int = 3) -> list[Path]:
    rng = np.random.default_rng(11)
    paths = []
    for i in range(n):
        p = root / f"cal{i}.mcap"
        calibration_trial(p, i, "press", 0, rng, n=120)
        paths.append(p)
    return paths


def _flip_middle(src: Path, dst: Path) -> None:
    raw = bytearray(src.read_bytes())
    for k in range(8):
        raw[len(raw) // 2 + k] ^= 0xA5
    dst.write_bytes(bytes(raw))


def test_bad_files_are_named_and_skipped_duplicates_used_once(tmp_path):
    root = tmp_path / "sessions"
    root.mkdir()
    good = _campaign(root)
    (root / "copy").mkdir()
    shutil.copy(good[0], root / "copy" / "cal0.mcap")  # the same trial in another folder
    _flip_middle(good[1], root / "damaged.mcap")
    (root / "dir.mcap").mkdir()
    header = bytearray(good[2].read_bytes())
    header[20] ^= 0x80
    (root / "header.mcap").write_bytes(bytes(header))
    (root / "text.mcap").write_text("notes")
    camp = load_campaign(root, progress=False, workers=1)
    assert sorted(t.name for t in camp.calibration) == ["cal0.mcap", "cal1.mcap", "cal2.mcap"]
    skipped = {f.name: f for f in camp.skipped_files}
    assert skipped["copy/cal0.mcap"].reason == "duplicate trial" and "cal0.mcap" in skipped["copy/cal0.mcap"].detail
    assert skipped["damaged.mcap"].reason == "damaged file" and "chunk" in skipped["damaged.mcap"].detail
    assert skipped["dir.mcap"].reason == "unreadable file" and "directory" in skipped["dir.mcap"].detail
    assert skipped["text.mcap"].reason == "unreadable file" and "not an MCAP file" in skipped["text.mcap"].detail
    assert skipped["header.mcap"].reason == "damaged file"
    assert camp.n_files == 8 and sum(camp.skipped.values()) == 5


def test_sessions_may_be_a_single_file(tmp_path):
    (p,) = _campaign(tmp_path, n=1)
    camp = load_campaign(p, progress=False, workers=1)
    assert camp.n_files == 1 and [t.name for t in camp.calibration] == ["cal0.mcap"]


def test_identity_in_metadata_decides_duplicates(tmp_path):
    """Two files with the same stored identity are one trial even if their labels differ; the
    same labels under different identities are two trials."""
    from layerskin_exp.log import SessionWriter

    root = tmp_path / "s"
    src = _campaign(tmp_path / "src", n=1)[0]
    s = load_session(src)
    for name, identity in (("a.mcap", "cfg1/pos0"), ("b.mcap", "cfg1/pos0"), ("c.mcap", "cfg2/pos0")):
        with SessionWriter(root / name, metadata={**s.metadata, "identity": identity},
                           labels={**s.labels, "note": name}) as w:
            _copy_streams(s, w)
    camp = load_campaign(root, progress=False, workers=1)
    assert sorted(t.name for t in camp.calibration) == ["a.mcap", "c.mcap"]
    assert [(f.name, f.reason) for f in camp.skipped_files] == [("b.mcap", "duplicate trial")]


def _copy_streams(s, w):
    from layerskin_exp.types import TwoLayerFrame, Wrench

    sk, wr = s.streams["skin"], s.streams["wrench"]
    for i in range(len(sk["seq"])):
        w.write(TwoLayerFrame(sk["superficial"][i], sk["deep"][i], int(sk["seq"][i]), int(sk["device_t_ns"][i]),
                              int(sk["host_t_ns"][i])))
    for i in range(len(wr["seq"])):
        w.write(Wrench(wr["force_n"][i], wr["torque_nm"][i], int(wr["seq"][i]), int(wr["device_t_ns"][i]),
                       int(wr["host_t_ns"][i])))


def test_random_damage_through_the_report_loading_path(tmp_path):
    src = _campaign(tmp_path / "clean", n=1)[0]
    raw = src.read_bytes()
    root = tmp_path / "damaged"
    root.mkdir()
    rng = np.random.default_rng(7)
    for case in range(24):
        out = bytearray(raw)
        for _ in range(int(rng.integers(1, 4))):
            out[int(rng.integers(0, len(raw)))] ^= int(rng.integers(1, 256))
        (root / f"d{case:02d}.mcap").write_bytes(bytes(out))
    camp = load_campaign(root, progress=False, workers=1)
    used = {t.name for t in camp.calibration}
    for f in camp.skipped_files:
        assert f.name not in used and f.reason in ("unreadable file", "damaged file", "duplicate trial",
                                                   "outcome not complete", "no or too short skin stream")
    for name in used:  # used only if it reads back complete, i.e. undamaged
        try:
            assert load_session(root / name, warn=False).complete
        except SessionFileError as exc:
            raise AssertionError(f"{name} used although unreadable: {exc}") from exc
    assert len(used) <= 1  # every copy is the same trial: at most one is used
    assert len(camp.skipped_files) + len(used) == 24


def test_bad_sessions_or_out_is_one_line_exit_2(tmp_path):
    for args in ([f"sessions={tmp_path / 'nope'}", f"out={tmp_path / 'o'}"],
                 [f"sessions={tmp_path}", f"out={Path(__file__)}"]):
        r = subprocess.run([sys.executable, "-m", "analysis.report", *args], capture_output=True, text=True,
                           cwd=Path(__file__).parents[2])
        assert r.returncode == 2, r.stderr[-2000:]
        assert "Traceback" not in r.stderr and r.stderr.strip().count("\n") == 0 and "error:" in r.stderr


def test_the_report_reads_by_default_where_the_protocols_write():
    import protocols.config  # noqa: F401 - the protocols' schemas, as their apps store them
    from analysis.config import ReportConfig
    from layerskin_exp.config import compose

    report = compose("report").sessions
    assert report == ReportConfig().sessions
    assert report == compose("force_calibration").data_root == compose("grip_depth").data_root


def test_an_empty_or_missing_sessions_folder_is_refused_naming_it(tmp_path):
    """A report of nothing is refused (exit 2, one line naming the folder); nothing is written."""
    empty = tmp_path / "empty"
    (empty / "grip_depth").mkdir(parents=True)
    (empty / "grip_depth" / "g9_translation_t0.mcap.partial").write_bytes(b"")  # an interrupted trial only
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])}
    for args, folder in (([f"out={tmp_path / 'o1'}"], "sessions=data"),  # the default; no data/ in cwd
                         ([f"sessions={empty}", f"out={tmp_path / 'o2'}"], f"sessions={empty}")):
        r = subprocess.run([sys.executable, "-m", "analysis.report", *args], capture_output=True, text=True,
                           cwd=tmp_path, env=env)
        assert r.returncode == 2, r.stderr[-2000:]
        assert r.stderr.strip().count("\n") == 0 and r.stderr.startswith(f"error: {folder}:"), r.stderr
        assert not list(tmp_path.rglob("report.md")) and not list(tmp_path.rglob("results.json"))


def _load_in_a_thread(root, timeout_s: float = 30.0):
    """load_campaign(root) in a thread; None if it did not return within timeout_s (a hang)."""
    import threading

    out = {}
    th = threading.Thread(target=lambda: out.setdefault("camp", load_campaign(root, progress=False, workers=1)),
                          daemon=True)
    th.start()
    th.join(timeout_s)
    return out.get("camp")


def test_a_fifo_named_like_a_session_is_skipped_by_type_without_opening_it(tmp_path):
    root = tmp_path / "sessions"
    root.mkdir()
    _campaign(root, n=1)
    fifo = root / "pipe.mcap"
    os.mkfifo(fifo)
    try:
        camp = _load_in_a_thread(root)
    finally:  # a reader blocked on the FIFO (the old behaviour) gets its end of file
        try:
            os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        except OSError:
            pass
    assert camp is not None, "load_campaign hung on a FIFO"
    assert [t.name for t in camp.calibration] == ["cal0.mcap"]
    (skip,) = camp.skipped_files
    assert (skip.name, skip.reason, skip.detail) == ("pipe.mcap", "not a regular file",
                                                     "a FIFO (named pipe); skipped without opening it")


def test_an_unreadable_subfolder_is_reported_as_skipped(tmp_path, monkeypatch):
    # Tests run as root, whom chmod does not stop: the listing of one folder fails as it would
    # without the permission.
    root = tmp_path / "sessions"
    (root / "locked").mkdir(parents=True)
    _campaign(root, n=1)
    _campaign(root / "locked", n=1)
    scandir = os.scandir

    def refusing(path="."):
        if Path(path).name == "locked":
            raise PermissionError(13, "Permission denied", str(path))
        return scandir(path)

    monkeypatch.setattr(os, "scandir", refusing)
    camp = load_campaign(root, progress=False, workers=1)
    assert [t.name for t in camp.calibration] == ["cal0.mcap"]
    assert [(f.name, f.reason, f.detail) for f in camp.skipped_files] == [
        ("locked/", "folder not read", "Permission denied; its session files are not in the report")]


def test_a_file_name_that_is_not_utf8_is_printed_escaped(tmp_path):
    from analysis.config import AnalysisConfig, ReportConfig
    from analysis.report_run import ReportRun

    root = tmp_path / "sessions"
    root.mkdir()
    (good,) = _campaign(root, n=1)
    odd = Path(os.fsdecode(bytes(root) + b"/caf\xe9.mcap"))
    odd.write_bytes(b"not a session")
    run = ReportRun(ReportConfig(sessions=str(root), out=str(tmp_path / "out"),
                                 analysis=AnalysisConfig(progress=False)))
    run.out.mkdir()
    run.load()
    run.write()
    md = (run.out / "report.md").read_text()
    assert "- `caf\\xe9.mcap`: unreadable file" in md
    assert json.loads((run.out / "results.json").read_text())["inputs"]["skipped_files"][0]["file"] == "caf\\xe9.mcap"


def _report_cli(args, cwd):
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])}
    return subprocess.run([sys.executable, "-m", "analysis.report", *args, "analysis=demo"], capture_output=True,
                          text=True, cwd=cwd, env=env, timeout=600)


def test_paths_with_spaces_work_quoted_as_hydra_documents(tmp_path):
    spaced = tmp_path / "my data"
    _campaign(spaced / "sessions", n=1)
    out = spaced / "the report"
    r = _report_cli([f'sessions="{spaced / "sessions"}"', f"out='{out}'"], tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (out / "report.md").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["my data"]  # no tree named after the quoted path
    data = json.loads((out / "results.json").read_text())
    assert data["inputs"]["sessions_dir"] == str(spaced / "sessions") and data["data"]["sessions_used"] == 1


def test_a_path_with_spaces_left_unquoted_says_how_to_quote_it(tmp_path):
    spaced = tmp_path / "my data"
    _campaign(spaced, n=1)
    # the shell split it: two arguments
    r = _report_cli([f"sessions={tmp_path}/my", "data", f"out={tmp_path}/o"], tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr == (f"configuration error: 'data' is not key=value: the shell split a value at a space; quote it "
                        f"for the shell and for Hydra: 'sessions=\"{tmp_path}/my data\"'\n")
    # one argument Hydra cannot read as it stands
    r = _report_cli([f"sessions={spaced}", f"out={tmp_path}/a b(1)"], tmp_path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.endswith(f"quote a value with spaces or brackets for Hydra: 'out=\"{tmp_path}/a b(1)\"'\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["my data"]  # nothing made


FULL_DISK = r"""
import errno, logging, sys
import analysis.report as report
from analysis.report_run import ReportRun

class Full:  # the job log's file on a full disk
    def write(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")
    def flush(self):
        pass
    def close(self):
        pass

def write(self):
    raise OSError(errno.ENOSPC, "No space left on device")

logging.FileHandler._open = lambda self: Full()
ReportRun.write = write
sys.argv = ["analysis.report", *sys.argv[1:]]
report.run_command("report", lambda: report.main, before=[report._check_command_line])
"""


def test_the_report_on_a_full_disk_stops_with_one_line(tmp_path):
    root = tmp_path / "sessions"
    _campaign(root, n=1)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])}
    r = subprocess.run([sys.executable, "-c", FULL_DISK, f"sessions={root}", f"out={out}", "analysis=demo",
                        "analysis.progress=false"],
                       capture_output=True, text=True, cwd=tmp_path, env=env, timeout=600)
    assert r.returncode == 1, r.stderr[-3000:]
    assert "Traceback" not in r.stderr and "Logging error" not in r.stderr, r.stderr[-3000:]
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert lines == [
        f"warning: the job log {out}/.hydra/report.log cannot be written (No space left on device); the run goes "
        "on without it",
        f"error: out={out}: the report could not be written (No space left on device); free space there or "
        "point out= at another disk"], r.stderr[-3000:]
