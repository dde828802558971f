"""`export lerobot`: a folder of sessions -> one LeRobot v3.0 dataset, checked with pyarrow alone.

The sessions are written here with SessionWriter (log_records: skin every 2.36 ms, wrench, stage,
TCP, gripper, two markers, small camera images), a few hundred frames each: the export of the
folder takes about a second. The checker (check_lerobot) is the one the injected-error tests break.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")  # the 'lerobot' extra (dev installs it)
import pyarrow.parquet as pq  # noqa: E402
from log_records import PERIOD_NS, frame, records  # noqa: E402

from layerskin_exp.log import SessionWriter  # noqa: E402
from layerskin_exp.log.export import ExportError, check_lerobot, export_lerobot  # noqa: E402
from layerskin_exp.log.export import lerobot as L  # noqa: E402
from layerskin_exp.log.export import lerobot_stats as ST  # noqa: E402

N_FRAMES = 400  # 0.94 s of skin: 80 frames at the default 85 fps
CAL_LABELS = {"protocol": "force_calibration", "position_index": 0, "position_mm": [1.5, -2.0], "kind": "press",
              "repeat": 0, "direction_rad": None, "z_offset_mm": None}


def _write(path, labels, n=N_FRAMES, outcome="complete", seed=0, images=True):
    with SessionWriter(path, metadata={"protocol": labels["protocol"]}, labels=labels) as w:
        for r in records(n, seed):
            w.write(r)
        if images:
            for i in range(0, n, 14):  # ~30 Hz, each image a function of i
                f = frame(i)
                img = np.full((24, 32), (i * 3) % 256, np.uint8)
                img[:, : 1 + i % 32] = 255
                w.write_image(img, f.device_t_ns, f.host_t_ns + 2000, seq=i // 14)
        w.close(outcome)
    return path


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """design/: two complete trials, one incomplete, one cut off, one damaged chunk, one
    interrupted (.partial), one that is no session at all."""
    root = tmp_path_factory.mktemp("sessions")
    d = root / "design"
    _write(d / "pos000_press0.mcap", CAL_LABELS)
    _write(d / "pos000_slide0.mcap", {**CAL_LABELS, "kind": "slide", "direction_rad": 1.25, "z_offset_mm": -0.3},
           seed=1)
    _write(d / "pos001_press0.mcap", {**CAL_LABELS, "position_index": 1}, outcome="incomplete: lost 3 skin frames")
    cut = _write(d / "pos001_slide0.mcap", {**CAL_LABELS, "position_index": 1, "kind": "slide"})
    cut.write_bytes(cut.read_bytes()[: len(cut.read_bytes()) * 2 // 3])
    bad = _write(d / "pos002_press0.mcap", {**CAL_LABELS, "position_index": 2}, n=1200)
    from mcap.reader import make_reader

    with open(bad, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    raw = bytearray(bad.read_bytes())
    c = chunks[len(chunks) // 2]
    raw[c.chunk_start_offset + c.chunk_length // 2: c.chunk_start_offset + c.chunk_length // 2 + 8] = bytes(8)
    bad.write_bytes(bytes(raw))
    shutil.copy(d / "pos000_press0.mcap", d / "pos003_press0.mcap.partial")
    (d / "notes.mcap").write_text("not a session")
    return root


@pytest.fixture(scope="module")
def dataset(campaign, tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "calib"
    report = export_lerobot(campaign, out)
    return out, report


def _fresh_copy(dataset, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(dataset[0], out)
    return out


def _rewrite_data(root, column, fn):
    """Rewrite one column of the data file (same schema metadata): the injected error."""
    path = root / "data" / "chunk-000" / "file-000.parquet"
    t = pq.read_table(path)
    i = t.column_names.index(column)
    new = fn(t.column(column).combine_chunks())
    t = t.set_column(i, pa.field(column, new.type), new).replace_schema_metadata(t.schema.metadata)
    pq.write_table(t, path)


def _edit_json(root, name, fn):
    path = root / "meta" / name
    d = json.loads(path.read_text())
    fn(d)
    path.write_text(json.dumps(d))


# ---------------------------------------------------------------------------------------------- the dataset


def test_the_complete_trials_become_a_dataset_the_checker_accepts(dataset):
    out, report = dataset
    assert check_lerobot(out) == []
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == round(1e9 / PERIOD_NS / 5) == 85
    assert report.episodes == ["design/pos000_press0.mcap", "design/pos000_slide0.mcap"]
    assert info["total_episodes"] == 2 and info["total_tasks"] == 1 and info["splits"] == {"train": "0:2"}
    assert info["robot_type"] == "three_axis_platform"
    f = info["features"]
    assert {k: (f[k]["dtype"], f[k]["shape"]) for k in f} == {
        "observation.tactile.superficial": ("float32", [16, 16]), "observation.tactile.deep": ("float32", [16, 16]),
        "observation.wrench": ("float32", [6]), "observation.stage.position": ("float32", [3]),
        "observation.tcp.pose": ("float32", [7]), "observation.gripper": ("float32", [6]),
        "observation.markers.0.pose": ("float32", [7]), "observation.markers.0.age_s": ("float32", [1]),
        "observation.markers.1.pose": ("float32", [7]), "observation.markers.1.age_s": ("float32", [1]),
        "observation.images.camera": ("video", [24, 32, 3]),
        "timestamp": ("float32", [1]), "frame_index": ("int64", [1]), "episode_index": ("int64", [1]),
        "index": ("int64", [1]), "task_index": ("int64", [1])}
    assert f["observation.images.camera"]["info"]["video.codec"] == "mpeg4"
    rs = info["resampling"]
    assert rs["fps"] == 85 and abs(rs["skin_rate_hz"] - 1e9 / PERIOD_NS) < 0.5
    assert set(rs["methods"]) == {k for k in f if k not in L.DEFAULT_FEATURES}
    # ~0.94 s of overlap per trial: 79 or 80 whole frames at 85 fps
    data = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet")
    assert data.num_rows == info["total_frames"] == report.frames and 150 <= data.num_rows <= 162
    assert pq.ParquetFile(out / "data" / "chunk-000" / "file-000.parquet").num_row_groups == 2  # one per episode
    hf = json.loads(data.schema.metadata[b"huggingface"])["info"]["features"]
    assert hf["observation.tactile.deep"] == {"shape": [16, 16], "dtype": "float32", "_type": "Array2D"}
    assert hf["observation.wrench"] == {"feature": {"dtype": "float32", "_type": "Value"}, "length": 6,
                                        "_type": "List"}
    # the 16 x 16 columns are datasets' Array2D extension (its reader gets Array2D back without features)
    assert data.schema.field("observation.tactile.deep").metadata == {
        b"ARROW:extension:name": b"datasets.features.features.Array2DExtensionType",
        b"ARROW:extension:metadata": b'[[16, 16], "float32"]'}


def test_episodes_carry_the_task_the_labels_and_the_source(dataset):
    out, _ = dataset
    eps = pq.read_table(out / "meta" / "episodes" / "chunk-000" / "file-000.parquet").to_pylist()
    assert [e["labels/kind"] for e in eps] == ["press", "slide"]
    assert [e["labels/direction_rad"] for e in eps] == [None, 1.25]
    assert eps[0]["labels/position_mm"] == [1.5, -2.0]
    assert eps[1]["source"] == "design/pos000_slide0.mcap"
    assert eps[0]["tasks"] == [L.TASKS["force_calibration"]]
    tasks = pq.read_table(out / "meta" / "tasks.parquet")
    assert tasks.to_pylist() == [{"task_index": 0, "task": L.TASKS["force_calibration"]}]


def test_damaged_and_incomplete_trials_are_left_out_and_listed(dataset):
    out, report = dataset
    why = {x.path: x.reason for x in report.left_out}
    assert set(why) == {"design/pos001_press0.mcap", "design/pos001_slide0.mcap", "design/pos002_press0.mcap",
                        "design/pos003_press0.mcap.partial", "design/notes.mcap"}
    assert "incomplete: lost 3 skin frames" in why["design/pos001_press0.mcap"]
    assert "not closed by its writer" in why["design/pos001_slide0.mcap"]
    assert why["design/pos002_press0.mcap"].startswith("damaged")
    assert "interrupted" in why["design/pos003_press0.mcap.partial"]
    assert "unreadable" in why["design/notes.mcap"]
    record = json.loads((out / "meta" / "layerskin_export.json").read_text())
    assert {x["path"] for x in record["left_out"]} == set(why)
    assert [e["source"] for e in record["episodes"]] == report.episodes
    assert record["lerobot_reference"]["commit"] == L.LEROBOT_COMMIT
    assert "left out 5 session(s)" in report.describe()


def test_frames_are_the_block_means_of_the_skin_and_the_latest_of_the_rest(dataset, campaign):
    """Episode 0's frame 3 recomputed from the session: the mean of the skin frames in its period,
    the latest TCP sample at or before the period's end."""
    from layerskin_exp.log import load_session

    out, _ = dataset
    s = load_session(campaign / "design" / "pos000_press0.mcap", warn=False)
    t0 = max(int(s.streams[k]["t_ns"][0]) for k in ("skin", "wrench", "stage", "tcp", "gripper", "markers", "camera"))
    lo, hi = t0 + round(3e9 / 85), t0 + round(4e9 / 85)
    t = s.streams["skin"]["t_ns"]
    want = s.streams["skin"]["deep"][(t >= lo) & (t < hi)].astype(np.float64).mean(axis=0)
    row = pq.read_table(out / "data" / "chunk-000" / "file-000.parquet").slice(3, 1).to_pylist()[0]
    assert row["frame_index"] == 3 and row["timestamp"] == np.float32(3 / 85)
    np.testing.assert_allclose(np.array(row["observation.tactile.deep"]), want, rtol=1e-6)
    tcp = s.streams["tcp"]
    j = np.searchsorted(tcp["t_ns"], hi, side="right") - 1
    np.testing.assert_allclose(row["observation.tcp.pose"], np.r_[tcp["position_m"][j], tcp["orientation_xyzw"][j]],
                               rtol=1e-6)


def test_a_chosen_rate(campaign, tmp_path):
    report = export_lerobot(campaign / "design" / "pos000_slide0.mcap", tmp_path / "ds", fps=30)
    assert report.fps == 30 and len(report.episodes) == 1 and check_lerobot(tmp_path / "ds") == []
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    assert info["fps"] == 30 and abs(info["resampling"]["skin_samples_per_frame"] - 1e9 / PERIOD_NS / 30) < 0.01


def test_stats_are_computed_as_lerobot_computes_them():
    """compute_stats' conventions: (N, 16, 16) -> statistics per last axis (16,), count = frames;
    (N,) -> (1,); images (C, 1, 1) in [0, 1]; aggregation weighted by count."""
    rng = np.random.default_rng(0)
    x = rng.normal(size=(50, 16, 16)).astype(np.float32)
    st = ST.vector_stats(x)
    assert st["mean"].shape == (16,) and st["count"].tolist() == [50]
    np.testing.assert_allclose(st["mean"], x.reshape(-1, 16).mean(axis=0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(st["q50"], np.median(x.reshape(-1, 16), axis=0), atol=0.02)
    assert ST.vector_stats(np.arange(10.0))["q50"].shape == (1,)
    a, b = rng.normal(0, 1, (30, 6)), rng.normal(3, 2, (70, 6))
    agg = ST.aggregate([{"x": ST.vector_stats(a)}, {"x": ST.vector_stats(b)}])["x"]
    both = np.vstack([a, b])
    np.testing.assert_allclose(agg["mean"], both.mean(axis=0))
    np.testing.assert_allclose(agg["std"], both.std(axis=0))
    assert agg["count"].tolist() == [100]
    img = ST.image_stats(np.full((5, 8, 8, 3), 51, np.uint8))
    assert img["mean"].shape == (3, 1, 1) and np.allclose(img["mean"], 0.2) and img["count"].tolist() == [5]


# ---------------------------------------------------------------------------------------------- injected errors


def _off_grid(col):
    v = col.to_numpy().copy()
    v[5] += 0.4 / 85
    return pa.array(v)


def _narrow(col):
    rows = col.to_pylist()
    return pa.array([[r[:15] for r in m] for m in rows], col.type)


def _drop_row(root):
    path = root / "data" / "chunk-000" / "file-000.parquet"
    t = pq.read_table(path)
    pq.write_table(t.slice(0, t.num_rows - 1), path)


INJECTED = {
    "timestamp off the grid": (lambda r: _rewrite_data(r, "timestamp", _off_grid), "off the 1/85 s grid"),
    "16x15 tactile rows": (lambda r: _rewrite_data(r, "observation.tactile.superficial", _narrow),
                           "rows of shape \\(16, 15\\)"),
    "wrong declared shape": (lambda r: _edit_json(r, "info.json", lambda d: d["features"]["observation.wrench"]
                                                  .update(shape=[5])), "column 'observation.wrench' is"),
    "stats not of the data": (lambda r: _edit_json(r, "stats.json", lambda d: d["observation.wrench"]["mean"]
                                                   .__setitem__(2, 9.0)), "disagrees with the data in \\['mean'\\]"),
    "a frame missing": (_drop_row, "rows in data/, total_frames says"),
    "video missing": (lambda r: (r / "videos" / L.CAMERA_KEY / "chunk-000" / "file-000.mp4").unlink(), "is missing"),
    "old codebase_version": (lambda r: _edit_json(r, "info.json", lambda d: d.update(codebase_version="v2.1")),
                             "codebase_version 'v2.1'"),
    "tasks not indexed by task": (lambda r: pq.write_table(pq.read_table(r / "meta" / "tasks.parquet")
                                                           .replace_schema_metadata(None), r / "meta" / "tasks.parquet"),
                                  "not its pandas index"),
}


@pytest.mark.parametrize("name", list(INJECTED))
def test_the_checker_fails_on_an_injected_error(dataset, tmp_path, name):
    inject, match = INJECTED[name]
    root = _fresh_copy(dataset, tmp_path)
    assert check_lerobot(root) == []
    inject(root)
    problems = check_lerobot(root)
    assert problems and any(re.search(match, p) for p in problems), problems


# ---------------------------------------------------------------------------------------------- bad input


@pytest.mark.parametrize("case, match", [
    ("missing", "SESSIONS='{missing}' does not exist"),
    ("empty", "SESSIONS='{empty}' holds no session files"),
    ("out not empty", "OUT='{full}' exists and is not empty"),
    ("fps 0", "fps=0: the dataset's frame rate must be a whole number"),
    ("nothing complete", "none of its 1 session file\\(s\\) is a complete trial"),
])
def test_bad_input_is_one_line_naming_the_value(campaign, tmp_path, capsys, case, match):
    from layerskin_exp.log.cli import main

    empty, full = tmp_path / "empty", tmp_path / "full"
    empty.mkdir()
    full.mkdir()
    (full / "x").write_text("x")
    (tmp_path / "one").mkdir()
    shutil.copy(campaign / "design" / "pos001_press0.mcap", tmp_path / "one")
    sessions, out, extra = str(campaign), str(tmp_path / "new"), []
    if case == "missing":
        sessions = str(tmp_path / "missing")
    elif case == "empty":
        sessions = str(empty)
    elif case == "out not empty":
        out = str(full)
    elif case == "fps 0":
        extra = ["--fps", "0"]
    else:
        sessions = str(tmp_path / "one")
    assert main(["export", "lerobot", sessions, out, *extra]) == 2
    err = capsys.readouterr().err
    fmt = {k: re.escape(str(v)) for k, v in
           {"missing": tmp_path / "missing", "empty": empty, "full": full}.items()}
    assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err
    assert re.search(match.format(**fmt), err), err
    assert not (tmp_path / "new").exists()
    with pytest.raises(ExportError):
        export_lerobot(sessions, out, fps=int(extra[1]) if extra else None)


def test_the_command_line(campaign, tmp_path):
    out = tmp_path / "cli"
    r = subprocess.run([sys.executable, "-m", "layerskin_exp.log", "export", "lerobot",
                        str(campaign / "design" / "pos000_press0.mcap"), str(out), "--fps", "20"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "1 episode(s)" in r.stdout and "at 20 fps" in r.stdout and check_lerobot(out) == []


def test_block_mean_and_latest_on_a_small_timeline():
    """Samples at 0, 10, 20, ... ns: periods of 25 ns average what falls in them; a period of 5 ns
    with no sample holds the latest earlier one; `latest` is the last sample at or before the end."""
    t = np.arange(0, 100, 10, dtype=np.int64)
    v = np.arange(10, dtype=np.float64)[:, None] * [1.0, -1.0]
    np.testing.assert_allclose(L._block_mean(t, v, np.array([0, 25, 50, 75])), [[1, -1], [3.5, -3.5], [6, -6]])
    np.testing.assert_allclose(L._block_mean(t, v, np.array([20, 25, 30, 35])), [[2, -2], [2, -2], [3, -3]])
    assert L._latest_index(t, np.array([0, 25, 50, 75])).tolist() == [2, 5, 7]
    assert L._edges(1000, 3, 85).tolist() == [1000, 1000 + 11764706, 1000 + 23529412, 1000 + 35294118]
