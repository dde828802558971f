"""Load exported datasets with LeRobot's own LeRobotDataset and compare them with the sessions.

    python tools/lerobot_load_check.py DATASET SESSIONS [DATASET SESSIONS ...] [--json OUT.json]
    python tools/lerobot_load_check.py --markdown OUT.json      # the tables of a result file

DATASET is a folder `python -m layerskin_exp.log export lerobot SESSIONS DATASET` wrote. The
`lerobot` package cannot live in the project's venv (every release pins a torch below the
project's 2.13.0), so this tool makes a second venv (--venv, default .cache/lerobot-check/venv,
reused while its recorded install matches) and installs there:

  - torch==2.13.0, as the project installs it (pip's configuration decides the build: give
    --pip-arg=--index-url=... for another index);
  - lerobot==VERSION with --no-deps: ITS TORCH PIN IS OVERRIDDEN (0.4.4 asks for torch<2.11,
    torchvision<0.26); 0.4.4 is the newest release for Python 3.11, 0.6.x needs Python >= 3.12;
  - torchvision==0.28.0 (the release built for torch 2.13.0), --no-deps;
  - what lerobot's dataset code imports: datasets, huggingface-hub, accelerate, av, pandas,
    pyarrow, pillow, packaging (torch held at 2.13.0 by a constraint).

PyPI's Linux torchvision (and torchcodec) wheels are linked against the CUDA build of torch; over
the CPU build they do not import ("operator torchvision::nms does not exist"). Then (unless
--no-torchvision-stub) the loader runs with a stub `torchvision` package first on its path, one
that raises on any use: lerobot's dataset code imports torchvision at module level but uses it only
for PIL image transforms and its pyav video backend, so a load that needed it fails loudly. The
stub is stated in the output. Without a video decoder the items of a dataset with video are read
without their video frames (LeRobotDataset.hf_dataset, lerobot's own parquet loading) and the
videos' frames are counted with PyAV.

The loader (tools/lerobot_load_probe.py, in the second venv) runs offline: HF_HUB_OFFLINE=1,
HF_DATASETS_OFFLINE=1, HF_HOME in the venv's folder, and every socket connect refused and
recorded; an attempt fails the check. Compared, per dataset:

  - episodes: LeRobotDataset.num_episodes = info.json = the complete sessions under SESSIONS
    (each episode's source, in order), the tasks;
  - frames: num_frames = len(dataset) = info.json = parquet rows; each episode's length = the whole
    frame periods its session's streams overlap for (from the session, read with the project's
    reader), the episodes' index ranges contiguous;
  - features: names, dtypes and shapes LeRobot reports = info.json = the parquet columns;
  - values: for the first, middle and last frame of each episode, every non-video value LeRobot
    gives = the parquet row (exactly), and the tactile layers, the wrench, the stage, TCP and
    gripper = the session's samples over that frame's period (means or latest, recomputed here
    from the session, not with the exporter's code), timestamp = frame_index / fps;
  - videos: frames in each file = the frames of its episodes.

Exit 0 when every comparison holds, 1 when one fails (each named), 2 when the venv or the load
cannot be made.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_VENV = ROOT / ".cache" / "lerobot-check" / "venv"
PROBE = ROOT / "tools" / "lerobot_load_probe.py"
LEROBOT = "0.4.4"
TORCH = "2.13.0"
TORCHVISION = "0.28.0"  # built for torch 2.13.0 (requires torch==2.13.0)
# What lerobot 0.4.4's datasets package imports (lerobot_dataset, utils, video_utils, compute_stats,
# utils/utils.py: accelerate), within lerobot's own ranges where it gives them.
DEPS = ["datasets>=4.0.0,<5.0.0", "huggingface-hub>=0.34.2,<0.36.0", "accelerate>=1.10.0,<2.0.0",
        "av>=15.0.0,<16.0.0", "packaging>=24.2,<26.0", "pandas", "pyarrow", "pillow", "numpy"]
OVERRIDE_NOTE = (f"lerobot installed with --no-deps: its pins torch<2.11 and torchvision<0.26 are overridden "
                 f"(torch {TORCH}, torchvision {TORCHVISION})")
STREAMS = {"observation.tactile.superficial": "skin", "observation.tactile.deep": "skin",
           "observation.wrench": "wrench", "observation.stage.position": "stage", "observation.tcp.pose": "tcp",
           "observation.gripper": "gripper", "observation.images.camera": "camera"}
GRIPPER_FIELDS = ["position_mm", "requested_mm", "speed", "force", "object_detected", "fault"]
STUB = '''"""Not torchvision: a stub put first on the path by tools/lerobot_load_check.py, because the
torchvision wheel for torch 2.13.0 on PyPI needs the CUDA build of torch. Any use raises."""
__version__ = "stub"
LAYERSKIN_STUB = True


def __getattr__(name):
    raise AttributeError(f"torchvision stub (lerobot_load_check): torchvision.{name} is not available here")
'''
STUB_TRANSFORMS = '''def __getattr__(name):
    raise AttributeError(f"torchvision stub (lerobot_load_check): torchvision.transforms.{name} is not available")
'''


class SetupError(RuntimeError):
    pass


# ---------------------------------------------------------------------------------------------- the venv


def _run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if r.returncode != 0:
        raise SetupError(f"{' '.join(cmd)} failed ({r.returncode}):\n{(r.stdout + r.stderr)[-3000:]}")
    return r


def ensure_venv(venv: Path, lerobot: str, python: str, pip_args: list[str], allow_stub: bool,
                log=print) -> dict:
    """Make (or reuse) the check venv; return its record (versions, whether the stub is used)."""
    spec = {"lerobot": lerobot, "torch": TORCH, "torchvision": TORCHVISION, "deps": DEPS, "pip_args": pip_args,
            "python": python}
    key = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:16]
    stamp = venv / "layerskin-check.json"
    py = venv / "bin" / "python"
    if stamp.is_file() and py.exists() and json.loads(stamp.read_text()).get("key") == key:
        record = json.loads(stamp.read_text())
        log(f"reusing {venv} (lerobot {lerobot})")
    else:
        log(f"making {venv}: lerobot {lerobot} (--no-deps), torch {TORCH}, torchvision {TORCHVISION} ... "
            f"(a few minutes)")
        venv.parent.mkdir(parents=True, exist_ok=True)
        _run([python, "-m", "venv", "--clear", str(venv)])
        pip = [str(py), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", *pip_args]
        _run(pip + [f"torch=={TORCH}"])
        _run(pip + ["--no-deps", f"lerobot=={lerobot}", f"torchvision=={TORCHVISION}"])
        with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as c:
            c.write(f"torch=={TORCH}\n")
        try:
            _run(pip + ["-c", c.name, *DEPS])
        finally:
            os.unlink(c.name)
        record = {"key": key, "spec": spec}
    probe = subprocess.run([str(py), "-c", "import torchvision"], capture_output=True, text=True)
    stub_dir = venv.parent / "torchvision-stub"
    if probe.returncode == 0:
        record["torchvision"] = "real"
    else:
        last = (probe.stderr.strip().splitlines() or ["?"])[-1]
        if not allow_stub:
            raise SetupError(f"torchvision {TORCHVISION} does not import in {venv} ({last}); "
                             f"without --no-torchvision-stub the check runs with a stub in its place")
        (stub_dir / "torchvision" / "transforms").mkdir(parents=True, exist_ok=True)
        (stub_dir / "torchvision" / "__init__.py").write_text(STUB)
        (stub_dir / "torchvision" / "transforms" / "__init__.py").write_text(STUB_TRANSFORMS)
        record["torchvision"] = f"stub (the real {TORCHVISION} does not import: {last})"
    record["stub_dir"] = str(stub_dir) if record["torchvision"] != "real" else None
    stamp.write_text(json.dumps(record, indent=2))
    return record


def load_with_lerobot(venv: Path, record: dict, dataset: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "HF_", "VIRTUAL_ENV"))}
    env.update(HF_HUB_OFFLINE="1", HF_DATASETS_OFFLINE="1", HF_HOME=str(venv.parent / "hf-home"),
               HF_LEROBOT_HOME=str(venv.parent / "hf-lerobot-home"))
    if record.get("stub_dir"):
        env["PYTHONPATH"] = record["stub_dir"]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "probe.json"
        r = subprocess.run([str(venv / "bin" / "python"), str(PROBE), str(dataset), str(out)], env=env,
                           capture_output=True, text=True, cwd=tmp)
        if r.returncode != 0:
            raise SetupError(f"LeRobotDataset did not load {dataset}:\n{(r.stdout + r.stderr)[-4000:]}")
        got = json.loads(out.read_text())
    got["log"] = [ln for ln in (r.stdout + r.stderr).splitlines() if ln.strip()][-10:]
    return got


# ---------------------------------------------------------------------------------------------- the project's side


def _expected_from_session(s, features: list[str], fps: int) -> dict:
    """What each frame of an episode holds, recomputed from a session read with the project's
    reader: (n_frames, t0, {feature: (t_ns, values, 'mean' | 'latest')})."""
    src = {}
    for key in features:
        if key.startswith("observation.markers."):
            a = s.streams["markers"]
            sel = a["marker_id"] == int(key.split(".")[2])
            src[key] = (a["t_ns"][sel], None, None)
            continue
        stream = STREAMS.get(key)
        if stream is None:
            continue
        a = s.streams[stream]
        if stream == "skin":
            src[key] = (a["t_ns"], np.asarray(a[key.rsplit(".", 1)[1]], np.float64), "mean")
        elif stream == "wrench":
            src[key] = (a["t_ns"], np.hstack([a["force_n"], a["torque_nm"]]).astype(np.float64), "mean")
        elif stream == "stage":
            src[key] = (a["t_ns"], np.asarray(a["position_mm"], np.float64), "latest")
        elif stream == "tcp":
            src[key] = (a["t_ns"], np.hstack([a["position_m"], a["orientation_xyzw"]]).astype(np.float64), "latest")
        elif stream == "gripper":
            src[key] = (a["t_ns"], np.column_stack([np.asarray(a[k], np.float64) for k in GRIPPER_FIELDS]), "latest")
        else:
            src[key] = (a["t_ns"], None, None)
    t0 = max(int(t[0]) for t, _, _ in src.values())
    t1 = min(int(t[-1]) for t, _, _ in src.values())
    return int((t1 - t0) * fps // 1_000_000_000), t0, src


def _value_at(t, v, how, t0, k, fps):
    lo = t0 + round(k * 1e9 / fps)
    hi = t0 + round((k + 1) * 1e9 / fps)
    if how == "mean":
        inside = (t >= lo) & (t < hi)
        if inside.any():
            return v[inside].mean(axis=0)
        return v[np.nonzero(t < hi)[0][-1]]
    return v[np.nonzero(t <= hi)[0][-1]]


def compare(dataset: Path, sessions: Path, got: dict) -> tuple[list[str], list[str], dict]:
    """(failures, checks passed, summary) for one dataset."""
    import pyarrow.parquet as pq

    from layerskin_exp.log import load_session

    fails, passed = [], []

    def check(ok, what, detail=""):
        (passed if ok else fails).append(what if ok else f"{what}: {detail}")

    info = json.loads((dataset / "meta" / "info.json").read_text())
    fps = info["fps"]
    check(got["network_attempts"] == [], "no network call attempted", f"{got['network_attempts']}")
    check(got["fps"] == fps, "fps", f"LeRobot {got['fps']}, info.json {fps}")

    # Episodes: the complete sessions under SESSIONS.
    files = sorted(sessions.rglob("*.mcap")) if sessions.is_dir() else [sessions]
    rel = (lambda p: str(p.relative_to(sessions))) if sessions.is_dir() else (lambda p: p.name)
    complete = {}
    import warnings
    for p in files:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                s = load_session(p, warn=False)
            except Exception:  # noqa: BLE001 - an unreadable file is not a complete session
                continue
        if s.complete and "skin" in s.streams and len(s.streams["skin"]["t_ns"]) > 1:
            complete[rel(p)] = s
    eps = got["episodes"]
    check(got["num_episodes"] == info["total_episodes"] == len(complete) == len(eps), "episode count",
          f"LeRobot {got['num_episodes']}, info.json {info['total_episodes']}, complete sessions {len(complete)}")
    check([e["source"] for e in eps] == sorted(complete), "each episode's session, in order",
          f"LeRobot's episodes {[e['source'] for e in eps]}, complete sessions {sorted(complete)}")
    check([e["episode_index"] for e in eps] == list(range(len(eps))), "episode indices 0..n-1")

    # Frames.
    data_files = sorted((dataset / "data").rglob("*.parquet"))
    rows = sum(pq.ParquetFile(f).metadata.num_rows for f in data_files)
    check(got["num_frames"] == got["len"] == got["hf_rows"] == info["total_frames"] == rows, "frame count",
          f"LeRobot num_frames {got['num_frames']}, len {got['len']}, hf rows {got['hf_rows']}, "
          f"info.json {info['total_frames']}, parquet rows {rows}")
    start = 0
    for e in eps:
        check(e["dataset_from_index"] == start and e["dataset_to_index"] - start == e["length"],
              f"episode {e['episode_index']} index range", f"{e['dataset_from_index']}..{e['dataset_to_index']}, "
              f"length {e['length']}, expected from {start}")
        start = e["dataset_to_index"]

    # Features: LeRobot's = info.json's = the parquet columns.
    lr = {k: (v["dtype"], tuple(v["shape"])) for k, v in got["features"].items()}
    inf = {k: (v["dtype"], tuple(v["shape"])) for k, v in info["features"].items()}
    check(lr == inf, "features (names, dtypes, shapes): LeRobot = info.json", f"LeRobot {lr}, info.json {inf}")
    schema = pq.read_schema(data_files[0])
    for k, (dtype, shape) in inf.items():
        if dtype == "video":
            continue
        if k not in schema.names:
            check(False, f"feature {k} in the parquet", "no such column")
            continue
        t = schema.field(k).type
        dims = []
        while hasattr(t, "value_type") or hasattr(t, "storage_type"):
            t = getattr(t, "storage_type", t)
            if hasattr(t, "list_size"):
                dims.append(t.list_size)
            elif hasattr(t, "value_type"):
                dims.append(None)
            t = t.value_type
        ok = str(t) == {"float32": "float", "int64": "int64"}.get(dtype, dtype) and (
            (shape == (1,) and dims == []) or len(dims) == len(shape))
        check(ok, f"feature {k}: parquet column type", f"{schema.field(k).type} for {dtype} {list(shape)}")
    check(len(got["tasks"]) == info["total_tasks"] and all(set(e["tasks"]) <= set(got["tasks"]) for e in eps),
          "tasks", f"LeRobot's tasks {got['tasks']}, info.json total_tasks {info['total_tasks']}")

    # Values: LeRobot's items = the parquet rows = the sessions.
    table = pq.read_table(data_files[0]) if len(data_files) == 1 else None
    if table is None:
        import pyarrow as pa
        table = pa.concat_tables([pq.read_table(f) for f in data_files])
    index = table.column("index").to_numpy()
    data_keys = [k for k, (d, _) in inf.items() if d != "video"]
    per_ep = {}
    n_values = 0
    for i_str, item in got["items"].items():
        i = int(i_str)
        rows_i = np.nonzero(index == i)[0]
        if len(rows_i) != 1:
            check(False, f"frame {i}: one parquet row with index {i}", f"{len(rows_i)} rows")
            continue
        row = int(rows_i[0])
        for k in data_keys:
            mine = np.asarray(table.column(k)[row].as_py(), dtype=inf[k][0])
            theirs = np.asarray(item[k], dtype=inf[k][0])
            same = mine.reshape(-1).shape == theirs.reshape(-1).shape and np.array_equal(
                mine.reshape(-1), theirs.reshape(-1))
            shape_ok = tuple(theirs.shape) == (inf[k][1] if inf[k][1] != (1,) else ())
            if not (same and shape_ok):
                check(False, f"frame {i} {k}: LeRobot = parquet",
                      f"LeRobot {theirs.reshape(-1)[:6]} shape {theirs.shape}, parquet {mine.reshape(-1)[:6]}")
            n_values += 1
        ep = int(item["episode_index"])
        e = eps[ep]
        k = int(item["frame_index"])
        if not np.isclose(float(item["timestamp"]), np.float32(k / fps), rtol=0, atol=1e-6):
            check(False, f"frame {i} timestamp", f"{item['timestamp']} != {k}/{fps}")
        if ep not in per_ep:
            per_ep[ep] = _expected_from_session(complete[e["source"]], list(inf), fps)
            n_sess, _, _ = per_ep[ep]
            check(n_sess == e["length"], f"episode {ep} length = its session's whole frame periods",
                  f"LeRobot {e['length']}, from the session {n_sess}")
        _, t0, src = per_ep[ep]
        for key, (t, v, how) in src.items():
            if v is None:
                continue
            want = _value_at(t, v, how, t0, k, fps)
            have = np.asarray(item[key], np.float64)
            if not np.allclose(have.reshape(-1), want.reshape(-1), rtol=1e-5, atol=1e-4):
                d = np.abs(have.reshape(-1) - want.reshape(-1)).max()
                check(False, f"frame {i} (episode {ep}, frame {k}) {key}: LeRobot = the session's {how}",
                      f"max |difference| {d:.6g}")
            n_values += 1
    for i, err in got.get("item_errors", {}).items():
        check(False, f"frame {i}: LeRobotDataset[{i}]", err)
    if not any(f.startswith("frame ") for f in fails):
        check(True, f"{n_values} values at {len(got['items'])} frames: LeRobot = parquet = sessions")

    for path, frames in got["video_frames"].items():
        key = path.split("/")[1]
        want = sum(e["length"] for e in eps if path == info["video_path"].format(
            video_key=key, chunk_index=e[key]["chunk_index"], file_index=e[key]["file_index"]))
        check(frames == want, f"video {path}: frames = its episodes' frames", f"{frames} decoded, {want} expected")

    summary = {"dataset": str(dataset), "sessions": str(sessions), "episodes": got["num_episodes"],
               "frames": got["num_frames"], "fps": got["fps"], "tasks": got["tasks"],
               "episode_lengths": [e["length"] for e in eps],
               "features": {k: {"dtype": d, "shape": list(s)} for k, (d, s) in lr.items()},
               "video_backend": got["video_backend"],
               "video_decoded_by_lerobot": got["video_keys"] != [] and got["video_decode_error"] is None,
               "video_decode_error": got["video_decode_error"], "video_frames": got["video_frames"],
               "network_attempts": got["network_attempts"], "values_compared": n_values,
               "checks_passed": len(passed), "failures": fails}
    return fails, passed, summary


# ---------------------------------------------------------------------------------------------- output


def markdown(result: dict) -> str:
    """The tables of a result file (docs/export.md's generated section)."""
    v = result["versions"]
    lines = [f"lerobot {v['lerobot']} (`LeRobotDataset`, codebase {v['codebase_version']}), torch {v['torch']}, "
             f"torchvision {result['torchvision']}, datasets {v['datasets']}, huggingface_hub "
             f"{v['huggingface_hub']}, Python {v['python']}. {result['override']}.", ""]
    lines += ["| dataset | episodes | frames | fps | checks | values compared | video |",
              "|---|---|---|---|---|---|---|"]
    for d in result["datasets"]:
        if d["video_frames"]:
            video = ("decoded by LeRobot" if d["video_decoded_by_lerobot"] else
                     f"not decoded by LeRobot (its `{d['video_backend']}` backend needs torchvision); "
                     f"{sum(d['video_frames'].values())} frames counted with PyAV")
        else:
            video = "none"
        status = f"{len(d['failures'])} failed"
        lines.append(f"| `{d['name']}` | {d['episodes']} | {d['frames']} ({' + '.join(map(str, d['episode_lengths']))})"
                     f" | {d['fps']} | {d['checks_passed']} passed, {status} | {d['values_compared']} | {video} |")
    for d in result["datasets"]:
        lines += ["", f"`{d['name']}`, as `LeRobotDataset.features` gives them:", "",
                  "| feature | dtype | shape |", "|---|---|---|"]
        lines += [f"| `{k}` | {f['dtype']} | {tuple(f['shape'])} |" for k, f in d["features"].items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python tools/lerobot_load_check.py", description=__doc__.split("\n\n")[0],
                                 epilog=__doc__.split("\n\n", 2)[2], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pairs", nargs="*", metavar="DATASET SESSIONS",
                    help="an exported dataset and the sessions it was exported from (repeat for more)")
    ap.add_argument("--venv", type=Path, default=DEFAULT_VENV, help=f"the check venv (default {DEFAULT_VENV})")
    ap.add_argument("--lerobot", default=LEROBOT, help=f"the lerobot release (default {LEROBOT})")
    ap.add_argument("--python", default=getattr(sys, "_base_executable", sys.executable),
                    help="the interpreter the venv is made with (default: this one's base)")
    ap.add_argument("--pip-arg", action="append", default=[], metavar="ARG",
                    help="an extra argument for every pip install in the venv, e.g. --pip-arg=--index-url=URL")
    ap.add_argument("--no-torchvision-stub", dest="stub", action="store_false",
                    help="fail if the real torchvision does not import, instead of loading with the stub")
    ap.add_argument("--json", type=Path, help="write the result here")
    ap.add_argument("--markdown", type=Path, metavar="RESULT.json", help="print the tables of a result file and exit")
    args = ap.parse_args(argv)
    if args.markdown:
        print(markdown(json.loads(args.markdown.read_text())), end="")
        return 0
    if not args.pairs or len(args.pairs) % 2:
        ap.error("give DATASET SESSIONS pairs (an exported dataset and the folder of sessions it came from)")
    pairs = [(Path(a), Path(b)) for a, b in zip(args.pairs[::2], args.pairs[1::2], strict=True)]
    for d, s in pairs:
        if not (d / "meta" / "info.json").is_file():
            ap.error(f"DATASET={str(d)!r} has no meta/info.json: give a folder `export lerobot` wrote")
        if not s.exists():
            ap.error(f"SESSIONS={str(s)!r} does not exist")
    try:
        record = ensure_venv(args.venv.resolve(), args.lerobot, args.python, args.pip_arg, args.stub)
    except SetupError as exc:
        print(f"lerobot_load_check: {exc}", file=sys.stderr)
        return 2
    result = {"override": OVERRIDE_NOTE, "torchvision": record["torchvision"], "datasets": []}
    failed = 0
    for d, s in pairs:
        try:
            got = load_with_lerobot(args.venv.resolve(), record, d.resolve())
        except SetupError as exc:
            print(f"lerobot_load_check: {exc}", file=sys.stderr)
            return 2
        result["versions"] = got["versions"]
        fails, passed, summary = compare(d, s, got)
        summary["name"] = d.name
        result["datasets"].append(summary)
        failed += bool(fails)
        print(f"{d}: LeRobotDataset (lerobot {got['versions']['lerobot']}) loaded {got['num_episodes']} episodes, "
              f"{got['num_frames']} frames at {got['fps']} fps, {len(got['features'])} features")
        for k, f in summary["features"].items():
            print(f"    {k}: {f['dtype']} {tuple(f['shape'])}")
        if got["video_keys"]:
            print("  video: " + ("decoded by LeRobot" if summary["video_decoded_by_lerobot"] else
                                 f"not decoded by LeRobot ({got['video_decode_error']}); items read without "
                                 f"the video frames, {got['video_frames']} frames counted with PyAV"))
        print(f"  {len(passed)} checks passed, {summary['values_compared']} values compared" +
              (f"; {len(fails)} FAILED:" if fails else ""))
        for f in fails:
            print(f"    FAIL {f}")
    print(f"lerobot {result['versions']['lerobot']}, torch {result['versions']['torch']}, "
          f"torchvision {record['torchvision']}")
    print(f"NOTE: {OVERRIDE_NOTE}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
