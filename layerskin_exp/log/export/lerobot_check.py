"""check_lerobot: is a folder a well-formed LeRobot v3.0 dataset? Read with pyarrow alone (and
OpenCV for the videos' frame counts), the rules LeRobot's own loader relies on (commit
7427f31801f944f5ec9ce53cda02862ce7d1638b): info.json's keys and features, the parquet columns and
types features give, the per-frame columns (timestamp on the 1/fps grid within tolerance_s,
frame_index, episode_index, index, task_index), the episodes metadata, the tasks, the videos, and
stats.json against the data.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from layerskin_exp.log.export import lerobot as L

INFO_KEYS = ("codebase_version", "fps", "features", "total_episodes", "total_frames", "total_tasks",
             "chunks_size", "data_files_size_in_mb", "video_files_size_in_mb", "data_path", "video_path",
             "robot_type", "splits")
STAT_KEYS = ("min", "max", "mean", "std", "count", *L.ST.QUANTILE_KEYS)


def _stat_shape(ft: dict) -> tuple:
    """The shape LeRobot's compute_stats gives a feature's statistics."""
    shape = tuple(ft["shape"])
    if ft["dtype"] in ("video", "image"):
        return (shape[2], 1, 1)
    return (shape[-1],)


def check_lerobot(root, *, tolerance_s: float = L.TOLERANCE_S) -> list[str]:
    """Problems found in the dataset at `root` (empty: none). Never raises for a bad dataset."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    root = Path(root)
    problems: list[str] = []
    try:
        info = json.loads((root / "meta" / "info.json").read_text())
    except (OSError, ValueError) as exc:
        return [f"meta/info.json unreadable: {exc}"]
    problems += [f"info.json lacks {k!r}" for k in INFO_KEYS if k not in info]
    if problems:
        return problems
    if info["codebase_version"] != L.CODEBASE_VERSION:
        problems.append(f"codebase_version {info['codebase_version']!r}, not {L.CODEBASE_VERSION!r}")
    fps = info["fps"]
    if not isinstance(fps, int) or fps <= 0:
        return problems + [f"fps {fps!r} is not a positive int"]
    for k in ("chunks_size", "data_files_size_in_mb", "video_files_size_in_mb"):
        if not isinstance(info[k], int) or info[k] <= 0:
            problems.append(f"{k} {info[k]!r} is not a positive int")
    features = info["features"]
    for k, ft in L.DEFAULT_FEATURES.items():
        if k not in features or {x: features[k].get(x) for x in ("dtype", "shape")} != \
                {x: ft[x] for x in ("dtype", "shape")}:
            problems.append(f"feature {k!r} must be {ft}, is {features.get(k)}")
    for k, ft in features.items():
        if not {"dtype", "shape", "names"} <= set(ft) or not isinstance(ft["shape"], list) or \
                not all(isinstance(d, int) and d > 0 for d in ft["shape"]):
            problems.append(f"feature {k!r} needs dtype, shape (positive ints) and names: {ft}")
    if problems:
        return problems
    videos = [k for k, ft in features.items() if ft["dtype"] == "video"]
    if info["data_path"] != L.DATA_PATH:
        problems.append(f"data_path {info['data_path']!r}, not {L.DATA_PATH!r}")
    if info["video_path"] != (L.VIDEO_PATH if videos else None):
        problems.append(f"video_path {info['video_path']!r} with video features {videos}")
    n_ep, n_frames = info["total_episodes"], info["total_frames"]
    if info["splits"] != {"train": f"0:{n_ep}"}:
        problems.append(f"splits {info['splits']!r}, not {{'train': '0:{n_ep}'}}")

    # ---- data
    data_files = sorted((root / "data").glob("*/*.parquet"))
    pattern = re.compile(r"data/chunk-(\d{3})/file-(\d{3})\.parquet$")
    if not data_files:
        return problems + ["no data/chunk-XXX/file-XXX.parquet files"]
    columns = [k for k, ft in features.items() if ft["dtype"] != "video"]
    tables, file_of_row = [], []
    for path in data_files:
        m = pattern.search(path.relative_to(root).as_posix())
        if not m:
            problems.append(f"{path.relative_to(root)} does not follow {L.DATA_PATH}")
            continue
        t = pq.read_table(path)
        if t.column_names != columns:
            problems.append(f"{path.relative_to(root)}: columns {t.column_names}, features give {columns}")
            continue
        for k in columns:
            want = L._arrow_type(pa, features[k], storage=True)
            got = t.schema.field(k).type
            got = got.storage_type if isinstance(got, pa.ExtensionType) else got  # datasets' ArrayND, where registered
            if got != want:
                problems.append(f"{path.relative_to(root)}: column {k!r} is {got}, "
                                f"its feature (dtype {features[k]['dtype']}, shape {features[k]['shape']}) gives {want}")
        tables.append(t)
        file_of_row.append(np.full(t.num_rows, int(m.group(1)) * 1000 + int(m.group(2))))
    if problems:
        return problems
    data = pa.concat_tables(tables)
    file_of_row = np.concatenate(file_of_row)
    if data.num_rows != n_frames:
        problems.append(f"{data.num_rows} rows in data/, total_frames says {n_frames}")
    arrays = {}
    for k in columns:
        shape = tuple(features[k]["shape"])
        col = data.column(k).combine_chunks()
        col = col.storage if isinstance(col, pa.ExtensionArray) else col
        try:
            arrays[k] = _to_numpy(pa, col, shape, features[k]["dtype"])
        except ValueError as exc:
            problems.append(f"column {k!r}: {exc}")
    if problems:
        return problems
    ts, fi, ei, ix, ti = (arrays[k] for k in ("timestamp", "frame_index", "episode_index", "index", "task_index"))
    if not np.array_equal(ix, np.arange(len(ix))):
        problems.append("index is not 0, 1, ... over the data files in order")
    starts = np.flatnonzero(np.r_[True, ei[1:] != ei[:-1]])
    ends = np.r_[starts[1:], len(ei)]
    if not np.array_equal(ei[starts], np.arange(len(starts))):
        problems.append(f"episode_index runs are {ei[starts][:10].tolist()}..., not 0, 1, ... in order")
    if len(starts) != n_ep:
        problems.append(f"{len(starts)} episodes in data/, total_episodes says {n_ep}")
    for a, b in zip(starts, ends, strict=True):
        if not np.array_equal(fi[a:b], np.arange(b - a)):
            problems.append(f"episode {ei[a]}: frame_index is not 0..{b - a - 1}")
        off = np.abs(ts[a:b].astype(np.float64) - fi[a:b] / fps)
        if off.max() > tolerance_s:
            k = int(np.argmax(off))
            problems.append(f"episode {ei[a]} frame {k}: timestamp {ts[a + k]:.6f} s is {off[k]:.2e} s off the "
                            f"1/{fps} s grid (tolerance {tolerance_s} s)")
        d = np.diff(ts[a:b].astype(np.float64))
        if d.size and np.abs(d - 1 / fps).max() > tolerance_s:
            problems.append(f"episode {ei[a]}: timestamps are not 1/{fps} s apart within {tolerance_s} s")
    if ti.size and (ti.min() < 0 or ti.max() >= info["total_tasks"]):
        problems.append(f"task_index outside 0..{info['total_tasks'] - 1}")

    # ---- tasks
    try:
        tasks = pq.read_table(root / L.TASKS_PATH)
        if sorted(tasks.column_names) != ["task", "task_index"] or tasks.num_rows != info["total_tasks"] or \
                sorted(tasks.column("task_index").to_pylist()) != list(range(tasks.num_rows)):
            problems.append(f"meta/tasks.parquet: {tasks.num_rows} rows of {tasks.column_names}, want task and "
                            f"task_index 0..{info['total_tasks'] - 1}")
        task_names = set(tasks.column("task").to_pylist())
        meta = json.loads(tasks.schema.metadata[b"pandas"]) if tasks.schema.metadata else {}
        if meta.get("index_columns") != ["task"]:
            problems.append("meta/tasks.parquet: 'task' is not its pandas index (LeRobot looks tasks up by it)")
    except (OSError, KeyError, ValueError, pa.ArrowInvalid) as exc:
        problems.append(f"meta/tasks.parquet unreadable: {exc}")
        task_names = set()

    # ---- episodes
    ep_files = sorted((root / "meta" / "episodes").glob("*/*.parquet"))
    if not ep_files:
        return problems + ["no meta/episodes/chunk-XXX/file-XXX.parquet"]
    eps = pa.concat_tables([pq.read_table(p) for p in ep_files]).to_pylist()
    if len(eps) != n_ep:
        problems.append(f"{len(eps)} rows in meta/episodes, total_episodes says {n_ep}")
    need = ["episode_index", "tasks", "length", "data/chunk_index", "data/file_index", "dataset_from_index",
            "dataset_to_index", "meta/episodes/chunk_index", "meta/episodes/file_index"]
    for v in videos:
        need += [f"videos/{v}/{x}" for x in ("chunk_index", "file_index", "from_timestamp", "to_timestamp")]
    need += [f"stats/{k}/{s}" for k in features for s in STAT_KEYS]
    missing = [c for c in need if eps and c not in eps[0]]
    if missing:
        return problems + [f"meta/episodes lacks columns {missing[:6]}{'...' if len(missing) > 6 else ''}"]
    video_frames: dict[tuple, float] = {}
    for i, e in enumerate(eps):
        if e["episode_index"] != i:
            problems.append(f"meta/episodes row {i} has episode_index {e['episode_index']}")
            continue
        if i < len(starts):
            a, b = int(starts[i]), int(ends[i])
            if (e["dataset_from_index"], e["dataset_to_index"], e["length"]) != (a, b, b - a):
                problems.append(f"episode {i}: from/to {e['dataset_from_index']}..{e['dataset_to_index']}, length "
                                f"{e['length']}; the data holds it at {a}..{b}")
            if set(file_of_row[a:b].tolist()) != {e["data/chunk_index"] * 1000 + e["data/file_index"]}:
                problems.append(f"episode {i}: data/chunk_index, file_index do not name the file holding it")
        if not set(e["tasks"]) <= task_names:
            problems.append(f"episode {i}: tasks {e['tasks']} not in meta/tasks.parquet")
        for v in videos:
            key = (v, e[f"videos/{v}/chunk_index"], e[f"videos/{v}/file_index"])
            span = (e[f"videos/{v}/to_timestamp"] - e[f"videos/{v}/from_timestamp"]) * fps
            if abs(span - e["length"]) > 0.5:
                problems.append(f"episode {i}: {v} spans {span:.2f} frames, the episode {e['length']}")
            video_frames[key] = max(video_frames.get(key, 0.0), e[f"videos/{v}/to_timestamp"] * fps)
    for (v, c, f), frames in video_frames.items():
        path = root / L.VIDEO_PATH.format(video_key=v, chunk_index=c, file_index=f)
        n = _video_frames(path, features[v])
        if isinstance(n, str):
            problems.append(n)
        elif abs(n - frames) > 0.5:
            problems.append(f"{path.relative_to(root)} holds {n} frames, its episodes {frames:.0f}")

    # ---- stats
    try:
        stats = json.loads((root / "meta" / "stats.json").read_text())
    except (OSError, ValueError) as exc:
        return problems + [f"meta/stats.json unreadable: {exc}"]
    for k, ft in features.items():
        if k not in stats:
            problems.append(f"stats.json has no {k!r}")
            continue
        st = {s: np.asarray(stats[k].get(s), dtype=np.float64) for s in STAT_KEYS if s in stats[k]}
        if set(st) != set(STAT_KEYS):
            problems.append(f"stats.json {k!r} has {sorted(stats[k])}, needs {list(STAT_KEYS)}")
            continue
        want = _stat_shape(ft)
        bad = [s for s in STAT_KEYS if s != "count" and st[s].shape != want]
        if bad or st["count"].shape != (1,):
            problems.append(f"stats.json {k!r}: {bad or ['count']} not of shape {want} (count (1,))")
            continue
        order = [st[s] for s in ("min", *L.ST.QUANTILE_KEYS, "max")]
        tol = 1e-6 * (1 + np.abs(st["max"]))
        if any(np.any(lo > hi + tol) for lo, hi in zip(order, order[1:], strict=False)) or \
                np.any(st["mean"] < st["min"] - tol) or np.any(st["mean"] > st["max"] + tol) or np.any(st["std"] < 0):
            problems.append(f"stats.json {k!r}: min <= q01 <= ... <= q99 <= max, min <= mean <= max, std >= 0 fail")
        if ft["dtype"] == "video":
            continue
        x = arrays[k].astype(np.float64)
        x = x.reshape(-1, 1) if x.ndim == 1 else x.reshape(-1, x.shape[-1])
        ref = {"min": x.min(axis=0), "max": x.max(axis=0), "mean": x.mean(axis=0), "std": x.std(axis=0)}
        scale = 1e-4 * (1 + np.abs(ref["max"]) + np.abs(ref["min"]))
        off = [s for s in ref if np.any(np.abs(st[s] - ref[s]) > scale)]
        if int(st["count"][0]) != len(arrays[k]):
            off.append(f"count {int(st['count'][0])} != {len(arrays[k])} frames")
        if off:
            problems.append(f"stats.json {k!r} disagrees with the data in {off}")
    return problems


def _to_numpy(pa, col, shape: tuple, dtype: str) -> np.ndarray:
    """A data column as an (N, *shape) array; ValueError where a row does not have the shape."""
    if shape == (1,):
        return col.to_numpy(zero_copy_only=False).astype(dtype, copy=False)
    a = col
    dims = []
    while pa.types.is_list(a.type) or pa.types.is_fixed_size_list(a.type):
        lengths = a.value_lengths().to_numpy(zero_copy_only=False) if pa.types.is_list(a.type) else \
            np.full(len(a), a.type.list_size)
        if len(lengths) and (lengths != lengths[0]).any():
            raise ValueError(f"rows of different lengths {sorted(set(lengths.tolist()))[:4]} at depth {len(dims)}")
        dims.append(int(lengths[0]) if len(lengths) else 0)
        a = a.flatten()
    if tuple(dims) != shape and len(col):
        raise ValueError(f"rows of shape {tuple(dims)}, its feature says {shape}")
    return a.to_numpy(zero_copy_only=False).astype(dtype, copy=False).reshape(len(col), *shape)


def _video_frames(path: Path, ft: dict) -> int | str:
    import cv2

    if not path.is_file():
        return f"{path} is missing"
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            return f"{path}: OpenCV cannot open it"
        h, w = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)), int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        if [h, w] != ft["shape"][:2]:
            return f"{path}: frames {h}x{w}, its feature says {ft['shape'][0]}x{ft['shape'][1]}"
        n = 0
        while cap.grab():
            n += 1
        return n
    finally:
        cap.release()
